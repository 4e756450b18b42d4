"""Vehicle models: pure functions of one run, parameters as pytrees.

The names of the vehicle models and of their parameter sets have their one home here: the study
config's ``[vehicle]`` schema, :func:`pfjax.scenarios`, :func:`pfjax.simulate`, tuning, the benchmark
and ``pfjax simulate`` read them from :data:`MODELS`, :data:`DYNAMIC_MODELS`,
:data:`DEFAULT_PARAMETER_SET` and :data:`PARAMETER_SETS`; :func:`check_setting` and
:func:`check_setting_range` are the one check of the vehicle settings they all take.
"""

from pfjax import errors
from pfjax.models.single_track_params import PARAMETER_SETS
from pfjax.models.slip import (
    CONVENTIONS,
    LENAIN,
    SOURCE,
    FrenetState,
    Pose,
    SlipParams,
    frenet_rhs,
    max_curvature,
    world_rhs,
    yaw_rate,
)

#: The vehicle models: ``"kinematic"`` (slip declared, :mod:`pfjax.models.slip`), ``"st"``
#: (CommonRoad's single-track model, slip from linear tyre forces) and ``"std"`` (its single-track
#: drift model: Pacejka tyres and wheel speeds; CommonRoad's vehicles only).
MODELS = ("kinematic", "st", "std")
#: The single-track (dynamic) models of :data:`MODELS`: the slip comes from their tyre forces, the
#: wheelbase and steering limit from their parameter set (:data:`PARAMETER_SETS`).
DYNAMIC_MODELS = tuple(m for m in MODELS if m != "kinematic")
#: The parameter set of each dynamic model when none is given: the 0.2 m robot for ``"st"``;
#: ``"std"`` has no robot set (no magic-formula tyre), so CommonRoad's vehicle2.
DEFAULT_PARAMETER_SET = {"st": "robot", "std": "vehicle2"}

#: The unit of each vehicle setting that is a positive magnitude (at least
#: :data:`pfjax.errors.MIN_POSITIVE`), by the study config's ``[vehicle]`` key: speed (m/s),
#: wheelbase ``L`` (m), steering actuator time constant ``tau_delta_s`` (s), speed loop gain ``k_v`` (1/s).
POSITIVE_SETTINGS = {"speed": " m/s", "L": " m", "tau_delta_s": " s", "k_v": " 1/s"}
#: The steering limit ``delta_max_deg`` lies in ``(0, STEERING_LIMIT_DEG)`` deg.
STEERING_LIMIT_DEG = 90.0


def check_setting(key: str, setting: str, value) -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` unless ``value`` (a number or an array of
    numbers, one per run; unchecked under a JAX transformation) obeys the rule of the vehicle setting
    ``setting`` (a :data:`POSITIVE_SETTINGS` key or ``"delta_max_deg"``): the one check the study
    config, :func:`pfjax.scenarios`, the scenario builders and ``pfjax simulate`` make, in the same words."""
    import numpy as np

    if setting in POSITIVE_SETTINGS:
        errors.numbers(key, value, positive=True, unit=POSITIVE_SETTINGS[setting])
        return
    errors.numbers(key, value)
    if errors.is_traced(value):
        return
    a = np.asarray(value, dtype=float)
    bad = ~((a > 0) & (a < STEERING_LIMIT_DEG))
    if np.any(bad):
        i = np.unravel_index(int(np.argmax(bad)), a.shape)
        where = f"{key}[{', '.join(str(int(j)) for j in i)}]" if a.ndim else key
        raise errors.InputError(
            f"{where}: must lie in (0, {STEERING_LIMIT_DEG:g}) deg, got {errors.shown(float(a[i]))}", where
        )
    errors.numbers(key, value, positive=True, unit=" deg")  # and at least MIN_POSITIVE, as every positive magnitude


def check_setting_range(key: str, setting: str, lo: float, hi: float) -> None:
    """:func:`check_setting` over a distribution's range ``[lo, hi]``: every value it draws must obey
    the rule (a constant, ``lo == hi``, is refused in :func:`check_setting`'s words)."""
    if lo == hi:
        check_setting(key, setting, lo)
        return
    steering = setting not in POSITIVE_SETTINGS
    if steering and not (lo > 0 and hi < STEERING_LIMIT_DEG):
        raise errors.InputError(
            f"{key}: must lie in (0, {STEERING_LIMIT_DEG:g}) deg over its whole range, got range [{lo:g}, {hi:g}]", key
        )
    if not lo >= errors.MIN_POSITIVE:
        unit = " deg" if steering else POSITIVE_SETTINGS[setting]
        bound = "> 0" if not lo > 0 else f"at least {errors.MIN_POSITIVE:g}{unit}"
        raise errors.InputError(f"{key}: must be {bound} over its whole range, got a lower bound {lo:g}", key)


__all__ = [
    "CONVENTIONS",
    "DEFAULT_PARAMETER_SET",
    "DYNAMIC_MODELS",
    "LENAIN",
    "MODELS",
    "PARAMETER_SETS",
    "POSITIVE_SETTINGS",
    "SOURCE",
    "STEERING_LIMIT_DEG",
    "FrenetState",
    "Pose",
    "SlipParams",
    "check_setting",
    "check_setting_range",
    "frenet_rhs",
    "max_curvature",
    "world_rhs",
    "yaw_rate",
]
