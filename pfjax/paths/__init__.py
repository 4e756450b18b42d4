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
from pfjax.paths.registry import PATHS, PathEntry, entry, fixed_paths, register, source_tests

__all__ = [
    "Projection", "arc_length", "closest_parameter", "curvature", "global_parameter", "measure",
    "project", "tangent_angle", "wrap_angle", "Circle", "Graph",
    "Spline", "circle", "line", "parabola", "sine", "spline_through",
    "PATHS", "PathEntry", "entry", "fixed_paths", "register", "source_tests",
]
