"""Car-like robot with front and rear wheel slip (docs/reproductions/path-following.md §1-2, source eq. 1-6).

Two descriptions of the same robot:

* :func:`world_rhs` — the world-frame kinematic bicycle with slip that the source
  simulates (eq. 1-3, 5). State ``Pose(x, y, theta)`` of the rear-axle centre.
* :func:`frenet_rhs` — the path-following error model (eq. 4, 6) in the Frenet
  frame of the path, state ``FrenetState(d, theta_e, s)``.

Sign conventions (``params.convention``):

* ``SOURCE`` (0, default): the source's form ``theta' = v/L (tan(delta - beta_f) - tan beta_r)``.
  Its sign is fixed by the source's line test, where with ``beta_r = beta_f = 5 deg``
  the steering settles at 10 deg (docs/reproductions/path-following.md §1, *derived*).
* ``LENAIN`` (1): the model the source cites (Lenain et al.),
  ``theta' = v cos(beta_r)/L (tan(delta + beta_f) - tan beta_r)``: front slip enters
  with the opposite sign and the yaw rate carries an extra ``cos beta_r``. The
  translational equations are the same in both.

Units: metres, seconds, radians throughout.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from pfjax.arrays import FloatLeaf, IntLeaf
from pfjax.numerics import elementary as E

SOURCE = 0
LENAIN = 1
CONVENTIONS = {"source": SOURCE, "lenain": LENAIN}
#: The sign of ``beta_f`` in the steering that holds a straight line, ``delta* = beta_r + sign beta_f``
#: (where :func:`yaw_rate` is 0): +1 in the source's convention, -1 in Lenain's.
FRONT_SLIP_SIGN = {SOURCE: 1, LENAIN: -1}


class SlipParams(NamedTuple):
    """Physical parameters of one run (a pytree: sample, vmap, differentiate).

    Attributes:
        v: longitudinal speed of the rear axle, m/s (Table 1: 1).
        L: wheelbase, m (Table 1: 0.2).
        delta_max: steering saturation, rad (*assumed* 30 deg, docs/reproductions/path-following.md §6).
        convention: ``SOURCE`` (0) or ``LENAIN`` (1) front-slip sign convention.
        delta_rate_max: steering rate limit, rad/s (``inf``: none). Applied per integrator step to
            sampled controllers; a continuous controller is not rate limited.
    """

    v: FloatLeaf = 1.0  # m/s
    L: FloatLeaf = 0.2  # m
    delta_max: FloatLeaf = 0.5235987755982988  # rad (30 deg)
    convention: IntLeaf = SOURCE  # 0 source, 1 Lenain
    delta_rate_max: FloatLeaf = float("inf")  # rad/s


class Pose(NamedTuple):
    """World-frame state of the rear-axle centre."""

    x: Array  # m
    y: Array  # m
    theta: Array  # rad, heading from the x axis, counter-clockwise positive


class FrenetState(NamedTuple):
    """Path-relative state (docs/reproductions/path-following.md §2)."""

    d: Array  # m, signed lateral distance, left of the path positive
    theta_e: Array  # rad, heading error theta - theta_p(s), wrapped to (-pi, pi]
    s: Array  # m, arc length of the closest path point


def yaw_rate(delta: Array, beta_r: Array, beta_f: Array, params: SlipParams) -> Array:
    """Yaw rate ``theta'`` in rad/s (eq. 3).

    ``SOURCE``: ``(v/L)(tan(delta - beta_f) - tan beta_r)``;
    ``LENAIN``: ``(v cos beta_r / L)(tan(delta + beta_f) - tan beta_r)``.
    """
    v, L = params.v, params.L
    lenain = jnp.asarray(params.convention) == LENAIN
    front = jnp.where(lenain, delta + beta_f, delta - beta_f)
    sbr, cbr = E.sincos(beta_r)  # one range reduction for tan and cos of beta_r
    scale = jnp.where(lenain, cbr, 1.0)
    return scale * (v / L) * (E.tan(front) - sbr / cbr)


def world_rhs(pose: Pose, delta: Array, beta_r: Array, beta_f: Array, params: SlipParams) -> Pose:
    """World-frame slip model (eq. 1-3, 5)::

        x'     = v (cos theta - tan beta_r sin theta)
        y'     = v (sin theta + tan beta_r cos theta)
        theta' = (v/L)(tan(delta - beta_f) - tan beta_r)     (SOURCE convention)

    Args:
        pose: current pose (m, m, rad).
        delta: applied steering angle, rad (already saturated).
        beta_r: rear slip angle, rad.
        beta_f: front slip angle, rad.
        params: physical parameters.

    Returns:
        The time derivative as a ``Pose`` (m/s, m/s, rad/s).
    """
    v = jnp.asarray(params.v)
    s, c = E.sincos(pose.theta)
    tbr = E.tan(beta_r)
    return Pose(
        x=v * (c - tbr * s),
        y=v * (s + tbr * c),
        theta=yaw_rate(delta, beta_r, beta_f, params),
    )


def frenet_rhs(
    state: FrenetState, delta: Array, beta_r: Array, beta_f: Array, kappa: Array, params: SlipParams
) -> FrenetState:
    """Path-following error model (eq. 4, 6)::

        d'       = v sin theta_e + v tan beta_r cos theta_e
        s'       = v (cos theta_e - tan beta_r sin theta_e) / (1 - kappa d)
        theta_e' = theta' - kappa s'

    Singular where ``1 - kappa d = 0`` (on the inside of a bend at the radius of
    curvature); callers flag that region as a failure.

    Args:
        state: Frenet state (m, rad, m).
        delta: applied steering, rad.
        beta_r: rear slip angle, rad.
        beta_f: front slip angle, rad.
        kappa: path curvature at ``s``, 1/m (left turn positive).
        params: physical parameters.
    """
    v = jnp.asarray(params.v)
    s, c = E.sincos(state.theta_e)
    tbr = E.tan(beta_r)
    s_dot = E.divide(v * (c - tbr * s), 1.0 - kappa * state.d)
    return FrenetState(
        d=v * (s + tbr * c),
        theta_e=yaw_rate(delta, beta_r, beta_f, params) - kappa * s_dot,
        s=s_dot,
    )


def max_curvature(params: SlipParams) -> Array:
    """Largest path curvature the robot can follow without slip, 1/m (eq. 2): ``tan(delta_max)/L``."""
    return E.tan(params.delta_max) / params.L
