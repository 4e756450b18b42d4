"""The controller interface.

A controller is a continuous-time system with (possibly empty) internal state ``c``::

    delta_cmd = output(params, c, obs)
    c'        = rate(params, c, obs, delta_cmd, delta_applied)

``params`` is a plain pytree (what tuners differentiate and samples vary), ``c`` a pytree
of arrays (the PI's integrators). ``delta_applied`` is the saturated steering
(:func:`saturate`), so anti-windup schemes can see the saturation.

The simulator uses it two ways, with no code in the controllers for either:

* **sampled** (default): at every sample the command is computed and held (zero-order hold)
  for ``control_every`` integrator steps; the state advances by
  :func:`step`, i.e. ``c <- c + T_c * rate`` (forward Euler at the sampling period ``T_c``,
  the usual discrete PI);
* **continuous** (``control_every=None``): ``output`` is evaluated inside every RK4 stage and
  ``c`` is integrated with the plant, as in the source's Simulink model.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.models.slip import Pose
from pfjax.numerics import elementary as E


class Observation(NamedTuple):
    """What a controller sees at one instant.

    With sensor noise (:class:`pfjax.sim.simulate.SensorNoise`) ``d``, ``theta_e`` and ``pose`` are
    the measured ones, consistent with each other (the measured pose's errors against the path are
    ``d`` and ``theta_e``); ``kappa``, ``s`` and ``u`` are the true closest point's, which is also the
    measured pose's closest point (``u`` is a warm start for a tracker's own projections).
    """

    d: Array  # m, lateral error (left positive)
    theta_e: Array  # rad, heading error
    kappa: Array  # 1/m, path curvature at the closest point
    s: Array  # m, arc length of the closest point
    u: Array  # path parameter of the closest point
    pose: Pose  # m, m, rad: rear-axle pose
    v: Array  # m/s, speed
    L: Array  # m, wheelbase
    delta_max: Array  # rad, steering limit
    path: Any  # the path pytree (for trackers that look ahead)


class Controller(NamedTuple):
    """A controller: three pure functions (hashable, so it can be a static jit argument)."""

    name: str
    init: Callable[[Any], Any]  # params -> c0
    output: Callable[[Any, Any, Observation], Array]  # -> delta_cmd, rad
    rate: Callable[[Any, Any, Observation, Array, Array], Any]  # -> c', same pytree as c
    params: type | None = None  # the parameter NamedTuple it takes (None: any pytree)

    def check_params(self, params) -> None:
        """:class:`~pfjax.errors.InputError` naming ``gains`` if ``params`` is not this controller's
        parameter type (a PI given state-feedback gains, say)."""
        if self.params is not None and not isinstance(params, self.params):
            from pfjax.errors import InputError

            raise InputError(
                f"gains: controller {self.name!r} takes {self.params.__name__}, got {type(params).__name__}", "gains"
            )


def no_state(params) -> Array:
    """Initial state of a memoryless controller (an empty array)."""
    return jnp.zeros((0,))


def no_rate(params, c, obs, delta_cmd, delta_applied):
    """State derivative of a memoryless controller."""
    return c


def saturate(delta_cmd, delta_max):
    """The steering saturation ``delta = clip(delta_cmd, -delta_max, delta_max)`` (rad), the one
    every simulator applies to a command. Its derivative is
    :func:`pfjax.numerics.elementary.clip`'s: ``d delta_cmd`` inside the limits (ties included),
    the limit's own beyond them (no division)."""
    return E.clip(delta_cmd, -delta_max, delta_max)


def step(controller: Controller, params, c, obs: Observation, period: Array | float):
    """One sample of a sampled controller: ``delta = output(c, obs)``, ``c <- c + period * rate``.

    Returns:
        ``(delta_cmd, c_next)``; the caller saturates ``delta_cmd``.
    """
    delta_cmd = controller.output(params, c, obs)
    delta = saturate(delta_cmd, obs.delta_max)
    dc = controller.rate(params, c, obs, delta_cmd, delta)
    return delta_cmd, jax.tree_util.tree_map(lambda a, b: a + period * b, c, dc)
