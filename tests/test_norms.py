"""H2 / H-infinity norms against independent references (time-domain integrals, frequency sweeps,
closed forms)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate as si
import scipy.linalg as sla
import scipy.optimize as so

from pfjax.synthesis import closed_loop, h2_norm, hinf_norm, slip_design_plant


def random_stable(n, m, p, seed, margin=0.2, with_d=False):
    """Random (A, B, C, D) with every eigenvalue of A at real part <= -margin."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + margin) * np.eye(n)
    B = rng.normal(size=(n, m))
    C = rng.normal(size=(p, n))
    D = rng.normal(size=(p, m)) if with_d else np.zeros((p, m))
    return A, B, C, D


def lightly_damped(zeta=2e-3, wn=3.0):
    """Non-square MIMO system with a sharp resonance at ~wn (damping zeta) plus a fast mode."""
    A = np.array([[0.0, 1.0, 0.0], [-(wn**2), -2.0 * zeta * wn, 0.5], [0.0, 0.0, -4.0]])
    B = np.array([[0.0, 1.0], [1.0, 0.0], [0.3, 1.0]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 0.2, 1.0], [0.5, 0.0, -1.0]])
    return A, B, C, np.zeros((3, 2))


# --- H2: independent reference  ||G||_2^2 = int_0^inf ||C e^{At} B||_F^2 dt ----------------------


def h2_time_integral(A, B, C):
    decay = -np.max(np.linalg.eigvals(A).real)
    T = 40.0 / decay  # tail below e^-80

    def f(t):
        return float(np.sum((C @ sla.expm(A * t) @ B) ** 2))

    edges = np.linspace(0.0, T, 41)
    total = sum(si.quad(f, a, b, epsabs=0.0, epsrel=1e-11, limit=200)[0] for a, b in zip(edges[:-1], edges[1:]))
    return np.sqrt(total)


@pytest.mark.parametrize("n,m,p,seed", [(1, 1, 1, 0), (2, 3, 2, 1), (4, 2, 3, 2), (5, 1, 4, 3), (3, 4, 1, 4)])
def test_h2_matches_time_domain_integral(n, m, p, seed):
    A, B, C, _ = random_stable(n, m, p, seed)
    assert h2_norm(A, B, C) == pytest.approx(h2_time_integral(A, B, C), rel=1e-6)


def test_h2_lightly_damped_matches_frequency_integral():
    # ||G||_2^2 = (1/pi) int_0^inf ||G(jw)||_F^2 dw, with the resonance split out for quad.
    A, B, C, _ = lightly_damped()
    n = A.shape[0]

    def f(w):
        return float(np.sum(np.abs(C @ np.linalg.solve(1j * w * np.eye(n) - A, B)) ** 2))

    pts = [0.0, 2.9, 2.99, 3.0, 3.01, 3.1, 10.0, np.inf]
    total = sum(si.quad(f, a, b, epsabs=0.0, epsrel=1e-12, limit=500)[0] for a, b in zip(pts[:-1], pts[1:]))
    assert h2_norm(A, B, C) == pytest.approx(np.sqrt(total / np.pi), rel=1e-6)


def test_h2_closed_forms():
    a = 2.5
    assert h2_norm([[-a]], [[1.0]], [[1.0]]) == pytest.approx(1.0 / np.sqrt(2.0 * a), rel=1e-12)
    zeta, wn = 0.3, 2.0  # wn^2 / (s^2 + 2 zeta wn s + wn^2): ||.||_2^2 = wn / (4 zeta)
    A = [[0.0, 1.0], [-(wn**2), -2.0 * zeta * wn]]
    assert h2_norm(A, [[0.0], [wn**2]], [[1.0, 0.0]]) == pytest.approx(np.sqrt(wn / (4.0 * zeta)), rel=1e-12)


def test_h2_infinite_when_unstable_or_feedthrough():
    assert h2_norm([[0.1]], [[1.0]], [[1.0]]) == np.inf
    assert h2_norm([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]]) == np.inf
    assert h2_norm([[-1.0]], [[1.0]], [[1.0]], [[0.5]]) == np.inf


# --- H-infinity: dense frequency sweep + local refinement -----------------------------------------


def sigma_max(A, B, C, D, w):
    n = A.shape[0]
    return np.linalg.norm(C @ np.linalg.solve(1j * w * np.eye(n) - A, B) + D, 2)


def hinf_sweep(A, B, C, D):
    poles = np.linalg.eigvals(A)
    lo = max(1e-4, 1e-3 * np.min(np.abs(poles)))
    hi = 1e3 * np.max(np.abs(poles))
    grid = np.concatenate([[0.0], np.geomspace(lo, hi, 4000)])
    for p in poles:  # dense linear grids across every resonance
        w0, half = abs(p.imag), max(abs(p.real), 1e-9)
        grid = np.concatenate([grid, w0 + half * np.linspace(-20.0, 20.0, 801)])
    grid = np.unique(grid[grid >= 0.0])
    vals = np.array([sigma_max(A, B, C, D, w) for w in grid])
    best = max(vals.max(), np.linalg.norm(D, 2))
    for i in np.argsort(vals)[-5:]:  # refine the top grid points between their neighbours
        a = grid[max(i - 1, 0)]
        b = grid[min(i + 1, grid.size - 1)]
        if b > a:
            res = so.minimize_scalar(
                lambda w: -sigma_max(A, B, C, D, w),
                bounds=(a, b),
                method="bounded",
                options={"xatol": 1e-14 * max(1.0, b)},
            )
            best = max(best, -res.fun)
    return best


@pytest.mark.parametrize(
    "n,m,p,seed,with_d",
    [(2, 1, 1, 10, False), (3, 2, 4, 11, False), (4, 3, 2, 12, True), (6, 2, 3, 13, False), (5, 4, 1, 14, True)],
)
def test_hinf_matches_frequency_sweep(n, m, p, seed, with_d):
    A, B, C, D = random_stable(n, m, p, seed, with_d=with_d)
    assert hinf_norm(A, B, C, D) == pytest.approx(hinf_sweep(A, B, C, D), rel=1e-6)


def test_hinf_lightly_damped_sharp_peak():
    A, B, C, D = lightly_damped()
    ref = hinf_sweep(A, B, C, D)
    assert ref > 50.0  # the resonance dominates
    assert hinf_norm(A, B, C, D) == pytest.approx(ref, rel=1e-6)


def test_hinf_closed_forms():
    a = 0.7
    assert hinf_norm([[-a]], [[1.0]], [[1.0]]) == pytest.approx(1.0 / a, rel=1e-8)
    for zeta in (0.05, 0.2, 0.5):
        wn = 1.7
        A = [[0.0, 1.0], [-(wn**2), -2.0 * zeta * wn]]
        peak = 1.0 / (2.0 * zeta * np.sqrt(1.0 - zeta**2))
        assert hinf_norm(A, [[0.0], [wn**2]], [[1.0, 0.0]]) == pytest.approx(peak, rel=1e-7)
    # zeta >= 1/sqrt(2): no resonance, the peak is the DC gain 1
    A = [[0.0, 1.0], [-1.0, -2.0]]
    assert hinf_norm(A, [[0.0], [1.0]], [[1.0, 0.0]]) == pytest.approx(1.0, rel=1e-8)
    # pure feed-through
    assert hinf_norm([[-1.0]], [[0.0, 0.0]], [[0.0]], [[3.0, 4.0]]) == pytest.approx(5.0)


def test_hinf_infinite_when_not_hurwitz():
    assert hinf_norm([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], [[1.0, 0.0]]) == np.inf


def test_closed_loop_of_slip_plant():
    P = slip_design_plant(v=2.0, L=0.5)
    K = np.array([[-1.0, -2.0]])
    Acl, Bw, Cinf, C2 = closed_loop(P, K)
    np.testing.assert_allclose(Acl, [[0.0, 2.0], [-4.0, -8.0]])
    np.testing.assert_allclose(Bw, [[2.0, 0.0, 0.0], [-4.0, -4.0, -2.0]])
    np.testing.assert_allclose(Cinf, np.eye(2))
    np.testing.assert_allclose(C2, [[1.0, 0.0], [0.0, 1.0], [-1.0, -2.0]])


def test_hinf_norm_is_a_lower_bound_within_rtol():
    """hinf_norm's value is a lower bound of the norm within rtol (relative), checked against the
    peak of sigma_max(G(jw)) refined by a bounded scalar search to 1e-13 (scipy) around the best of
    a dense log grid, on random stable systems with a resonance."""
    import numpy as np
    from scipy.optimize import minimize_scalar

    from pfjax.synthesis.norms import hinf_norm

    rng = np.random.default_rng(3)
    for _ in range(5):
        n = 4
        A = rng.standard_normal((n, n))
        A = A - (np.max(np.linalg.eigvals(A).real) + 0.05) * np.eye(n)  # stable, lightly damped
        B, C = rng.standard_normal((n, 2)), rng.standard_normal((2, n))

        def smax(w, A=A, B=B, C=C):
            return np.linalg.svd(C @ np.linalg.solve(1j * w * np.eye(n) - A, B), compute_uv=False)[0]

        grid = np.concatenate([[0.0], np.logspace(-3, 3, 20001)])
        k = int(np.argmax([smax(w) for w in grid]))
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        r = minimize_scalar(lambda w: -smax(w), bounds=(lo, hi), method="bounded", options={"xatol": 1e-13})
        ref = max(-r.fun, smax(grid[k]))
        for rtol in (1e-4, 1e-8):
            got = hinf_norm(A, B, C, rtol=rtol)
            assert ref * (1 - rtol) - 1e-12 <= got <= ref * (1 + 1e-12), (rtol, got, ref)
