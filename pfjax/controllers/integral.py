"""State feedback with integral action on the lateral error (pfjax's design beyond the source).

::

    delta = K_d d + K_theta theta_e + c,      c' = K_i d + k_aw (delta_applied - delta_cmd)

i.e. ``delta = K [d, theta_e, int d dt]`` with the integral *term* ``c = K_i int d dt`` (rad) as the
controller state and optional back-calculation anti-windup (``k_aw``, 1/s; 0 = none). Under a
constant slip an equilibrium needs ``c' = 0``, hence ``d* = 0``: the slip-induced offset of the
static gain (``d* = (beta_f - 1.08 beta_r)/2.78`` for the source's K) is removed. The gain is
designed on the augmented plant by :func:`pfjax.synthesis.integral.integral_mixed`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.controllers.base import Controller, Observation
from pfjax.controllers.registry import register
from pfjax.numerics import elementary as E


class IntegralParams(NamedTuple):
    """``delta = K [d, theta_e, int d] + feedforward atan(L kappa)`` (+ anti-windup)."""

    K: Array  # (3,) rad/m, rad/rad, rad/(m s)
    k_aw: Array  # 1/s, back-calculation anti-windup gain
    feedforward: Array  # 0 or 1: add the path-curvature steering atan(L kappa)


#: Mixed H2/H-inf design on the augmented plant at v = 1 m/s, L = 0.2 m, alpha = 10, beta = 1
#: (``integral_mixed()``; recomputed and checked in tests/test_synthesis_robust.py).
DEFAULT_K = (-5.2544, -2.2374, -2.2575)


def integral_params(K=DEFAULT_K, k_aw=0.0, feedforward=0.0) -> IntegralParams:
    f = lambda a: jnp.asarray(a, dtype=float)
    return IntegralParams(f(np.ravel(K)), f(k_aw), f(feedforward))


def _init(p: IntegralParams) -> Array:
    return jnp.zeros((1,), dtype=jnp.result_type(p.K))


def _output(p: IntegralParams, c: Array, obs: Observation) -> Array:
    return p.K[0] * obs.d + p.K[1] * obs.theta_e + c[0] + p.feedforward * E.atan(obs.L * obs.kappa)


def _rate(p: IntegralParams, c: Array, obs: Observation, delta_cmd: Array, delta: Array) -> Array:
    return jnp.stack([p.K[2] * obs.d + p.k_aw * (delta - delta_cmd)])


integral = Controller("integral", _init, _output, _rate, IntegralParams)
"""State feedback with integral of ``d`` (see the module docstring)."""
register(
    integral,
    integral_params,
    box=(("K",), (-20.0, -10.0, -20.0), (0.0, 0.0, 0.0)),
    style={"color": "#e377c2", "lw": 1.4, "label": "state feedback with integral action"},
    labels={"K": ("k_d", "k_theta", "k_i")},
    gains=("k_d", "k_theta", "k_i", "k_aw"),
    units={"k_d": "rad/m", "k_theta": "rad/rad", "k_i": "rad/(m s)", "k_aw": "1/s", "feedforward": "1"},
)
