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

def checked_factory(name: str, factory, defaults: dict | None = None):
    """``factory`` (keyword gains -> parameter pytree) with its arguments checked: an unknown gain
    name or a gain that is not a finite number raises :class:`~pfjax.errors.InputError` naming
    ``gains.<name>``. ``defaults`` are used for the gains not given."""
    import inspect

    from pfjax import errors

    names = list(inspect.signature(factory).parameters)

    def make(**gains):
        for k, v in gains.items():
            if k not in names:
                raise errors.InputError(f"gains.{k}: unknown gain for controller {name!r}; expected one of "
                                        f"{', '.join(names)}", "gains")
            errors.numbers(f"gains.{k}", v)
        return factory(**{**(defaults or {}), **gains})

    make.gain_names = tuple(names)
    make.__doc__ = factory.__doc__
    return make


REGISTRY = {
    "state_feedback": (state_feedback, checked_factory("state_feedback", state_feedback_params)),
    "pi": (pi, checked_factory("pi", pi_params, PAPER_PI)),
    "stanley": (stanley, checked_factory("stanley", stanley_params)),
    "pure_pursuit": (pure_pursuit, checked_factory("pure_pursuit", pure_pursuit_params)),
    "rear_wheel": (rear_wheel, checked_factory("rear_wheel", rear_wheel_params)),
    "integral": (integral, checked_factory("integral", integral_params)),
}

__all__ = [
    "Controller", "Observation", "step", "PAPER_K", "TABLE3_GAINS", "PAPER_PI", "PIParams",
    "StateFeedbackParams", "pi", "pi_params", "state_feedback", "state_feedback_params",
    "table3_assignments", "PurePursuitParams", "RearWheelParams", "StanleyParams", "pure_pursuit",
    "pure_pursuit_params", "rear_wheel", "rear_wheel_params", "stanley", "stanley_params", "REGISTRY",
]
