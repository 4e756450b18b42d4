"""Input-output linearisation of the focus point, with speed, steering-rate and steering limits (docs/reproductions/vehicle-tracking.md §4).

The page defines the output, not the controller; pfjax designs it. With ``z' = M(theta, gamma) u``,
``u = [v; omega]`` (see :mod:`pfjax.tracking.geometry`), the law::

    u_cmd = M(theta, gamma)^{-1} (z_d' - k z~)

gives ``z~' = -k z~`` (each component decays as ``exp(-k t)``) wherever ``M`` is invertible and no
limit is active. Limits, in order: ``|v| <= v_max``, ``|omega| <= omega_max``, and the steering
stop ``|gamma| <= gamma_max`` enforced exactly over one zero-order-hold step ``dt`` by
``omega <- clip(omega, (-gamma_max - gamma)/dt, (gamma_max - gamma)/dt)``. Where
``|det M / (l p)| < sing_tol`` the inverse is not used (``singular`` is returned true and the
simulator records the run as ``SINGULAR``); the command there is computed with the determinant
pushed to ``+-sing_tol l p`` so nothing becomes infinite.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from pfjax.arrays import FloatLeaf
from pfjax.tracking.geometry import input_matrix, invertibility_factor, tracking_error
from pfjax.tracking.model import Follower, FollowerParams


class FocusGains(NamedTuple):
    k: FloatLeaf = 1.0  # 1/s, error decay rate (Lambda = k I)


class Command(NamedTuple):
    v: Array  # m/s, limited speed
    omega: Array  # rad/s, limited steering rate (before the steering stop)
    v_cmd: Array  # m/s, unlimited
    omega_cmd: Array  # rad/s, unlimited
    factor: Array  # det M / (l p)
    singular: Array  # bool


def focus_control(
    s: Follower, zd: Array, zd_dot: Array, params: FollowerParams, gains: FocusGains, sing_tol: float = 1e-3
) -> Command:
    """One evaluation of the law on a (measured) state ``s`` and the leader's ``z_d, z_d'`` (m, m/s)."""
    M = input_matrix(s.theta, s.gamma, params)
    b = zd_dot - gains.k * tracking_error(s, zd, params)
    factor = invertibility_factor(s.gamma, params)
    singular = ~(jnp.abs(factor) >= sing_tol)
    lp = params.l * params.p
    safe = jnp.where(singular, jnp.where(factor < 0, -sing_tol, sing_tol), factor) * lp
    v_cmd = (M[1, 1] * b[0] - M[0, 1] * b[1]) / safe
    w_cmd = (-M[1, 0] * b[0] + M[0, 0] * b[1]) / safe
    v = jnp.clip(v_cmd, -params.v_max, params.v_max)
    w = jnp.clip(w_cmd, -params.omega_max, params.omega_max)
    return Command(v=v, omega=w, v_cmd=v_cmd, omega_cmd=w_cmd, factor=factor, singular=singular)


def steering_stop(omega: Array, gamma: Array, gamma_max: FloatLeaf, dt: float) -> Array:
    """Steering rate that keeps ``|gamma + omega dt| <= gamma_max`` over one held step, rad/s."""
    return jnp.clip(omega, (-gamma_max - gamma) / dt, (gamma_max - gamma) / dt)
