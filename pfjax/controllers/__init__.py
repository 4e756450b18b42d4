"""Controllers with one interface (:class:`~pfjax.controllers.base.Controller`) and a registry.

``REGISTRY`` maps a controller name to its :class:`~pfjax.controllers.registry.ControllerEntry`
(``controller, make_params = REGISTRY[name][:2]``); ``make_params`` takes keyword gains, checks
them and returns the controller's parameter pytree.
"""

from pfjax.controllers.base import Controller, Observation, step
from pfjax.controllers.registry import (REGISTRY, ControllerEntry, checked_factory, entry, flat_gains, params_from_flat,
                                        register)
# Importing a controller's module registers it (pfjax.controllers.registry): one line per kind.
from pfjax.controllers.linear import (
    PAPER_K,
    PAPER_PI,
    TABLE3_GAINS,
    LinearParams,
    PIParams,
    StateFeedbackParams,
    linear,
    linear_params,
    pi,
    pi_params,
    state_feedback,
    state_feedback_params,
    table3_assignments,
)
from pfjax.controllers.integral import IntegralParams, integral, integral_params
from pfjax.controllers.designs import DESIGNS, DesignEntry, cli_names, controller_types, resolve, style
from pfjax.controllers.trackers import (
    PurePursuitParams,
    RearWheelParams,
    StanleyParams,
    pure_pursuit,
    pure_pursuit_params,
    rear_wheel,
    rear_wheel_params,
    stanley,
    stanley_params,
)

__all__ = [
    "Controller", "Observation", "step", "PAPER_K", "TABLE3_GAINS", "PAPER_PI", "PIParams",
    "StateFeedbackParams", "pi", "pi_params", "state_feedback", "state_feedback_params",
    "table3_assignments", "PurePursuitParams", "RearWheelParams", "StanleyParams", "pure_pursuit",
    "pure_pursuit_params", "rear_wheel", "rear_wheel_params", "stanley", "stanley_params", "REGISTRY",
    "ControllerEntry", "register", "entry", "checked_factory", "flat_gains", "params_from_flat", "IntegralParams", "integral", "integral_params",
    "LinearParams", "linear", "linear_params", "DESIGNS", "DesignEntry", "cli_names", "controller_types", "resolve",
    "style",
]
