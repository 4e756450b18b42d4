"""Unicycle model and the time-state switching controller (docs/reproductions/parking.md §1-2; source eq. 1-3).

Model (source eq. 1), reference point the midpoint of the driving wheels::

    ẋ = v₁ cos θ,   ẏ = v₁ sin θ,   θ̇ = ω

Controller (source eq. 2-3), valid for |θ| < π/2::

    v₂ = −v₁ cos³θ · (k₁ y + sgn(v₁) · α · k₂ · tan θ)

With z₁ = y, z₂ = tan θ and x as the time scale, dz₁/dx = z₂ and
dz₂/dx = −k₁ z₁ − sgn(v₁) α k₂ z₂. In the distance-travelled scale τ = ∫|dx| = ∫|v₁| cos θ dt
both directions share V = k₁ z₁² + z₂² with dV/dτ = −2 α k₂ z₂² ≤ 0, so any switching of sgn(v₁)
and of α > 0 keeps V non-increasing in time while |θ| < π/2 (the source's Theorem). With the
yaw-rate PI loop on, ω ≠ v₂ and the guarantee no longer holds exactly.

Optional yaw-rate PI loop (the experiment's k_P = 0.8, k_I = 16; **assumed** structure): the
robot's yaw rate is the PI output acting on the measured yaw-rate error with a static plant,
``ω = k_P (v₂ − ω) + k_I q``, ``q̇ = v₂ − ω``, i.e. ``ω = (k_P v₂ + k_I q) / (1 + k_P)``: a lag
of time constant (1 + k_P) / k_I = 0.1125 s with a direct feed-through k_P / (1 + k_P).
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from pfjax.numerics import elementary as E
from pfjax.parking.defaults import K1, K2, KI, KP, SPEED

Array = jnp.ndarray


class ControlParams(NamedTuple):
    """Controller and actuator parameters of one run (a pytree; every leaf can be batched)."""

    k1: Array  # 1/m², gain on y (source: 32)
    k2: Array  # 1/m, gain on tan θ (source: 8)
    speed: Array  # m/s, |v₁| (source: 0.05)
    kp: Array  # -, yaw-rate PI proportional gain (source: 0.8)
    ki: Array  # 1/s, yaw-rate PI integral gain (source: 16)
    lag: Array  # -, 1.0 = yaw-rate PI loop on, 0.0 = ideal yaw rate


def control_params(k1=K1, k2=K2, speed=SPEED, kp=KP, ki=KI, lag=False) -> ControlParams:
    """One run's controller (1/m², 1/m, m/s, -, 1/s; defaults the source's, :mod:`pfjax.parking.defaults`);
    ``lag``: the yaw-rate PI loop on (bool, or 1.0/0.0)."""
    f = lambda v: jnp.asarray(v, dtype=float)
    return ControlParams(f(k1), f(k2), f(speed), f(kp), f(ki), f(1.0 if lag is True else 0.0 if lag is False else lag))


def yaw_rate_command(theta, y, v1, alpha, k1, k2):
    """v₂ = −v₁ cos³θ (k₁ y + sgn(v₁) α k₂ tan θ) in rad/s (source eq. 2-3). Shapes broadcast."""
    c = E.cos(theta)  # pfjax's cos and tan share one range reduction (pfjax.numerics.elementary)
    return -v1 * c**3 * (k1 * y + jnp.sign(v1) * alpha * k2 * E.tan(theta))


def actual_yaw_rate(v2, q, p: ControlParams):
    """ω (rad/s): v₂ itself, or the PI loop's output (k_P v₂ + k_I q) / (1 + k_P) when ``p.lag``."""
    return jnp.where(p.lag > 0.5, (p.kp * v2 + p.ki * q) / (1.0 + p.kp), v2)


def vector_field(state, v1, alpha, p: ControlParams):
    """d/dt of state = [x, y, θ, q] (m, m, rad, rad) under travel velocity v₁ (m/s) and gain α."""
    y, th, q = state[1], state[2], state[3]
    v2 = yaw_rate_command(th, y, v1, alpha, p.k1, p.k2)
    w = actual_yaw_rate(v2, q, p)
    dq = jnp.where(p.lag > 0.5, v2 - w, 0.0)
    s, c = E.sincos(th)
    return jnp.stack([v1 * c, v1 * s, w, dq])


def lyapunov(y, theta, k1):
    """V = k₁ z₁² + z₂² with z₁ = y, z₂ = tan θ (docs/reproductions/parking.md §2); non-increasing along closed-loop runs."""
    return k1 * y**2 + E.tan(theta) ** 2


def parking_error(x, y, theta):
    """|x| + sqrt(y² + tan²θ) (m-like); the robot stops when it is below the tolerance (0.02)."""
    return jnp.abs(x) + jnp.sqrt(y**2 + E.tan(theta) ** 2)
