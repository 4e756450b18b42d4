"""Vehicle models: pure functions of one run, parameters as pytrees."""

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

__all__ = [
    "CONVENTIONS",
    "LENAIN",
    "SOURCE",
    "FrenetState",
    "Pose",
    "SlipParams",
    "frenet_rhs",
    "max_curvature",
    "world_rhs",
    "yaw_rate",
]
