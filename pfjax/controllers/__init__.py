"""Controllers with one interface (:class:`~pfjax.controllers.base.Controller`) and a registry.

``REGISTRY`` maps a controller name to ``(controller, default_params_factory)``; the
factories take keyword gains and return the controller's parameter pytree.
"""

from pfjax.controllers.base import Controller, Observation, step
from pfjax.controllers.linear import (
    PAPER_K,
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

#: The reading of Table 3 adopted as the source's PI. The labels were lost (spec §5); the
#: paper-reproduction study simulates all 24 readings and this is the one consistent with every
#: claim the source makes about its PI (see README): Table 3's printed order is
#: (Ki_d, Ki_theta, Kp_d, Kp_theta).
PAPER_PI = dict(kp_d=TABLE3_GAINS[2], ki_d=TABLE3_GAINS[0], kp_theta=TABLE3_GAINS[3], ki_theta=TABLE3_GAINS[1])

REGISTRY = {
    "state_feedback": (state_feedback, state_feedback_params),
    "pi": (pi, lambda **g: pi_params(**{**PAPER_PI, **g})),
    "stanley": (stanley, stanley_params),
    "pure_pursuit": (pure_pursuit, pure_pursuit_params),
    "rear_wheel": (rear_wheel, rear_wheel_params),
    "integral": (integral, integral_params),
}

__all__ = [
    "Controller", "Observation", "step", "PAPER_K", "TABLE3_GAINS", "PAPER_PI", "PIParams",
    "StateFeedbackParams", "pi", "pi_params", "state_feedback", "state_feedback_params",
    "table3_assignments", "PurePursuitParams", "RearWheelParams", "StanleyParams", "pure_pursuit",
    "pure_pursuit_params", "rear_wheel", "rear_wheel_params", "stanley", "stanley_params", "REGISTRY",
]
