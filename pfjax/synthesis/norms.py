"""H2 and H-infinity norms of continuous-time LTI systems, and the state-feedback closed loop.

System ``G(s) = C (sI - A)^-1 B + D`` with ``A`` of shape (n, n), ``B`` (n, m), ``C`` (p, n),
``D`` (p, m). Non-square MIMO (``p != m``) is supported throughout. Plain NumPy/SciPy; nothing here
is traced or jitted.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from pfjax.synthesis.plant import Plant

__all__ = ["closed_loop", "h2_norm", "hinf_norm", "is_hurwitz"]


def _as_system(A, B, C, D=None):
    A = np.atleast_2d(np.asarray(A, dtype=float))
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)
    C = np.asarray(C, dtype=float).reshape(-1, A.shape[0])
    if D is None:
        D = np.zeros((C.shape[0], B.shape[1]))
    else:
        D = np.asarray(D, dtype=float).reshape(C.shape[0], B.shape[1])
    if A.shape[0] != A.shape[1]:
        raise ValueError(f"A must be square, got shape {A.shape}")
    return A, B, C, D


def is_hurwitz(A) -> bool:
    """True when every eigenvalue of ``A`` has a strictly negative real part."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    if A.size == 0:
        return True
    return bool(np.max(np.linalg.eigvals(A).real) < 0.0)


def h2_norm(A, B, C, D=None) -> float:
    """H2 norm of ``G(s) = C (sI - A)^-1 B + D``.

    ``||G||_2^2 = trace(C Wc C')`` with the controllability Gramian ``Wc`` solving
    ``A Wc + Wc A' + B B' = 0``; equivalently ``int_0^inf ||C e^{At} B||_F^2 dt``.

    Args:
        A: (n, n) state matrix.
        B: (n, m) input matrix.
        C: (p, n) output matrix.
        D: (p, m) feed-through, default zero.

    Returns:
        The norm (units of output per input, per sqrt(s)); ``inf`` when ``A`` is not Hurwitz or
        ``D`` is nonzero (the impulse response then contains a Dirac).
    """
    A, B, C, D = _as_system(A, B, C, D)
    if np.any(D != 0.0) or not is_hurwitz(A):
        return float("inf")
    if B.size == 0 or C.size == 0:
        return 0.0
    Wc = sla.solve_continuous_lyapunov(A, -B @ B.T)
    Wc = 0.5 * (Wc + Wc.T)
    return float(np.sqrt(max(np.trace(C @ Wc @ C.T), 0.0)))


def _sigma_max(A, B, C, D, w: float) -> float:
    """Largest singular value of ``G(j w)``."""
    n = A.shape[0]
    G = C @ np.linalg.solve(1j * w * np.eye(n) - A, B) + D
    return float(np.linalg.norm(G, 2))


def _hamiltonian(A, B, C, D, gamma: float) -> np.ndarray:
    """Hamiltonian matrix whose imaginary eigenvalues ``j w`` are the frequencies at which
    ``gamma`` is a singular value of ``G(j w)`` (valid for ``gamma > sigma_max(D)``)::

        R = D'D - gamma^2 I,  S = DD' - gamma^2 I
        H = [[A - B R^-1 D' C,     -gamma B R^-1 B'     ],
             [gamma C' S^-1 C,     -A' + C' D R^-1 B'   ]]
    """
    m = B.shape[1]
    p = C.shape[0]
    R = D.T @ D - gamma**2 * np.eye(m)
    S = D @ D.T - gamma**2 * np.eye(p)
    Rinv_Dt = np.linalg.solve(R, D.T)
    Rinv_Bt = np.linalg.solve(R, B.T)
    H11 = A - B @ Rinv_Dt @ C
    H12 = -gamma * B @ Rinv_Bt
    H21 = gamma * C.T @ np.linalg.solve(S, C)
    H22 = -A.T + C.T @ D @ Rinv_Bt
    return np.block([[H11, H12], [H21, H22]])


def hinf_norm(A, B, C, D=None, rtol: float = 1e-8) -> float:
    """H-infinity norm ``sup_w sigma_max(G(j w))`` by the Hamiltonian iteration of
    Bruinsma and Steinbuch (1990), a quadratically convergent refinement of the
    Boyd-Balakrishnan (1990) bisection.

    Starting from a lower bound ``g_lb`` (``sigma_max`` at ``w = 0``, ``w = inf`` and at the
    moduli/imaginary parts of the poles), each step forms the Hamiltonian ``H(g)`` for
    ``g = (1 + rtol) g_lb``. No imaginary-axis eigenvalue means ``||G||_inf < g`` and the
    iteration stops; otherwise the imaginary eigenvalues ``j w_1 < ... < j w_k`` bracket the
    intervals where ``sigma_max > g``, and ``g_lb`` becomes the largest ``sigma_max`` at the
    interval midpoints. Works for non-square MIMO systems.

    Args:
        A: (n, n) state matrix.
        B: (n, m) input matrix.
        C: (p, n) output matrix.
        D: (p, m) feed-through, default zero.
        rtol: relative accuracy of the returned value.

    Returns:
        The norm (a lower bound within ``rtol`` of it, attained at some frequency); ``inf``
        when ``A`` is not Hurwitz.
    """
    A, B, C, D = _as_system(A, B, C, D)
    if not is_hurwitz(A):
        return float("inf")
    sd = float(np.linalg.norm(D, 2)) if D.size else 0.0
    if B.size == 0 or C.size == 0:
        return sd
    if not np.any(B) or not np.any(C):
        return sd
    poles = np.linalg.eigvals(A)
    cands = {0.0}
    cands.update(abs(float(p.imag)) for p in poles)
    cands.update(float(abs(p)) for p in poles)
    g_lb = max([sd] + [_sigma_max(A, B, C, D, w) for w in cands])
    if g_lb == 0.0:
        return 0.0
    for _ in range(200):
        g = (1.0 + rtol) * g_lb  # none above it: the norm is below (1 + rtol) g_lb, g_lb within rtol
        eig = np.linalg.eigvals(_hamiltonian(A, B, C, D, g))
        scale = max(1.0, float(np.max(np.abs(eig)))) if eig.size else 1.0
        # Near-tangent crossings leave the axis by ~sqrt(machine eps); a spurious candidate only
        # costs extra sigma_max evaluations, a missed one can stop the iteration early.
        on_axis = (np.abs(eig.real) < 1e-6 * scale) & (eig.imag >= 0.0)
        imag = np.sort(eig[on_axis].imag)
        if imag.size == 0:
            break
        pts = np.concatenate([[0.0], imag])
        mids = 0.5 * (pts[:-1] + pts[1:])
        new = max(_sigma_max(A, B, C, D, w) for w in np.concatenate([mids, imag]))
        if new <= g_lb:
            break
        g_lb = new
    return float(g_lb)


def closed_loop(plant: Plant, K) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closed loop of a :class:`Plant` under static state feedback ``u = K x`` (source eq. 8).

    ::

        x'    = (A + Bu K) x + Bw w
        z_inf = (Cinf + Dinf_u K) x
        z2    = (C2 + D2u K) x

    Args:
        plant: the generalised plant.
        K: (n_u, n_x) gain.

    Returns:
        ``(Acl, Bw, Cinf_cl, C2_cl)`` with shapes (n_x, n_x), (n_x, n_w), (n_zinf, n_x),
        (n_z2, n_x).
    """
    K = np.asarray(K, dtype=float).reshape(plant.Bu.shape[1], plant.A.shape[0])
    Acl = plant.A + plant.Bu @ K
    Cinf_cl = plant.Cinf + plant.Dinf_u @ K
    C2_cl = plant.C2 + plant.D2u @ K
    return Acl, np.array(plant.Bw, dtype=float), Cinf_cl, C2_cl
