"""Controllers with one interface (:class:`~pfjax.controllers.base.Controller`) and a registry.

``REGISTRY`` maps a controller name to its :class:`~pfjax.controllers.registry.ControllerEntry`
(``controller, make_params = REGISTRY[name][:2]``); ``make_params`` takes keyword gains, checks
them and returns the controller's parameter pytree.
"""

from pfjax.controllers.base import Controller, Observation, step
from pfjax.controllers.designs import DESIGNS, DesignEntry, cli_names, controller_types, design_gains, resolve, style
from pfjax.controllers.integral import IntegralParams, integral, integral_params

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
    table3_label,
)
from pfjax.controllers.registry import (
    REGISTRY,
    UNSTATED,
    ControllerEntry,
    box_units,
    check_box,
    checked_factory,
    entry,
    flat_gains,
    gain_names,
    gain_units,
    params_from_flat,
    register,
)
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
    "DESIGNS",
    "PAPER_K",
    "PAPER_PI",
    "REGISTRY",
    "TABLE3_GAINS",
    "UNSTATED",
    "Controller",
    "ControllerEntry",
    "DesignEntry",
    "IntegralParams",
    "LinearParams",
    "Observation",
    "PIParams",
    "PurePursuitParams",
    "RearWheelParams",
    "StanleyParams",
    "StateFeedbackParams",
    "box_units",
    "check_box",
    "checked_factory",
    "cli_names",
    "controller_types",
    "design_gains",
    "entry",
    "flat_gains",
    "gain_names",
    "gain_units",
    "integral",
    "integral_params",
    "linear",
    "linear_params",
    "params_from_flat",
    "pi",
    "pi_params",
    "pure_pursuit",
    "pure_pursuit_params",
    "rear_wheel",
    "rear_wheel_params",
    "register",
    "resolve",
    "stanley",
    "stanley_params",
    "state_feedback",
    "state_feedback_params",
    "step",
    "style",
    "table3_assignments",
    "table3_label",
]
