"""The slip models (docs/reproductions/path-following.md §1-2) against hand-derived steady states, closed forms and solve_ivp.

References are written here from the equations of docs/reproductions/path-following.md (or derived independently, e.g. the
velocity as speed ``v / cos beta_r`` along the course angle ``theta + beta_r``), never by
calling pfjax. Tolerances: closed forms at 1e-13 (a few ulps of the trigonometry); solve_ivp
comparisons at 1e-8 with DOP853 at rtol 1e-12, atol 1e-13 over 6 s (a sign error or a
missing ``cos beta_r`` shows up at 1e-2 or more).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pfjax.models import LENAIN, SOURCE, FrenetState, Pose, SlipParams, frenet_rhs, max_curvature, world_rhs, yaw_rate

DEG = math.pi / 180
B5 = 5 * DEG


def params(convention=SOURCE, v=1.0, L=0.2, delta_max=30 * DEG):
    return SlipParams(v=v, L=L, delta_max=delta_max, convention=convention)


def test_source_line_steady_state_needs_10_degrees():
    """Source convention, beta_r = beta_f = 5 deg: zero yaw rate needs tan(delta - 5) = tan 5, i.e.
    delta = 10 deg (the source's line test). With theta_e = -beta_r the course angle theta + beta_r
    is the line's direction, so the robot stays on the line (d' = 0)."""
    p = params(SOURCE)
    assert abs(float(yaw_rate(10 * DEG, B5, B5, p))) < 1e-14
    assert abs(float(yaw_rate(0.0, B5, B5, p))) > 0.8  # (1/0.2)(tan(-5) - tan 5) = -0.875 rad/s
    np.testing.assert_allclose(float(yaw_rate(0.0, B5, B5, p)), 5 * (math.tan(-B5) - math.tan(B5)), rtol=1e-14)
    line_dir = math.pi / 4
    rate = world_rhs(Pose(jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(line_dir - B5)), 10 * DEG, B5, B5, p)
    # Velocity along the line y = x, no yaw: the steady state [d, theta_e] = [0, -beta_r].
    assert abs(float(rate.theta)) < 1e-14
    assert abs(float(rate.x) - float(rate.y)) < 1e-15
    np.testing.assert_allclose(math.hypot(float(rate.x), float(rate.y)), 1 / math.cos(B5), rtol=1e-14)


def test_lenain_line_steady_state_needs_zero_steering():
    """Lenain convention: theta' = v cos(beta_r)/L (tan(delta + beta_f) - tan beta_r), so the
    straight-line steady state needs delta = beta_r - beta_f = 0 for equal slip angles."""
    p = params(LENAIN)
    assert abs(float(yaw_rate(0.0, B5, B5, p))) < 1e-14
    br, bf = 7 * DEG, 3 * DEG
    assert abs(float(yaw_rate(br - bf, br, bf, p))) < 1e-14
    # The cos(beta_r) factor: at delta = 10 deg the rate is cos(5 deg) times the bare bracket.
    bracket = (1 / 0.2) * (math.tan(15 * DEG) - math.tan(B5))
    np.testing.assert_allclose(float(yaw_rate(10 * DEG, B5, B5, p)), math.cos(B5) * bracket, rtol=1e-14)
    assert abs(float(yaw_rate(10 * DEG, B5, B5, p)) - bracket) > 1e-3  # the factor matters


def test_rates_match_the_equations_for_random_inputs():
    """yaw_rate and world_rhs for random inputs, both conventions, vmapped over SlipParams (a
    pytree): the translation as speed v/cos(beta_r) along the course angle theta + beta_r."""
    rng = np.random.default_rng(3)
    n = 64
    delta, br, bf = (rng.uniform(-0.5, 0.5, n) for _ in range(3))
    theta, v, L = rng.uniform(-4, 4, n), rng.uniform(0.2, 3, n), rng.uniform(0.1, 2, n)
    conv = rng.integers(0, 2, n)
    p = SlipParams(
        v=jnp.asarray(v),
        L=jnp.asarray(L),
        delta_max=jnp.full(n, 0.5),
        convention=jnp.asarray(conv),
        delta_rate_max=jnp.full(n, jnp.inf),
    )  # vmap maps every field: batch them all
    pose = Pose(jnp.asarray(rng.normal(size=n)), jnp.asarray(rng.normal(size=n)), jnp.asarray(theta))
    r = jax.jit(jax.vmap(world_rhs))(pose, jnp.asarray(delta), jnp.asarray(br), jnp.asarray(bf), p)
    speed = v / np.cos(br)
    np.testing.assert_allclose(np.asarray(r.x), speed * np.cos(theta + br), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(np.asarray(r.y), speed * np.sin(theta + br), rtol=1e-13, atol=1e-13)
    src = v / L * (np.tan(delta - bf) - np.tan(br))
    len_ = v * np.cos(br) / L * (np.tan(delta + bf) - np.tan(br))
    np.testing.assert_allclose(np.asarray(r.theta), np.where(conv == LENAIN, len_, src), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("convention", [SOURCE, LENAIN])
def test_zero_slip_is_the_kinematic_bicycle(convention):
    """With beta_r = beta_f = 0 both conventions are x' = v cos theta, y' = v sin theta,
    theta' = v tan(delta)/L."""
    p = params(convention, v=1.7, L=0.35)
    for delta, theta in [(0.3, 0.2), (-0.45, 2.5), (0.0, -1.0)]:
        r = world_rhs(Pose(jnp.asarray(0.0), jnp.asarray(0.0), jnp.asarray(theta)), delta, 0.0, 0.0, p)
        np.testing.assert_allclose(
            [float(r.x), float(r.y), float(r.theta)],
            [1.7 * math.cos(theta), 1.7 * math.sin(theta), 1.7 * math.tan(delta) / 0.35],
            rtol=1e-14,
            atol=1e-15,
        )


def _circumradius(p1, p2, p3):
    a, b, c = np.linalg.norm(p2 - p3), np.linalg.norm(p1 - p3), np.linalg.norm(p1 - p2)
    area2 = abs((p2[0] - p1[0]) * (p3[1] - p1[1]) - (p3[0] - p1[0]) * (p2[1] - p1[1]))
    return a * b * c / (2 * area2)


def _integrate_world(p, delta, br, bf, pose0, T, t_eval=None):
    f = jax.jit(lambda z: jnp.stack(world_rhs(Pose(*z), delta, br, bf, p)))
    sol = solve_ivp(
        lambda t, z: np.asarray(f(jnp.asarray(z))),
        (0, T),
        pose0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-13,
        t_eval=t_eval,
        dense_output=t_eval is None,
    )
    assert sol.success
    return sol


def test_max_curvature_is_the_tightest_turn():
    """kappa_max = tan(delta_max)/L (eq. 2) equals 1/radius of the circle the world model drives at
    full steering without slip (radius fitted from three integrated points). With slip the same fit
    gives the derived radius L / (cos beta_r (tan(delta - beta_f) - tan beta_r))."""
    p = params(SOURCE, v=1.3, L=0.25, delta_max=25 * DEG)
    np.testing.assert_allclose(float(max_curvature(p)), math.tan(25 * DEG) / 0.25, rtol=1e-14)
    for br, bf, radius in [
        (0.0, 0.0, 1 / float(max_curvature(p))),
        (B5, 2 * DEG, 0.25 / (math.cos(B5) * (math.tan(23 * DEG) - math.tan(B5)))),
    ]:
        sol = _integrate_world(p, 25 * DEG, br, bf, [0.3, -0.2, 0.4], 1.0, t_eval=[0.0, 0.4, 0.9])
        pts = sol.y[:2].T
        np.testing.assert_allclose(_circumradius(*pts), radius, rtol=1e-9)


CIRCLE_CASES = [
    # (convention, direction, delta, beta_r, beta_f, pose0 offset (radial, heading))
    (SOURCE, 1.0, math.atan(0.2 / 2.0) + 0.08 + 0.02, 0.05, 0.03, (0.15, 0.1)),
    (SOURCE, -1.0, -math.atan(0.2 / 2.0) + 0.03, -0.04, 0.02, (-0.2, -0.15)),
    (LENAIN, 1.0, math.atan(0.2 / 2.0) - 0.01, 0.06, -0.03, (-0.25, 0.2)),
]


@pytest.mark.parametrize("case", CIRCLE_CASES, ids=["source-ccw", "source-cw", "lenain-ccw"])
def test_frenet_model_agrees_with_world_model_on_a_circle(case):
    """Integrate world_rhs (solve_ivp), measure (d, theta_e, s) against a circle of radius R by exact
    geometry (d = +-(R - r), theta_p = phi +- pi/2, s = +-R (phi - phi0) unwrapped), and integrate
    frenet_rhs with kappa = +-1/R from the matching initial state: they agree to 1e-8 over 6 s."""
    conv, direction, delta, br, bf, (dr, dth) = case
    R, cx, cy, phi0 = 2.0, 0.4, -0.3, -math.pi / 2
    p = params(conv)
    # Start near the circle's point at phi0, offset radially by dr and in heading by dth.
    x0, y0 = cx + (R - dr) * math.cos(phi0), cy + (R - dr) * math.sin(phi0)
    th0 = phi0 + direction * math.pi / 2 + dth
    t = np.linspace(0.0, 6.0, 25)
    world = _integrate_world(p, delta, br, bf, [x0, y0, th0], 6.0, t_eval=t)
    x, y, th = world.y
    phi = np.unwrap(np.arctan2(y - cy, x - cx))
    r = np.hypot(x - cx, y - cy)
    d_geo = direction * (R - r)
    te_geo = np.angle(np.exp(1j * (th - (phi + direction * math.pi / 2))))
    s_geo = direction * R * (phi - phi0)
    assert np.all(1 - d_geo * direction / R > 0.5)  # well inside the Frenet model's valid region

    kappa = direction / R
    f = jax.jit(lambda z: jnp.stack(frenet_rhs(FrenetState(*z), delta, br, bf, kappa, p)))
    z0 = [d_geo[0], te_geo[0], s_geo[0]]
    fr = solve_ivp(
        lambda _, z: np.asarray(f(jnp.asarray(z))), (0, 6.0), z0, method="DOP853", rtol=1e-12, atol=1e-13, t_eval=t
    )
    assert fr.success
    np.testing.assert_allclose(fr.y[0], d_geo, atol=1e-8)
    np.testing.assert_allclose(np.angle(np.exp(1j * (fr.y[1] - te_geo))), 0.0, atol=1e-8)
    np.testing.assert_allclose(fr.y[2], s_geo, atol=1e-8)
    assert np.ptp(d_geo) > 0.05 and np.ptp(te_geo) > 0.05  # the errors really evolve


def test_frenet_rhs_matches_the_equations():
    """frenet_rhs against eq. 4/6 written out, including the 1/(1 - kappa d) factor."""
    p = params(SOURCE, v=1.4, L=0.3)
    d, te, s, delta, br, bf, kappa = 0.3, -0.4, 2.0, 0.2, 0.05, -0.02, 1.5
    r = frenet_rhs(FrenetState(jnp.asarray(d), jnp.asarray(te), jnp.asarray(s)), delta, br, bf, kappa, p)
    sdot = 1.4 * (math.cos(te) - math.tan(br) * math.sin(te)) / (1 - kappa * d)
    np.testing.assert_allclose(
        [float(r.d), float(r.theta_e), float(r.s)],
        [
            1.4 * (math.sin(te) + math.tan(br) * math.cos(te)),
            1.4 / 0.3 * (math.tan(delta - bf) - math.tan(br)) - kappa * sdot,
            sdot,
        ],
        rtol=1e-14,
    )


@pytest.mark.parametrize("convention", ["source", "lenain"])
def test_the_straight_line_steering_has_the_conventions_front_slip_sign(convention):
    """FRONT_SLIP_SIGN: the steering delta* = beta_r + sign beta_f holds a straight line (zero yaw
    rate) in each convention; the study's slip map draws its limit |delta*| = delta_max with it."""
    import math

    from pfjax.models.slip import CONVENTIONS, FRONT_SLIP_SIGN, SlipParams, yaw_rate

    code = CONVENTIONS[convention]
    p = SlipParams(1.0, 0.2, math.radians(30.0), code)
    for br, bf in ((0.05, 0.03), (-0.04, 0.07)):
        delta = br + FRONT_SLIP_SIGN[code] * bf
        assert abs(float(yaw_rate(delta, br, bf, p))) < 1e-12
