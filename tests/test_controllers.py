"""Controllers: closed-form outputs from exact geometry, the PI's discrete integrator and
anti-windup, and every controller converging in ``simulate_batch``.

The closed forms are derived here, not read from pfjax: pure pursuit on a circle (the chord of
length l_d subtends alpha = asin(l_d / 2R), so delta = atan(2 L sin(alpha) / l_d) = atan(L / R)),
rear-wheel feedback at zero error (omega = v kappa), Stanley with the front axle on a line.
Tolerances: closed forms at 1e-12 rad (the projections and the pure-pursuit goal search are
Newton iterations converged to machine precision).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.controllers import Observation
from pfjax.models import Pose
from pfjax.paths import circle, line, project
from pfjax.sim import SimConfig, simulate_batch, stack
from pfjax.sim.scenario import paper_scenario

DMAX = math.radians(30.0)
CFG = SimConfig(dt=0.01, horizon=20.0)  # sampled every step (zero-order hold over 10 ms)
POSES = [(1.0, 0.0, math.pi / 2), (0.0, 1.0, 0.0)]  # the source's line start; one left of the line
#: PI gains with a real integral on d (Table 3's ki_d = 0.023 barely winds up), started 2.8 m off.
WINDUP_GAINS = dict(kp_d=1.0, ki_d=0.5, kp_theta=1.5, ki_theta=0.0)
WINDUP_POSE = (4.0, 0.0, math.pi / 4)


def obs_at(path, x, y, theta, v=1.0, L=0.2, delta_max=DMAX) -> Observation:
    """The observation a controller gets for a pose (closest point by the cold projection)."""
    p = project(path, jnp.asarray(x), jnp.asarray(y), jnp.asarray(theta))
    return Observation(
        d=p.d,
        theta_e=p.theta_e,
        kappa=p.kappa,
        s=p.s,
        u=p.u,
        pose=Pose(jnp.asarray(x), jnp.asarray(y), jnp.asarray(theta)),
        v=jnp.asarray(v),
        L=jnp.asarray(L),
        delta_max=jnp.asarray(delta_max),
        path=path,
    )


def on_circle(path, u):
    """Pose exactly on the circle at arc length u, heading along the tangent."""
    x, y = path.point(jnp.asarray(u))
    dx, dy = path.d1(jnp.asarray(u))
    return float(x), float(y), math.atan2(float(dy), float(dx))


# ----------------------------------------------------------------------------- closed forms


@pytest.mark.parametrize("direction", [1.0, -1.0])
@pytest.mark.parametrize("R,v,L", [(2.0, 1.0, 0.2), (0.9, 0.3, 0.35), (5.0, 2.0, 0.5)])
def test_pure_pursuit_on_a_circle_steers_atan_L_over_R(direction, R, v, L):
    """On the circle, heading tangent: the goal point at distance l_d along the chord gives
    sin(alpha) = l_d / (2R), so delta = atan(L/R), signed by the turn (both l_d branches)."""
    path = circle(radius=R, cx=0.3, cy=-0.2, direction=direction)
    gains = C.pure_pursuit_params()
    obs = obs_at(path, *on_circle(path, 1.1), v=v, L=L)
    delta = float(C.pure_pursuit.output(gains, C.pure_pursuit.init(gains), obs))
    np.testing.assert_allclose(delta, direction * math.atan(L / R), atol=1e-12)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_rear_wheel_at_zero_error_steers_atan_L_kappa(direction):
    """Rear-wheel feedback with d = theta_e = 0 commands omega = v kappa, delta = atan(L kappa);
    off the path it follows its law (Paden et al. 2016) term by term."""
    R, L, v = 1.5, 0.2, 1.2
    path = circle(radius=R, direction=direction)
    gains = C.rear_wheel_params()
    obs = obs_at(path, *on_circle(path, 2.0), v=v, L=L)
    assert abs(float(obs.d)) < 1e-12 and abs(float(obs.theta_e)) < 1e-12
    delta = float(C.rear_wheel.output(gains, C.rear_wheel.init(gains), obs))
    np.testing.assert_allclose(delta, math.atan(L * direction / R), atol=1e-12)
    # Off the path: d = 0.2 (inside for CCW) and theta_e = 0.3.
    x, y, th = on_circle(path, 2.0)
    nx, ny = -math.sin(th), math.cos(th)
    obs = obs_at(path, x + 0.2 * nx, y + 0.2 * ny, th + 0.3, v=v, L=L)
    k = direction / R
    omega = v * k * math.cos(0.3) / (1 - k * 0.2) - 3.0 * v * 0.3 - 4.0 * v * (math.sin(0.3) / 0.3) * 0.2
    np.testing.assert_allclose(float(C.rear_wheel.output(gains, (), obs)), math.atan(L * omega / v), atol=1e-12)


@pytest.mark.parametrize("heading_error", [0.2, -0.35])
def test_stanley_with_front_axle_on_the_path_steers_minus_heading_error(heading_error):
    """Front axle exactly on the line y = x: d_f = 0, so delta = -theta_e,f; offset by 0.3 m to
    the left, delta = -theta_e,f - atan(k d_f / (k_soft + v))."""
    path, L, v = line(), 0.2, 1.0
    gains = C.stanley_params()
    th = math.pi / 4 + heading_error
    for d_f in (0.0, 0.3):
        fx, fy = 2.0 - d_f * math.sin(math.pi / 4), 2.0 + d_f * math.cos(math.pi / 4)
        obs = obs_at(path, fx - L * math.cos(th), fy - L * math.sin(th), th, v=v, L=L)
        expect = -heading_error - math.atan(2.5 * d_f / (0.1 + v))
        np.testing.assert_allclose(float(C.stanley.output(gains, (), obs)), expect, atol=1e-12)


def test_stanley_on_a_circle_uses_the_front_axle_tangent():
    """Front axle on a circle: d_f = 0 and theta_e,f = theta - theta_p(front), not the rear's."""
    R, L = 1.0, 0.2
    path = circle(radius=R)
    fx, fy, tp = on_circle(path, 0.7)
    th = tp + 0.1
    obs = obs_at(path, fx - L * math.cos(th), fy - L * math.sin(th), th, L=L)
    assert abs(float(obs.theta_e) - 0.1) > 0.05  # the rear axle's heading error is different
    np.testing.assert_allclose(float(C.stanley.output(C.stanley_params(), (), obs)), -0.1, atol=1e-12)


@pytest.mark.parametrize("ff", [0.0, 1.0])
def test_state_feedback_output(ff):
    """delta = K [d, theta_e] (+ atan(L kappa) with the feedforward on)."""
    K = (-2.7381, -2.0772)
    gains = C.state_feedback_params(K=K, feedforward=ff)
    path = circle(radius=2.0)
    x, y, th = on_circle(path, 1.0)
    obs = obs_at(path, x + 0.1, y - 0.05, th + 0.2)
    d, te = float(obs.d), float(obs.theta_e)
    expect = K[0] * d + K[1] * te + ff * math.atan(0.2 / 2.0)
    np.testing.assert_allclose(float(C.state_feedback.output(gains, (), obs)), expect, atol=1e-14)


def _fixed_obs(d, te):
    path = line()
    return Observation(
        d=jnp.asarray(d),
        theta_e=jnp.asarray(te),
        kappa=jnp.asarray(0.0),
        s=jnp.asarray(0.0),
        u=jnp.asarray(0.0),
        pose=Pose(*(jnp.asarray(0.0),) * 3),
        v=jnp.asarray(1.0),
        L=jnp.asarray(0.2),
        delta_max=jnp.asarray(DMAX),
        path=path,
    )


def test_pi_step_is_forward_euler_of_the_integral_terms():
    """delta = -kp_d d - kp_th theta_e + c_d + c_th and c <- c + T (-ki_d d, -ki_th theta_e)
    (the integral terms of eq. 14 with their minus signs); unsaturated, so k_aw plays no part."""
    g = C.pi_params(kp_d=1.3, ki_d=0.7, kp_theta=0.9, ki_theta=2.1, k_aw=3.0)
    c = jnp.asarray([0.05, -0.02])
    obs = _fixed_obs(0.1, -0.15)
    cmd, c1 = C.step(C.pi, g, c, obs, 0.02)
    np.testing.assert_allclose(float(cmd), -1.3 * 0.1 - 0.9 * -0.15 + 0.05 - 0.02, atol=1e-15)
    assert abs(float(cmd)) < DMAX
    np.testing.assert_allclose(np.asarray(c1), [0.05 + 0.02 * -0.7 * 0.1, -0.02 + 0.02 * -2.1 * -0.15], atol=1e-15)


def test_pi_anti_windup_bounds_the_integral_under_constant_saturation():
    """Constant d = -2 m saturates the command. Without anti-windup the d-integral term grows
    linearly, c_n = n T ki_d 2 (windup); with back-calculation (k_aw > 0, all of it on the d term
    since ki_theta = 0) it converges to the fixed point of c' = 2 ki_d + k_aw (delta_max - P - c),
    c* = delta_max - P + 2 ki_d / k_aw."""
    T, n = 0.01, 3000
    obs = _fixed_obs(-2.0, 0.0)
    P = 2.0 * WINDUP_GAINS["kp_d"]
    run = jax.jit(lambda g: jax.lax.scan(lambda c, _: (C.step(C.pi, g, c, obs, T)[1], None), C.pi.init(g), None, n)[0])
    c_free = np.asarray(run(C.pi_params(**WINDUP_GAINS)))
    np.testing.assert_allclose(c_free, [n * T * WINDUP_GAINS["ki_d"] * 2.0, 0.0], rtol=1e-12)
    k_aw = 4.0
    c_aw = np.asarray(run(C.pi_params(**WINDUP_GAINS, k_aw=k_aw)))
    np.testing.assert_allclose(c_aw, [DMAX - P + 2 * WINDUP_GAINS["ki_d"] / k_aw, 0.0], atol=1e-12)
    assert abs(c_aw[0]) < abs(c_free[0]) / 5


def test_table3_assignments_are_the_24_permutations():
    a = C.table3_assignments()
    assert len(a) == 24
    combos = {tuple(float(x) for x in g[:4]) for g in a.values()}
    assert len(combos) == 24
    assert all(sorted(c) == sorted(C.TABLE3_GAINS) for c in combos)
    assert all(float(g.k_aw) == 0.0 for g in a.values())
    assert tuple(C.TABLE3_GAINS) in combos  # the printed order read as (kp_d, ki_d, kp_theta, ki_theta)


# ------------------------------------------------------------------------- in the simulator


@pytest.fixture(scope="module")
def runs():
    """Every registered controller on the line with zero slip from POSES; the PI batch also holds
    the windup scenario with and without anti-windup (one compile per controller)."""
    out = {}
    for name, (ctrl, make, *_) in C.REGISTRY.items():
        rows = [paper_scenario("line", make(), beta_r_deg=0.0, beta_f_deg=0.0, pose0=p) for p in POSES]
        if name == "pi":
            rows += [
                paper_scenario(
                    "line", C.pi_params(**WINDUP_GAINS, k_aw=k), beta_r_deg=0.0, beta_f_deg=0.0, pose0=WINDUP_POSE
                )
                for k in (0.0, 5.0)
            ]
        out[name] = jax.device_get(simulate_batch(stack(rows), controller=ctrl, config=CFG))
    return out


@pytest.mark.parametrize("name", list(C.REGISTRY))
def test_every_controller_converges_on_the_line_without_slip(runs, name):
    """Zero slip, 20 s: every controller brings |d| below 1 cm (the PI with Table 3's gains is
    the slowest, ~6 mm at 20 s) without failing, and respects the steering limit."""
    r = runs[name]
    n = len(POSES)
    np.testing.assert_array_equal(r.status[:n], 0)
    assert np.all(np.isnan(r.fail_time[:n]))
    assert np.all(np.abs(r.final.d[:n]) < 0.01), r.final.d
    assert np.all(np.abs(r.trajectory.delta[:n]) <= DMAX + 1e-15)
    assert np.all(np.abs(r.trajectory.d[:n, 0]) > 0.5)  # they really started off the path


def test_sampled_pi_integrates_by_forward_euler_in_the_simulator(runs):
    """In the simulator (k_aw = 0), the integral terms recovered from the recorded command,
    I_k = delta_cmd_k + kp_d d_k + kp_th theta_e_k, equal the forward-Euler sums
    dt sum_{j<k} (-ki_d d_j - ki_th theta_e_j) of the recorded errors (to rounding, 1e-11)."""
    r = runs["pi"]
    gains = [C.PAPER_PI] * len(POSES) + [WINDUP_GAINS]
    for i, g in enumerate(gains):
        tr = r.trajectory
        d, te, cmd = tr.d[i, :-1], tr.theta_e[i, :-1], tr.delta_cmd[i, :-1]  # the last sample holds
        integ = cmd + g["kp_d"] * d + g["kp_theta"] * te
        euler = np.r_[0.0, np.cumsum(CFG.dt * (-g["ki_d"] * d - g["ki_theta"] * te))[:-1]]
        np.testing.assert_allclose(integ, euler, atol=1e-11)


def test_pi_anti_windup_in_the_simulator(runs):
    """Started 2.8 m off, the command saturates. With back-calculation the d-integral is wound up
    less in the direction of the saturation, |I| stays smaller over the run, the loop leaves
    saturation sooner and overshoots less than without."""
    r = runs["pi"]
    n = len(POSES)
    tr = r.trajectory
    g = WINDUP_GAINS
    integ = tr.delta_cmd[n:, :-1] + g["kp_d"] * tr.d[n:, :-1] + g["kp_theta"] * tr.theta_e[n:, :-1]
    sat = np.abs(tr.delta_cmd[n:, :-1]) > DMAX
    windup = [np.max(np.sign(tr.delta_cmd[n + i, :-1][sat[i]]) * integ[i][sat[i]]) for i in range(2)]
    assert windup[1] < 0.5 * windup[0], windup
    assert np.abs(integ[1]).max() < 0.5 * np.abs(integ[0]).max()
    assert r.metrics.sat_fraction[n + 1] < r.metrics.sat_fraction[n]
    assert r.metrics.overshoot[n + 1] < 0.5 * r.metrics.overshoot[n]
    np.testing.assert_array_equal(r.status[n:], 0)


@pytest.mark.parametrize(
    "gains",
    [
        C.state_feedback_params(C.PAPER_K, feedforward=1.0),
        C.pi_params(**WINDUP_GAINS, k_aw=5.0),
        C.pi_params(**C.PAPER_PI),
    ],
    ids=["state_feedback", "pi_anti_windup", "pi_table3"],
)
def test_linear_controller_reproduces_state_feedback_and_pi(gains):
    """``linear`` with :func:`linear_params` is the same controller (a study runs both kinds as it,
    one compiled program for the two): from a start with saturation and slip, in the simulator
    (sampled every step, float64), the same metrics and final state as the original to 1e-12 relative
    (they are one formula up to the order of exact zero terms; the compiler may fuse them differently)."""
    original = C.state_feedback if isinstance(gains, C.StateFeedbackParams) else C.pi
    rows = [
        paper_scenario("sine", gains, beta_r_deg=4.0, beta_f_deg=-3.0, pose0=p) for p in (WINDUP_POSE, (0.0, 0.5, 0.3))
    ]
    a = simulate_batch(stack(rows), controller=original, config=CFG)
    lin = [r._replace(gains=C.linear_params(r.gains)) for r in rows]
    b = simulate_batch(stack(lin), controller=C.linear, config=CFG)
    np.testing.assert_array_equal(a.status, b.status)
    for x, y in zip(jax.tree_util.tree_leaves((a.metrics, a.final)), jax.tree_util.tree_leaves((b.metrics, b.final))):
        np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=1e-12, atol=1e-14)


def test_linear_params_rejects_other_gains():
    with pytest.raises(TypeError, match="gains"):
        C.linear_params(C.stanley_params())


def test_steering_saturation_is_a_clip_whose_derivative_selects():
    """``saturate``: ``jnp.clip``'s values bit for bit; derivative 1 in the command inside the limits
    (ties included), 0 beyond them, and the limit's own there (d/d delta_max = +-1)."""
    from pfjax.controllers.base import saturate

    cmd = jnp.asarray([-1.0, -0.5, -0.2, 0.0, 0.3, 0.5, 2.0])
    np.testing.assert_array_equal(saturate(cmd, 0.5), jnp.clip(cmd, -0.5, 0.5))
    d_cmd = jax.vmap(jax.grad(saturate))(cmd, jnp.full_like(cmd, 0.5))
    np.testing.assert_array_equal(d_cmd, [0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0])
    d_max = jax.vmap(jax.grad(saturate, argnums=1))(cmd, jnp.full_like(cmd, 0.5))
    np.testing.assert_array_equal(d_max, [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
