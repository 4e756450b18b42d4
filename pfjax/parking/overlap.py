"""The start check's NumPy geometry (at the edge, never under jit): points in polygons, the robot's
rectangle at a pose, and the area where it overlaps an obstacle (:func:`pfjax.parking.maps.check_start`).
"""

from __future__ import annotations

import math

import numpy as np

#: Intersection area (m², scaled by the squared coordinate magnitude when that exceeds 1 m) below
#: which the robot's rectangle and an obstacle count as touching, not overlapping: rounding of the
#: clipped area stays below it, a 1 µm × 1 µm overlap does not.
OVERLAP_AREA_TOL = 1e-12


def orient(o, p, q):
    """z-component of (p − o) × (q − o) for (..., 2) arrays, m²; positive when o→p→q turns left.

    The same float operations in the same order as a scalar evaluation, so signs agree bit for bit.
    """
    return (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0])


def points_in_polygon_np(pts, poly) -> np.ndarray:
    """(N,) bool: points inside or on one polygon, in NumPy (validation at the edges).

    The crossing-number rule of :func:`pfjax.parking.geometry.points_in_polygons` (boundary,
    within 1e-12, counted as inside), vectorised over points and edges.

    Args:
        pts: (N, 2) points, m.
        poly: (n, 2) polygon vertices, m, the first not repeated last.
    """
    p = np.asarray(pts, float).reshape(-1, 2)[:, None, :]
    a = np.asarray(poly, float)
    b = np.roll(a, -1, axis=0)
    ay, by = a[:, 1], b[:, 1]
    straddle = (ay > p[..., 1]) != (by > p[..., 1])
    dy = np.where(by == ay, 1.0, by - ay)
    x_cross = a[:, 0] + (p[..., 1] - ay) * (b[:, 0] - a[:, 0]) / dy
    crossings = np.sum(straddle & (p[..., 0] < x_cross), axis=-1)
    in_box = np.all((p >= np.minimum(a, b) - 1e-12) & (p <= np.maximum(a, b) + 1e-12), axis=-1)
    on = np.any((np.abs(orient(a, b, p)) <= 1e-12) & in_box, axis=-1)
    return (crossings % 2 == 1) | on


def point_in_polygon_np(pt, poly) -> bool:
    """Point (x, y) in m inside or on the polygon (n, 2); see :func:`points_in_polygon_np`."""
    return bool(points_in_polygon_np([pt], poly)[0])


def robot_rectangle(x0, shape) -> np.ndarray:
    """World corners (4, 2), m, counter-clockwise, of the robot rectangle at a pose (NumPy).

    The body-frame rectangle of :mod:`pfjax.parking.geometry`: ``x_b ∈ [front − length, front]``
    ahead of the axle midpoint, ``y_b ∈ [−width/2, width/2]`` to its left, in the corner order of
    :func:`pfjax.parking.geometry.rectangle_corners`.

    Args:
        x0: pose (x m, y m, θ deg).
        shape: (width m, length m, front m): a :class:`~pfjax.parking.geometry.RobotShape` (such as
            ``run_params(...).shape``) or a tuple in that order.
    """
    width, length, front = (float(s) for s in tuple(shape)[:3])
    x, y, th = float(x0[0]), float(x0[1]), math.radians(float(x0[2]))
    bx = np.array([front - length, front, front, front - length])
    by = np.array([-0.5, -0.5, 0.5, 0.5]) * width
    c, s = math.cos(th), math.sin(th)
    return np.stack([x + c * bx - s * by, y + s * bx + c * by], axis=1)


def _clip(v, a, b):
    """Sutherland–Hodgman step: polygon ``v`` (k, 2) cut to the closed half-plane left of a→b."""
    s = orient(a, b, v)
    inside = s >= 0
    sp, vp = np.roll(s, 1), np.roll(v, 1, axis=0)
    cut = inside != np.roll(inside, 1)  # edge vp→v enters or leaves: s and sp differ in sign, sp − s ≠ 0
    t = np.where(cut, sp / np.where(cut, sp - s, 1.0), 0.0)
    pts = np.stack([vp + t[:, None] * (v - vp), v], axis=1)  # per edge: the cut point, then its end point
    return pts[np.stack([cut, inside], axis=1)]


def overlap_area(poly, quad) -> float:
    """Area, m², of a simple polygon intersected with a convex counter-clockwise quadrilateral.

    Sutherland–Hodgman clipping by the quadrilateral's four half-planes, each a whole-array step
    over the polygon's vertices. For a simple (possibly non-convex) polygon the clipped chain may
    contain zero-width bridges along a clip line, but each half-plane cut keeps the winding number
    of every point strictly inside the half-plane, so ``|shoelace area|`` is the area of the
    intersection. Coordinates are taken relative to the quadrilateral's first corner.

    Args:
        poly: (n, 2) polygon vertices, m, either orientation, the first not repeated last.
        quad: (4, 2) convex quadrilateral corners, m, counter-clockwise.
    """
    q = np.asarray(quad, float)
    o = q[0]
    v, q = np.asarray(poly, float) - o, q - o
    for i in range(4):
        if len(v) < 3:
            return 0.0
        v = _clip(v, q[i], q[(i + 1) % 4])
    if len(v) < 3:
        return 0.0
    return 0.5 * abs(float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1])))


def body_overlaps(polygons: dict[str, list], x0, shape) -> dict[str, float]:
    """Obstacles whose interior meets the interior of the robot rectangle at pose ``x0``.

    Two closed polygons overlap when their intersection has positive area (equivalently, when a
    corner of one lies strictly inside the other or two edges cross properly, or the boundaries
    coincide along a stretch with both interiors on the same side); a rectangle that only touches
    an obstacle along an edge or at a point does not overlap it. The area is
    :func:`overlap_area`, exact up to rounding; it counts as positive above
    :data:`OVERLAP_AREA_TOL` (times the squared largest corner coordinate when that exceeds 1 m).

    Args:
        polygons: {name: (n, 2) vertices, m}, as :func:`pfjax.parking.maps.load_map` returns.
        x0: pose (x m, y m, θ deg).
        shape: (width m, length m, front m) or a RobotShape; see :func:`robot_rectangle`.

    Returns:
        {name: intersection area m²} of the overlapping obstacles, in map order.
    """
    quad = robot_rectangle(x0, shape)
    scale = max(1.0, float(np.max(np.abs(quad))))
    tol = OVERLAP_AREA_TOL * scale * scale  # inf, not OverflowError, for absurd poses
    q_lo, q_hi = quad.min(axis=0), quad.max(axis=0)
    out = {}
    for name, poly in polygons.items():
        v = np.asarray(poly, float)
        if np.any(v.max(axis=0) < q_lo) or np.any(v.min(axis=0) > q_hi):
            continue
        area = overlap_area(v, quad)
        if area > tol:
            out[name] = area
    return out
