"""Classic geometric path trackers practitioners compare with (none knows the slip).

References: Snider, "Automatic Steering Methods for Autonomous Automobile Path Tracking",
CMU-RI-TR-09-08 (2009); Paden et al., "A Survey of Motion Planning and Control Techniques
for Self-driving Urban Vehicles", IEEE T-IV 1(1), 2016, §V.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from pfjax.controllers.base import Controller, Observation, no_rate, no_state
from pfjax.controllers.registry import register
from pfjax.numerics import elementary as E
from pfjax.paths.geometry import closest_parameter, measure


class StanleyParams(NamedTuple):
    """Stanley: ``delta = -theta_e,f - atan(k d_f / (k_soft + v))`` on the front-axle errors.

    The front axle is projected from the observed rear-axle pose ``(x, y, theta)``:
    ``(x + L cos theta, y + L sin theta)`` (m) with heading ``theta``, its closest path point found
    by Newton from one wheelbase ahead of ``obs.u``; ``d_f`` (m) and ``theta_e,f`` (rad) are its
    lateral and heading errors. With sensor noise the observed pose is the measured one
    (:class:`pfjax.sim.simulate.SensorNoise`), so both come from the noisy position and heading;
    ``obs.d`` and ``obs.theta_e`` are not read.
    """

    k: Array  # 1/s, cross-track gain
    k_soft: Array  # m/s, softening speed


def stanley_params(k=2.5, k_soft=0.1) -> StanleyParams:
    return StanleyParams(jnp.asarray(k, dtype=float), jnp.asarray(k_soft, dtype=float))


def _stanley_output(p: StanleyParams, c, obs: Observation) -> Array:
    path, pose = obs.path, obs.pose
    fx = pose.x + obs.L * E.cos(pose.theta)
    fy = pose.y + obs.L * E.sin(pose.theta)
    # Front-axle closest point, warm-started one wheelbase ahead of the rear axle's.
    dx, dy = path.d1(obs.u)
    u0 = jnp.clip(obs.u + obs.L * E.rsqrt(dx * dx + dy * dy), path.u_min, path.u_max)
    front = measure(path, fx, fy, pose.theta, closest_parameter(path, fx, fy, u0, iters=4))
    return -front.theta_e - E.atan(p.k * front.d / (p.k_soft + jnp.abs(obs.v)))


stanley = Controller("stanley", no_state, _stanley_output, no_rate, StanleyParams)
register(
    stanley,
    stanley_params,
    box=(("k", "k_soft"), (0.1, 0.01), (20.0, 2.0)),
    style={"color": "#2ca02c", "lw": 1.0, "label": "Stanley"},
    units={"k": "1/s", "k_soft": "m/s"},
)


class PurePursuitParams(NamedTuple):
    """Pure pursuit: ``delta = atan(2 L sin(alpha) / l_d)``, ``l_d = max(ld_min, ld_gain v)``.

    The goal is the path point ahead of ``obs.u`` at distance ``l_d`` (m) from the observed
    rear-axle position ``(x, y)``, and ``alpha = atan2(g_y - y, g_x - x) - theta`` (rad) its bearing
    from the observed heading ``theta``. With sensor noise the observed pose is the measured one
    (:class:`pfjax.sim.simulate.SensorNoise`): the goal and ``alpha`` come from the noisy position
    and heading; ``obs.d`` and ``obs.theta_e`` are not read.
    """

    ld_gain: Array  # s, look-ahead time
    ld_min: Array  # m, minimum look-ahead distance


def pure_pursuit_params(ld_gain=0.5, ld_min=0.3) -> PurePursuitParams:
    return PurePursuitParams(jnp.asarray(ld_gain, dtype=float), jnp.asarray(ld_min, dtype=float))


def _pure_pursuit_output(p: PurePursuitParams, c, obs: Observation) -> Array:
    path, pose = obs.path, obs.pose
    ld = jnp.maximum(p.ld_min, p.ld_gain * jnp.abs(obs.v))
    # Goal: the path point ahead of the closest one at distance l_d from the rear axle,
    # h(u) = |p(u) - q|^2 - l_d^2 = 0, by Newton from the arc-length guess.
    dx, dy = path.d1(obs.u)
    u = obs.u + ld * E.rsqrt(dx * dx + dy * dy)
    for _ in range(4):
        px, py = path.point(u)
        tx, ty = path.d1(u)
        ex, ey = px - pose.x, py - pose.y
        h = ex * ex + ey * ey - ld * ld
        hp = 2.0 * (ex * tx + ey * ty)
        hp = jnp.where(hp > 1e-3 * ld, hp, 1e-3 * ld)
        u = jnp.clip(u - h / hp, obs.u, path.u_max)
    gx, gy = path.point(u)
    alpha = E.atan2(gy - pose.y, gx - pose.x) - pose.theta
    return E.atan(2.0 * obs.L * E.sin(alpha) / ld)


pure_pursuit = Controller("pure_pursuit", no_state, _pure_pursuit_output, no_rate, PurePursuitParams)
register(
    pure_pursuit,
    pure_pursuit_params,
    box=(("ld_gain", "ld_min"), (0.05, 0.05), (3.0, 2.0)),
    style={"color": "#9467bd", "lw": 1.0, "label": "pure pursuit"},
    units={"ld_gain": "s", "ld_min": "m"},
)


class RearWheelParams(NamedTuple):
    """Rear-wheel feedback (Paden et al. 2016)::

    omega = v kappa cos(theta_e) / (1 - kappa d) - k_theta |v| theta_e - k_d v sinc(theta_e) d
    delta = atan(L omega / v)
    """

    k_theta: Array  # 1/m
    k_d: Array  # 1/m^2


def rear_wheel_params(k_theta=3.0, k_d=4.0) -> RearWheelParams:
    return RearWheelParams(jnp.asarray(k_theta, dtype=float), jnp.asarray(k_d, dtype=float))


def _rear_wheel_output(p: RearWheelParams, c, obs: Observation) -> Array:
    v, te = obs.v, obs.theta_e
    nonzero = jnp.where(te == 0.0, 1.0, te)
    sinc = jnp.where(te == 0.0, 1.0, E.sin(te) / nonzero)  # sin(te)/te, 1 at 0
    omega = (
        v * obs.kappa * E.cos(te) / (1.0 - obs.kappa * obs.d) - p.k_theta * jnp.abs(v) * te - p.k_d * v * sinc * obs.d
    )
    return E.atan(obs.L * omega / v)


rear_wheel = Controller("rear_wheel", no_state, _rear_wheel_output, no_rate, RearWheelParams)
register(
    rear_wheel,
    rear_wheel_params,
    box=(("k_theta", "k_d"), (0.1, 0.1), (20.0, 40.0)),
    style={"color": "#8c564b", "lw": 1.0, "label": "rear-wheel feedback"},
    units={"k_theta": "1/m", "k_d": "1/m^2"},
)
