"""Car-like follower with a steering state (docs/reproductions/vehicle-tracking.md §1), optional wheel slip.

State ``Follower(x, y, theta, gamma)``: rear-axle centre ``P_b = (x, y)`` (m), heading ``theta``
(rad), steering angle ``gamma`` (rad, ``|gamma| <= gamma_max < pi/2``). Inputs: rear-axle speed
``v`` (m/s) and steering rate ``omega`` (rad/s)::

    x' = v cos theta,   y' = v sin theta,   theta' = (v / a) tan gamma,   gamma' = omega

With slip angles ``beta_r, beta_f`` the translational and yaw equations are exactly those of the
path-following model (docs/reproductions/path-following.md §1, :func:`pfjax.models.slip.world_rhs`, with
the steering angle ``gamma`` in place of ``delta`` and the wheelbase ``a`` in place of ``L``); the
steering state is unaffected by slip.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.arrays import FloatLeaf, IntLeaf
from pfjax.models.slip import SOURCE, Pose, SlipParams, world_rhs


class Follower(NamedTuple):
    """World-frame state of the follower."""

    x: Array  # m, rear-axle centre
    y: Array  # m, rear-axle centre
    theta: Array  # rad, heading from the x axis, counter-clockwise positive
    gamma: Array  # rad, steering angle, left positive


class FollowerParams(NamedTuple):
    """Vehicle, focus-point and limit parameters of one run (a pytree: sample, vmap).

    Attributes:
        a: wheelbase, m (``P_f = P_b + a (cos theta, sin theta)``).
        f: +1 forward tracking (reference point ``P_f``), -1 backward tracking (``P_b``).
        l: focus-point distance from the reference point, m (signed, as in eq. 8.5; backward
            tracking uses ``l < 0`` so the focus point lies ahead in the direction of travel).
        p: focus-point turning ratio, the focus direction is ``theta + p gamma``.
        gamma_max: steering limit, rad (< pi/2).
        v_max: speed limit, m/s (``|v| <= v_max``).
        omega_max: steering-rate limit, rad/s.
        convention: front-slip sign convention of the slip model (0 source, 1 Lenain).
    """

    a: FloatLeaf = 1.0  # m
    f: FloatLeaf = 1.0  # +1 forward, -1 backward
    l: FloatLeaf = 1.0  # m
    p: FloatLeaf = 1.0  # -
    gamma_max: FloatLeaf = 0.5235987755982988  # rad (30 deg)
    v_max: FloatLeaf = 3.0  # m/s
    omega_max: FloatLeaf = 1.5707963267948966  # rad/s (90 deg/s)
    convention: IntLeaf = SOURCE


def as_arrays(params: FollowerParams) -> FollowerParams:
    """``params`` with float64 NumPy leaves and an int32 ``convention`` (what one batch row holds)."""
    return FollowerParams(
        *(np.asarray(v, np.int32 if k == "convention" else np.float64) for k, v in params._asdict().items())
    )


def follower_rhs(
    state: Follower, v: Array, omega: Array, beta_r: Array, beta_f: Array, params: FollowerParams
) -> Follower:
    """Time derivative of the follower state (docs/reproductions/vehicle-tracking.md §1; slip as in :func:`world_rhs`).

    Args:
        state: current state (m, m, rad, rad).
        v: rear-axle speed, m/s (already limited).
        omega: steering rate, rad/s (already limited).
        beta_r: rear slip angle, rad (0 for the slip-free model).
        beta_f: front slip angle, rad (0 for the slip-free model).
        params: vehicle parameters.

    Returns:
        ``Follower`` of rates (m/s, m/s, rad/s, rad/s).
    """
    sp = SlipParams(v=v, L=params.a, delta_max=params.gamma_max, convention=params.convention)
    d = world_rhs(Pose(state.x, state.y, state.theta), state.gamma, beta_r, beta_f, sp)
    return Follower(x=d.x, y=d.y, theta=d.theta, gamma=jnp.asarray(omega) + 0.0 * state.gamma)
