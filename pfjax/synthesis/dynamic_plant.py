"""Design plants on the dynamic single-track model's lateral-yaw dynamics, and the mixed H2/H-inf
designs of the path-following gains on them (NumPy in, NumPy out; nothing traced).

The kinematic designs (:func:`~pfjax.synthesis.plant.slip_design_plant`) take the steering to act on
the heading at once. On the ST model (:mod:`pfjax.models.single_track`) at speed ``v`` without
acceleration the steering acts through the tyres' lateral-yaw dynamics ``(psi_dot, beta)`` (matrices
``A_lat``, ``B_lat`` of :func:`pfjax.models.single_track.lateral_yaw_matrices`) and the first-order
steering actuator of the simulator (:mod:`pfjax.sim.dynamic`, time constant ``tau``). Linearised
about straight driving along the path, the rear axle's errors (``d`` m, ``theta_e`` rad) follow
``d' = v sin(theta_e + beta) - l_r psi_dot cos(theta_e)`` and ``theta_e' = psi_dot - v kappa``, so
with ``x = [d, theta_e, (int d), psi_dot, beta, delta]``, ``u = delta_c`` (rad)::

    d'       = v theta_e + v beta - l_r psi_dot + v w_r
    theta_e' = psi_dot - (v / L) (w_r + w_f) - v kappa
    (int d)' = d                                          (with integral action)
    [psi_dot', beta']' = A_lat [psi_dot, beta]' + B_lat delta
    delta'   = (delta_c - delta) / tau

The exogenous inputs ``w = [w_r, w_f, kappa]`` enter the error rows as in the kinematic plant
(declared slip angles in rad and the path's curvature in 1/m), so that the design criteria
(``z_inf = [d, theta_e(, int d)]``, ``z2 = [z_inf; u]``) and weights are those of the kinematic
designs. The controllers measure only ``d``, ``theta_e`` (and integrate ``d``): the gain is a static
output feedback ``u = K [d, theta_e(, int d)]``. Its convex LMI form (a block-diagonal Lyapunov
matrix, the usual sufficient condition) is infeasible on this plant, where the command reaches the
errors only through unmeasured states (measured: the LMI solver reports it infeasible at every
friction of the robot set). :func:`dynamic_mixed` therefore minimises the mixed criterion itself,
``alpha ||T_{w->z_inf}||_inf^2 + beta ||T_{w->z2}||_2^2`` with the true norms
(:mod:`pfjax.synthesis.norms`), over the output-feedback gain by Nelder-Mead search started from the
kinematic LMI design (a local optimum of a non-convex problem; no LMI bound is claimed); over several
plants (speeds and frictions) it minimises the largest criterion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm, is_hurwitz
from pfjax.synthesis.plant import Plant


def dynamic_design_plant(a_lat, b_lat, v: float, l_r: float, L: float, tau: float, integral: bool = False) -> Plant:
    """The design plant of the module docstring.

    Args:
        a_lat, b_lat: the lateral-yaw matrices (2, 2) and (2, 1) at ``v``.
        v: speed, m/s. l_r: centre of mass to rear axle, m. L: wheelbase, m.
        tau: steering actuator time constant, s.
        integral: augment with ``int d`` (the third measured state).

    Returns:
        A :class:`Plant` with ``n_x = 5`` (6 with integral action), the measured states first.
    """
    v, l_r, L, tau = float(v), float(l_r), float(L), float(tau)
    if not (v > 0 and L > 0 and tau > 0):
        raise ValueError(f"dynamic_design_plant needs v, L, tau > 0, got v={v}, L={L}, tau={tau}")
    m = 3 if integral else 2  # measured states
    n = m + 3
    i_r, i_b, i_d = m, m + 1, m + 2  # psi_dot, beta, delta
    A = np.zeros((n, n))
    A[0, 1], A[0, i_b], A[0, i_r] = v, v, -l_r
    A[1, i_r] = 1.0
    if integral:
        A[2, 0] = 1.0
    A[i_r : i_b + 1, i_r : i_b + 1] = np.asarray(a_lat, float)
    A[i_r : i_b + 1, i_d] = np.asarray(b_lat, float).ravel()
    A[i_d, i_d] = -1.0 / tau
    Bu = np.zeros((n, 1))
    Bu[i_d, 0] = 1.0 / tau
    Bw = np.zeros((n, 3))
    Bw[0, 0] = v
    Bw[1] = [-v / L, -v / L, -v]
    Cinf = np.hstack([np.eye(m), np.zeros((m, 3))])
    return Plant(
        A=A,
        Bw=Bw,
        Bu=Bu,
        Cinf=Cinf,
        Dinf_u=np.zeros((m, 1)),
        C2=np.vstack([Cinf, np.zeros((1, n))]),
        D2u=np.vstack([np.zeros((m, 1)), [[1.0]]]),
    )


@dataclass(frozen=True)
class OutputFeedbackDesign:
    """A gain on the measured states designed by :func:`dynamic_mixed`.

    Attributes:
        K: (1, m) gain of ``u = K [d, theta_e(, int d)]`` (rad/m, rad/rad(, rad/(m s))).
        K0: the start of the search (the kinematic design's gain).
        criterion: ``alpha hinf^2 + beta h2^2`` at ``K`` (the largest over the plants).
        criterion0: the same at ``K0`` (inf if ``K0`` does not stabilise every plant).
        hinf_norm, h2_norm: the largest true closed-loop norms over the plants at ``K``.
        max_pole_real: the largest real part of the closed-loop poles over the plants, 1/s.
        evaluations: criterion evaluations of the search.
    """

    K: np.ndarray
    K0: np.ndarray
    criterion: float
    criterion0: float
    hinf_norm: float
    h2_norm: float
    max_pole_real: float
    evaluations: int

    def to_dict(self) -> dict:
        return {k: (np.asarray(v).tolist() if k in ("K", "K0") else v) for k, v in self.__dict__.items()}


def _norms(plants: list[Plant], k_measured: np.ndarray) -> tuple[float, float, float]:
    """Largest ``hinf``, ``h2`` and pole real part over ``plants`` under ``u = [K, 0] x`` (inf, inf, pole
    if one is unstable)."""
    hn = h2n = 0.0
    pole = -np.inf
    for p in plants:
        K = np.zeros((1, p.A.shape[0]))
        K[0, : k_measured.size] = k_measured
        Acl, Bw, Ci, C2 = closed_loop(p, K)
        pole = max(pole, float(np.max(np.linalg.eigvals(Acl).real)))
        if not is_hurwitz(Acl):
            return np.inf, np.inf, pole
        hn, h2n = max(hn, hinf_norm(Acl, Bw, Ci)), max(h2n, h2_norm(Acl, Bw, C2))
    return hn, h2n, pole


def dynamic_mixed(plants: list[Plant], K0, *, alpha=10.0, beta=1.0, max_evaluations=3000) -> OutputFeedbackDesign:
    """The mixed criterion's output-feedback gain over ``plants`` (module docstring), from ``K0``.

    Args:
        plants: :func:`dynamic_design_plant` plants (same shapes).
        K0: start gain on the measured states, (m,) or (1, m); it must stabilise every plant.
        alpha, beta: the criterion's weights (the kinematic designs': 10, 1).
        max_evaluations: bound on the search's criterion evaluations.

    Raises:
        ValueError: ``K0`` does not stabilise every plant.
    """
    k0 = np.asarray(K0, float).ravel()

    def criterion(k):
        hn, h2n, _ = _norms(plants, k)
        return alpha * hn**2 + beta * h2n**2

    c0 = criterion(k0)
    if not np.isfinite(c0):
        raise ValueError(f"K0: {k0.tolist()} does not stabilise every plant")
    res = minimize(
        criterion, k0, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-10, "maxfev": max_evaluations}
    )
    k = np.asarray(res.x, float)
    hn, h2n, pole = _norms(plants, k)
    return OutputFeedbackDesign(k.reshape(1, -1), k0.reshape(1, -1), float(res.fun), c0, hn, h2n, pole, int(res.nfev))
