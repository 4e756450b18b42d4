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
    PAPER_PATHS,
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
    "Projection", "arc_length", "closest_parameter", "curvature", "global_parameter", "measure",
    "project", "tangent_angle", "wrap_angle", "PAPER_PATHS", "Circle", "Graph",
    "Spline", "circle", "line", "parabola", "sine", "spline_through",
]
