"""Equilibria and local stability of the state-feedback loop under constant slip (docs/reproductions/path-following.md §7).

References used here, none taken from pfjax.analysis:

* **Closed-form equilibrium on a line** (derived from docs/reproductions/path-following.md §2 eq. 6): ``d' = 0`` with forward
  travel forces ``theta_e* = -beta_r``; ``theta_e' = 0`` with ``kappa = 0`` forces the yaw rate to
  vanish, ``tan(delta* - beta_f) = tan(beta_r)`` -> ``delta* = beta_r + beta_f`` (source
  convention) or ``tan(delta* + beta_f) = tan(beta_r)`` -> ``delta* = beta_r - beta_f`` (Lenain);
  ``K x* = delta*`` gives ``d* = (delta* + K_2 beta_r) / K_1``. With saturation the yaw rate can
  only vanish if ``|delta*| < delta_max``.
* **Closed-form Jacobian on a line.** With ``delta = K_1 d + K_2 theta_e``::

      d d'/d d        = 0
      d d'/d theta_e  = v (cos theta_e - tan beta_r sin theta_e)       = v / cos beta_r   at theta_e = -beta_r
      d theta_e'/d d  = (v/L) sec^2(delta - beta_f) K_1                = a K_1
      d theta_e'/d th = (v/L) sec^2(delta - beta_f) K_2                = a K_2

  with ``a = (v/L) sec^2(beta_r)`` at the equilibrium (``delta* - beta_f = beta_r``), so the
  characteristic polynomial is ``s^2 - a K_2 s - (v / cos beta_r) a K_1``. In Lenain's convention
  the yaw rate is ``cos(beta_r) (v/L)(tan(delta + beta_f) - tan beta_r)`` and
  ``delta* + beta_f = beta_r``, so ``a = (v/L) / cos(beta_r)``. At the source's point
  ``[0, -beta_r]`` (not an equilibrium) the same algebra gives ``a = (v/L) sec^2(-K_2 beta_r - beta_f)``.
* **Central finite differences** of ``closed_loop_field`` and ``numpy.linalg.eigvals``.
* **A NumPy transcription of the Frenet model** (docs/reproductions/path-following.md §2) to check the field itself.
* **scipy ``brentq``** on the scalar equilibrium equation on a circle, and pfjax's simulator
  (world-frame model, measured against the path) for convergence to it.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from pfjax import controllers as C
from pfjax.analysis import closed_loop_field, equilibrium, source_linearisation, stability_map
from pfjax.models.slip import FrenetState, SlipParams, frenet_rhs
from pfjax.sim import SimConfig, simulate_batch, stack, unstack
from pfjax.sim.scenario import paper_scenario

K = np.array(C.PAPER_K, dtype=float)  # source's K = [-2.7381, -2.0772]
V, L, DMAX = 1.0, 0.2, math.radians(30.0)
SOURCE = SlipParams(V, L, DMAX, 0)
LENAIN = SlipParams(V, L, DMAX, 1)
# Grid step 12 deg: beta_r +- beta_f is a multiple of 12 deg, never exactly +-30 deg = +-delta_max,
# so "exists" is never decided by rounding at the boundary.
GRID_DEG = np.linspace(-42.0, 42.0, 8)

equilibrium_jit = jax.jit(equilibrium, static_argnames="iters")
field_jit = jax.jit(closed_loop_field, static_argnames="saturate")


def field_np(x, br, bf, kappa, params: SlipParams, saturate=True):
    """docs/reproductions/path-following.md §2 eq. 6 with delta = sat(K x), written in NumPy (independent of pfjax)."""
    d, th = x
    v, Lw, dmax = params.v, params.L, params.delta_max
    delta = K[0] * d + K[1] * th
    if saturate:
        delta = min(max(delta, -dmax), dmax)
    if params.convention == 0:
        yaw = (v / Lw) * (math.tan(delta - bf) - math.tan(br))
    else:
        yaw = math.cos(br) * (v / Lw) * (math.tan(delta + bf) - math.tan(br))
    s_dot = v * (math.cos(th) - math.tan(br) * math.sin(th)) / (1 - kappa * d)
    return np.array([v * (math.sin(th) + math.tan(br) * math.cos(th)), yaw - kappa * s_dot])


def fd_jacobian(x, br, bf, kappa, params, saturate, h=1e-6):
    """Central differences of pfjax's closed_loop_field; truncation O(h^2 f''') ~ 1e-10 here."""
    J = np.zeros((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        fp = np.asarray(field_jit(jnp.asarray(x + e), jnp.asarray(K), br, bf, kappa, params, saturate))
        fm = np.asarray(field_jit(jnp.asarray(x - e), jnp.asarray(K), br, bf, kappa, params, saturate))
        J[:, j] = (fp - fm) / (2 * h)
    return J


def sorted_eig(z):
    z = np.asarray(z, complex)
    return z[np.lexsort((z.imag, z.real))]


def char_poly_roots(br, a):
    """Roots of s^2 - a K_2 s - (v / cos br) a K_1 (see module docstring)."""
    return sorted_eig(np.roots([1.0, -a * K[1], -(V / math.cos(br)) * a * K[0]]))


@pytest.fixture(scope="module", params=["source", "lenain"])
def grid_map(request):
    params = SOURCE if request.param == "source" else LENAIN
    eq, src = stability_map(jnp.asarray(K), jnp.radians(GRID_DEG), jnp.radians(GRID_DEG), params)
    BR, BF = np.meshgrid(np.radians(GRID_DEG), np.radians(GRID_DEG), indexing="ij")
    return request.param, params, eq, src, BR, BF


def test_field_matches_numpy_transcription_of_spec():
    """The field the analysis linearises is docs/reproductions/path-following.md §2 eq. 6 (both conventions, line and circle, saturated)."""
    rng = np.random.default_rng(0)
    for params in (SOURCE, LENAIN):
        for _ in range(6):
            x = rng.uniform([-0.5, -0.8], [0.5, 0.8])
            br, bf = rng.uniform(-0.6, 0.6, 2)
            kappa = rng.choice([0.0, 0.5, -0.3])
            for sat in (True, False):
                got = np.asarray(field_jit(jnp.asarray(x), jnp.asarray(K), br, bf, kappa, params, sat))
                np.testing.assert_allclose(got, field_np(x, br, bf, kappa, params, sat), rtol=1e-12, atol=1e-12)


def test_equilibrium_on_line_matches_closed_form(grid_map):
    """theta_e* = -beta_r, delta* = beta_r +- beta_f, d* = (delta* + K_2 beta_r) / K_1, exists iff
    |delta*| < delta_max. Tolerance 1e-12: closed form vs a Newton iteration started on it."""
    conv, params, eq, _, BR, BF = grid_map
    delta_star = BR + BF if conv == "source" else BR - BF
    d_star = (delta_star + K[1] * BR) / K[0]
    np.testing.assert_allclose(np.asarray(eq.theta_e), -BR, atol=1e-14)
    np.testing.assert_allclose(np.asarray(eq.delta), delta_star, atol=1e-12)
    np.testing.assert_allclose(np.asarray(eq.d), d_star, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(eq.exists), np.abs(delta_star) < DMAX)
    # both outcomes occur on this grid, so the check can fail either way
    assert np.asarray(eq.exists).any() and not np.asarray(eq.exists).all()
    # where it exists it is a rest point of the *saturated* loop (the simulated one)
    for i, j in zip(*np.nonzero(np.asarray(eq.exists))):
        x = np.array([float(eq.d[i, j]), float(eq.theta_e[i, j])])
        assert np.abs(field_np(x, BR[i, j], BF[i, j], 0.0, params)).max() < 1e-12


def test_no_rest_point_beyond_the_steering_limit():
    """Where |beta_r + beta_f| >= delta_max the saturated yaw rate has a fixed sign on theta_e = -beta_r."""
    br, bf = math.radians(20.0), math.radians(20.0)  # delta* = 40 deg > 30 deg
    eq = equilibrium_jit(jnp.asarray(K), br, bf, SOURCE)
    assert not bool(eq.exists) and not bool(eq.hurwitz)
    ds = np.linspace(-5, 5, 201)
    yaw = [field_np(np.array([d, -br]), br, bf, 0.0, SOURCE)[1] for d in ds]
    assert np.all(np.array(yaw) < 0) or np.all(np.array(yaw) > 0)


def test_eigenvalues_match_finite_difference_jacobian(grid_map):
    """Jacobian eigenvalues at the true equilibrium vs eigvals of a central-difference Jacobian.

    Tolerance rel 1e-6: FD truncation ~h^2 |f'''| ~ 1e-10 and round-off ~eps |f| / h ~ 1e-10, on
    eigenvalues of size 1-20 1/s.
    """
    conv, params, eq, _, BR, BF = grid_map
    checked = 0
    for i, j in zip(*np.nonzero(np.asarray(eq.exists))):
        if (i + j) % 3:  # a spread subset keeps the test fast
            continue
        x = np.array([float(eq.d[i, j]), float(eq.theta_e[i, j])])
        J = fd_jacobian(x, BR[i, j], BF[i, j], 0.0, params, saturate=True)
        np.testing.assert_allclose(sorted_eig(eq.eig[i, j]), sorted_eig(np.linalg.eigvals(J)), rtol=1e-6)
        checked += 1
    assert checked >= 4


def test_eigenvalues_match_closed_form_characteristic_polynomial(grid_map):
    """s^2 - a K_2 s - (v/cos beta_r) a K_1 with a = (v/L) sec^2 beta_r (source) or (v/L)/cos beta_r
    (Lenain), at every grid point where the equilibrium exists. Tolerance rel 1e-9 (closed forms)."""
    conv, params, eq, _, BR, BF = grid_map
    ex = np.asarray(eq.exists)
    for i, j in zip(*np.nonzero(ex)):
        br = BR[i, j]
        a = (V / L) / math.cos(br) ** 2 if conv == "source" else (V / L) / math.cos(br)
        np.testing.assert_allclose(sorted_eig(eq.eig[i, j]), char_poly_roots(br, a), rtol=1e-9)
    # K_1, K_2 < 0 and a > 0: both coefficients positive, so Hurwitz wherever it exists
    np.testing.assert_array_equal(np.asarray(eq.hurwitz), ex)


def test_source_linearisation_is_the_jacobian_at_zero_minus_beta_r(grid_map):
    """The source's appendix-B eigenvalues: Jacobian of the unsaturated loop at [0, -beta_r]."""
    conv, params, _, src, BR, BF = grid_map
    for i, j in [(1, 2), (3, 4), (4, 3), (6, 1), (2, 6)]:
        br, bf = BR[i, j], BF[i, j]
        got = sorted_eig(src[i, j])
        J = fd_jacobian(np.array([0.0, -br]), br, bf, 0.0, params, saturate=False)
        np.testing.assert_allclose(got, sorted_eig(np.linalg.eigvals(J)), rtol=1e-6)
        direct = sorted_eig(source_linearisation(jnp.asarray(K), br, bf, params))
        np.testing.assert_allclose(direct, got, rtol=1e-12)
        if conv == "source":
            a = (V / L) / math.cos(-K[1] * br - bf) ** 2
            np.testing.assert_allclose(got, char_poly_roots(br, a), rtol=1e-9)


def test_source_point_is_not_an_equilibrium_for_the_paper_case():
    """beta_r = beta_f = 5 deg: [0, -beta_r] has theta_e' != 0 (delta* = -K_2 beta_r only if K_2 = -2)."""
    b = math.radians(5.0)
    f = field_np(np.array([0.0, -b]), b, b, 0.0, SOURCE)
    assert abs(f[0]) < 1e-15 and abs(f[1]) > 1e-2
    eq = equilibrium_jit(jnp.asarray(K), b, b, SOURCE)
    assert float(eq.d) == pytest.approx((2 * b + K[1] * b) / K[0], abs=1e-13)
    assert 1e-3 < float(eq.d) < 3e-3  # 2.46 mm, not 0


@pytest.mark.parametrize("br_deg, bf_deg", [(5.0, 5.0), (-8.0, 3.0)])
def test_equilibrium_on_a_circle(br_deg, bf_deg):
    """kappa = 1/2 (pfjax's circle scenario). Rest point of frenet_rhs to 1e-10; d* agrees with
    brentq on the scalar equation (v/L)(tan(K_1 d - K_2 beta_r - beta_f) - tan beta_r)
    = kappa v / (cos beta_r (1 - kappa d)) to 1e-10 m; the world-frame simulation (continuous
    controller, RK4 5 ms, 20 s) ends within 1e-4 m of d* (slowest pole ~ -1.6 1/s: the transient
    has decayed by e^-30; RK4 error ~1e-7 m)."""
    br, bf, kappa = math.radians(br_deg), math.radians(bf_deg), 0.5
    eq = equilibrium_jit(jnp.asarray(K), br, bf, SOURCE, kappa)
    assert bool(eq.exists) and bool(eq.hurwitz)
    res = frenet_rhs(FrenetState(eq.d, eq.theta_e, 0.0), eq.delta, br, bf, kappa, SOURCE)
    assert abs(float(res.d)) < 1e-10 and abs(float(res.theta_e)) < 1e-10
    assert float(eq.theta_e) == pytest.approx(-br, abs=1e-14)

    g = lambda d: (
        (V / L) * (math.tan(K[0] * d - K[1] * br - bf) - math.tan(br)) - kappa * V / (math.cos(br) * (1 - kappa * d))
    )
    d_ref = brentq(g, -0.3, 0.3, xtol=1e-14)  # |K_1| 0.3 < pi/2 - |K_2 beta_r + beta_f|: tan stays on one branch
    assert float(eq.d) == pytest.approx(d_ref, abs=1e-10)
    # the curve shifts the rest point: it is not the line's
    d_line = ((br + bf) + K[1] * br) / K[0]
    assert abs(d_ref - d_line) > 1e-2

    x = np.array([float(eq.d), float(eq.theta_e)])
    J = fd_jacobian(x, br, bf, kappa, SOURCE, saturate=True)
    np.testing.assert_allclose(sorted_eig(eq.eig), sorted_eig(np.linalg.eigvals(J)), rtol=1e-6)

    sc = paper_scenario("circle", C.state_feedback_params(C.PAPER_K), beta_r_deg=br_deg, beta_f_deg=bf_deg)
    r = unstack(
        simulate_batch(
            stack([sc]), controller=C.state_feedback, config=SimConfig(control_every=None, horizon=20.0, record=False)
        ),
        0,
    )
    assert int(r.status) == 0
    assert float(r.final.d) == pytest.approx(float(eq.d), abs=1e-4)
    assert float(r.final.theta_e) == pytest.approx(-br, abs=1e-4)
    assert float(r.final.delta) == pytest.approx(float(eq.delta), abs=1e-3)


def _numpy_map(grid_deg, params: SlipParams):
    """(exists, hurwitz) on a line, independently: the closed-form equilibrium (d* from K x* = delta*,
    theta_e* = -beta_r), its existence |delta*| <= delta_max, and numpy.linalg.eigvals of a central
    finite-difference Jacobian of :func:`field_np` (unsaturated)."""
    n = len(grid_deg)
    exists, hurwitz, margin = np.zeros((n, n), bool), np.zeros((n, n), bool), np.zeros((n, n))
    for i, br in enumerate(np.radians(grid_deg)):
        for j, bf in enumerate(np.radians(grid_deg)):
            delta = br + bf if params.convention == 0 else br - bf
            x = np.array([(delta + K[1] * br) / K[0], -br])
            h = 1e-6
            J = np.stack(
                [
                    (field_np(x + e, br, bf, 0.0, params, False) - field_np(x - e, br, bf, 0.0, params, False))
                    / (2 * h)
                    for e in np.eye(2) * h
                ],
                axis=1,
            )
            exists[i, j] = abs(delta) <= params.delta_max
            hurwitz[i, j] = exists[i, j] and np.all(np.linalg.eigvals(J).real < 0)
            margin[i, j] = abs(abs(delta) - params.delta_max)
    return exists, hurwitz, margin


@pytest.mark.parametrize("grid_max", [10.0, 89.0])
def test_stability_map_is_right_in_float32_and_float64(grid_max):
    """The Hurwitz mask the report draws: float32 and float64 agree with an independent NumPy
    computation at every grid point off the steering-limit boundary (where rounding may decide).
    (A residual tolerance fixed at 1e-9 once made float32 reject most equilibria: a scrambled mask.)"""
    grid = np.linspace(-grid_max, grid_max, 48)
    exists, hurwitz, margin = _numpy_map(grid, SOURCE)
    clear = margin > 1e-4  # rad away from |delta*| = delta_max
    for x64 in (False, True):
        with jax.enable_x64(x64):
            eq, _ = stability_map(
                jnp.asarray(K, float),
                jnp.radians(jnp.asarray(grid, float)),
                jnp.radians(jnp.asarray(grid, float)),
                SOURCE,
            )
            np.testing.assert_array_equal(np.asarray(eq.exists)[clear], exists[clear])
            np.testing.assert_array_equal(np.asarray(eq.hurwitz)[clear], hurwitz[clear])
    assert clear.mean() > 0.9 and hurwitz[clear].any()


def test_the_pi_quasi_equilibrium_is_where_unsaturated_readings_settle():
    """pi_quasi_equilibrium's offset d_q = ki_theta beta_r / ki_d against the line test simulated
    with pfjax (5 deg of slip on each axle, the source's speed and wheelbase, continuous PI, 120 s or
    the path's end): the readings of Table 3 whose linearised loop decays faster than 0.1 1/s and
    whose steering ends off its limit end within 2 % of d_q (and 1e-5 m); the poles are those of the
    3x3 matrix of its docstring (numpy)."""
    import math

    import jax

    from pfjax import controllers as C
    from pfjax.analysis import pi_quasi_equilibrium
    from pfjax.models import SlipParams
    from pfjax.sim import SimConfig, simulate_batch, stack, unstack
    from pfjax.sim.scenario import paper_scenario

    with jax.enable_x64(True):
        readings = C.table3_assignments()
        params, br = SlipParams(1.0, 0.2, math.radians(30.0), 0), math.radians(5.0)
        scs = [
            paper_scenario("line", g, beta_r_deg=5.0, beta_f_deg=5.0, v=1.0, L=0.2, delta_max_deg=30.0)
            for g in readings.values()
        ]
        res = simulate_batch(stack(scs), controller=C.pi, config=SimConfig(control_every=None, horizon=120.0))
        checked = 0
        for i, g in enumerate(readings.values()):
            q = pi_quasi_equilibrium(g, br, params)
            r = unstack(res, i)
            saturated = abs(float(r.final.delta)) > math.radians(30.0) - 1e-6  # held at the limit
            if q.poles.real.max() < -0.1 and not saturated:
                assert float(r.final.d) == pytest.approx(q.d_q, rel=0.02, abs=1e-5)
                checked += 1
        assert checked >= 4


def test_the_pi_quasi_equilibrium_poles_are_the_models_jacobian():
    """The poles against the Jacobian (jax.jacfwd) of the loop built from the model and the
    controller themselves: frenet_rhs's d' and theta_e' under the PI's output (controllers.linear
    ``_pi_output``, its two integral terms summed in sigma) and sigma' from ``_pi_rate`` (no
    anti-windup), at (d_q, -beta_r, the sigma that steers beta_r + beta_f), where the field is 0;
    random gains, slips, speeds and wheelbases."""
    import math

    import jax
    import jax.numpy as jnp
    import numpy as np

    from pfjax import controllers as C
    from pfjax.analysis import pi_quasi_equilibrium
    from pfjax.controllers.base import Observation
    from pfjax.controllers.linear import _pi_output, _pi_rate
    from pfjax.models.slip import FrenetState, SlipParams, frenet_rhs

    rng = np.random.default_rng(0)
    with jax.enable_x64(True):
        for _ in range(6):
            g = C.pi_params(*(float(x) for x in rng.uniform([0.5, 0.02, 0.5, 0.01], [40, 12, 40, 12])))
            br, bf = (math.radians(x) for x in rng.uniform(-12, 12, 2))
            p = SlipParams(float(rng.uniform(0.3, 3)), float(rng.uniform(0.1, 1)), math.radians(30.0), 0)

            def field(x, g=g, br=br, bf=bf, p=p):
                d, th, sigma = x
                obs = Observation(
                    d=d, theta_e=th, kappa=0.0, s=0.0, u=0.0, pose=None, v=p.v, L=p.L, delta_max=p.delta_max, path=None
                )
                delta = _pi_output(g, jnp.stack([sigma, 0.0]), obs)
                f = frenet_rhs(FrenetState(d, th, 0.0), delta, br, bf, 0.0, p)
                return jnp.stack([f.d, f.theta_e, jnp.sum(_pi_rate(g, jnp.zeros(2), obs, delta, delta))])

            q = pi_quasi_equilibrium(g, br, p)
            sigma = br + bf + float(g.kp_d) * q.d_q - float(g.kp_theta) * br  # steers beta_r + beta_f
            x0 = jnp.array([q.d_q, -br, sigma])
            f0 = np.asarray(field(x0))
            assert abs(f0[0]) < 1e-12 and abs(f0[1]) < 1e-12  # at rest in d and theta_e; sigma ramps...
            assert abs(f0[2]) < 1e-12  # ...as a sum, not at all: the two integral terms cancel
            jac = np.asarray(jax.jacfwd(field)(x0))
            want, got = np.sort_complex(np.linalg.eigvals(jac)), np.sort_complex(q.poles)
            assert np.max(np.abs(got - want)) <= 1e-9 * np.max(np.abs(want))
