"""Paths: shapes as pytrees, and generic geometry / closest-point projection."""

from pfjax.paths.geometry import (
    Projection,
    arc_length,
    closest_parameter,
    curvature,
    global_parameter,
    measure,
    project,
    tangent_angle,
    wrap_angle,
)
from pfjax.paths.registry import PATHS, PathEntry, entry, fixed_entry, fixed_paths, register, source_tests
from pfjax.paths.shapes import (
    Circle,
    Graph,
    Spline,
    circle,
    line,
    parabola,
    sine,
    spline_through,
)

__all__ = [
    "PATHS",
    "Circle",
    "Graph",
    "PathEntry",
    "Projection",
    "Spline",
    "arc_length",
    "circle",
    "closest_parameter",
    "curvature",
    "entry",
    "fixed_entry",
    "fixed_paths",
    "global_parameter",
    "line",
    "measure",
    "parabola",
    "project",
    "register",
    "sine",
    "source_tests",
    "spline_through",
    "tangent_angle",
    "wrap_angle",
]
