"""A plugin for tests/test_registries.py: one controller and one path, registered on import
(nothing else in pfjax is edited to use them)."""

import math
from typing import NamedTuple

import jax.numpy as jnp

from pfjax import controllers as C
from pfjax import paths
from pfjax.controllers.base import Controller, no_rate, no_state


class HeadingParams(NamedTuple):
    k_d: jnp.ndarray  # rad/m
    k_h: jnp.ndarray  # rad/rad


def heading_params(k_d=-1.5, k_h=-1.8) -> HeadingParams:
    return HeadingParams(jnp.asarray(k_d, dtype=float), jnp.asarray(k_h, dtype=float))


def _output(p: HeadingParams, c, obs):
    # state feedback plus the path's curvature feedforward: delta = k_d d + k_h theta_e + atan(L kappa)
    return p.k_d * obs.d + p.k_h * obs.theta_e + jnp.arctan(obs.L * obs.kappa)


heading = Controller("dummy_heading", no_state, _output, no_rate, HeadingParams)
C.register(
    heading,
    heading_params,
    box=(("k_d", "k_h"), (-6.0, -6.0), (0.0, 0.0)),
    style={"color": "#bcbd22", "label": "dummy heading"},
    units={"k_d": "rad/m", "k_h": "rad/rad"},
)

# y = 0.5 sin(0.5 x): curvature at most A w^2 = 0.125 1/m; start on the path, tangent to it
paths.register(
    "gentle",
    lambda: paths.sine(amplitude=0.5, omega=0.5),
    start_pose=(0.0, -0.1, math.atan(0.25)),
    max_curvature=0.125,
    description="a gentle sine (test plugin)",
)
