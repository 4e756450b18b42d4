"""Robot rectangle, polygon obstacle maps and the exact rectangle–polygon intersection test.

The robot's area (docs/reproductions/parking.md §3) is a rectangle of width L₁ and length L₂ in the body frame (x_b ahead,
y_b to the left of the wheel-axle midpoint): ``x_b ∈ [a_f − L₂, a_f]``, ``y_b ∈ [−L₁/2, L₁/2]``.
It is split into a front and a rear half at ``x_b = split`` (**assumed**; default its geometric
middle ``a_f − L₂/2``, or at the wheel axle ``x_b = 0``); the robot reverses when an obstacle lies
in the half toward which it travels (:func:`obstacle_ahead`). ``zone`` widens each half's detection
zone past the split into the other half (default 0; ``L₂``: any contact with the rectangle
reverses, the "whole rectangle" reading of the rule).

Obstacles are simple polygons (not necessarily convex) stored as padded edge arrays so a map is a
fixed-shape pytree: ``a, b: (P, E, 2)`` edge end points in m, ``valid: (P, E)``. A convex
quadrilateral Q (closed set) meets a polygon O (closed set) iff a vertex of O lies in Q, or a
vertex of Q lies in O, or an edge of Q meets an edge of O (orientation tests with a bounding-box
check for the collinear case). All functions are pure and jittable; NumPy validation of user
maps lives in :mod:`pfjax.parking.maps`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp

from pfjax.numerics import elementary as E
from pfjax.parking.defaults import L1_WIDTH, L2_LENGTH

Array = jnp.ndarray


class RobotShape(NamedTuple):
    """Robot rectangle in the body frame (a pytree; leaves can be batched)."""

    width: Array  # m, L₁ (across)
    length: Array  # m, L₂ (along)
    front: Array  # m, a_f: how far the rectangle reaches ahead of the wheel axle
    split: Array  # m, body-frame x of the boundary between the front and the rear half
    zone: Array  # m, how far each half's detection zone reaches past the split into the other half


def robot_shape(front, width=L1_WIDTH, length=L2_LENGTH, split=None, zone=0.0) -> RobotShape:
    """The rectangle; ``split`` (m, body frame) defaults to its geometric middle ``front − length/2``."""
    f = lambda v: jnp.asarray(v, dtype=float)
    return RobotShape(f(width), f(length), f(front), f(front - 0.5 * length if split is None else split), f(zone))


class ObstacleMap(NamedTuple):
    """Obstacle polygons as padded edges (pytree of arrays)."""

    a: Array  # (P, E, 2) m, edge start points
    b: Array  # (P, E, 2) m, edge end points
    valid: Array  # (P, E) bool, False on padding edges


def _cross(o, p, q):
    """z-component of (p − o) × (q − o); positive when o→p→q turns left."""
    return (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (p[..., 1] - o[..., 1]) * (q[..., 0] - o[..., 0])


def half_corners(pose, shape: RobotShape, half):
    """World corners (4, 2), counter-clockwise, of the front (half=+1) or rear (half=−1) half.

    ``pose = (x, y, θ)`` in m, m, rad; ``half`` may be traced (±1).
    """
    x, y, th = pose[0], pose[1], pose[2]
    rear_end = shape.front - shape.length
    mid = jnp.clip(shape.split - jnp.sign(half) * shape.zone, rear_end, shape.front)
    far = jnp.where(half > 0, shape.front, rear_end)
    lo, hi = jnp.minimum(mid, far), jnp.maximum(mid, far)
    w = 0.5 * shape.width
    bx = jnp.stack([lo, hi, hi, lo])
    by = jnp.stack([-w, -w, w, w])
    s, c = E.sincos(th)
    return jnp.stack([x + c * bx - s * by, y + s * bx + c * by], axis=-1)


def rectangle_corners(pose, shape: RobotShape):
    """World corners (4, 2), counter-clockwise, of the whole robot rectangle (for figures)."""
    rear, front = half_corners(pose, shape, -1.0), half_corners(pose, shape, 1.0)
    return jnp.stack([rear[0], front[1], front[2], rear[3]])


def points_in_polygons(pts, omap: ObstacleMap):
    """(N, P) bool: point n inside or on polygon p (crossing number; boundary counted as inside).

    A loop over the (static, padded) edge index: every operation is elementwise over the points,
    polygons and (under ``vmap``) runs, and only whole arrays are combined, so XLA's CPU backend
    vectorises it over the runs instead of reducing a short edge axis per run (see
    :func:`quad_hits_map`)."""
    p = pts[:, None, :]
    crossings, on = 0, False
    for e in range(omap.a.shape[1]):
        a, b, valid = omap.a[:, e], omap.b[:, e], omap.valid[:, e]
        ay, by_ = a[..., 1], b[..., 1]
        straddle = (ay > p[..., 1]) != (by_ > p[..., 1])
        dy = jnp.where(by_ == ay, 1.0, by_ - ay)
        x_cross = a[..., 0] + (p[..., 1] - ay) * (b[..., 0] - a[..., 0]) / dy
        crossings = crossings + (straddle & (p[..., 0] < x_cross) & valid).astype(jnp.int32)
        # on an edge: collinear and inside its bounding box
        on = on | ((jnp.abs(_cross(a, b, p)) <= 1e-12) & _in_box(p, a, b) & valid)
    return (crossings % 2 == 1) | on


def _in_box(p, a, b):
    return (
        (p[..., 0] >= jnp.minimum(a[..., 0], b[..., 0]) - 1e-12)
        & (p[..., 0] <= jnp.maximum(a[..., 0], b[..., 0]) + 1e-12)
        & (p[..., 1] >= jnp.minimum(a[..., 1], b[..., 1]) - 1e-12)
        & (p[..., 1] <= jnp.maximum(a[..., 1], b[..., 1]) + 1e-12)
    )


def _points_in_convex(pts, quad):
    """(...) bool: points (..., 2) inside or on the convex CCW quadrilateral ``quad`` (4, 2)."""
    inside = True
    for i in range(4):
        inside = inside & (_cross(quad[i], quad[(i + 1) % 4], pts) >= -1e-12)
    return inside


def _segments_meet(p1, p2, q1, q2):
    """Closed segments p1p2 and q1q2 share a point (broadcasting over leading axes)."""
    d1, d2 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    d3, d4 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    straddle = (d1 * d2 <= 0) & (d3 * d4 <= 0)
    boxes = (
        jnp.maximum(jnp.minimum(p1[..., 0], p2[..., 0]), jnp.minimum(q1[..., 0], q2[..., 0]))
        <= jnp.minimum(jnp.maximum(p1[..., 0], p2[..., 0]), jnp.maximum(q1[..., 0], q2[..., 0]))
    ) & (
        jnp.maximum(jnp.minimum(p1[..., 1], p2[..., 1]), jnp.minimum(q1[..., 1], q2[..., 1]))
        <= jnp.minimum(jnp.maximum(p1[..., 1], p2[..., 1]), jnp.maximum(q1[..., 1], q2[..., 1]))
    )
    return straddle & boxes


def quad_hits_map(quad, omap: ObstacleMap):
    """True when the convex CCW quadrilateral ``quad`` (4, 2) meets any obstacle polygon (closed sets).

    The tests over the quadrilateral's 4 corners and edges are a Python loop of whole-array
    operations, and one ``any`` over the (polygon, edge) arrays ends it: reducing the 4-long axes per
    run made XLA's CPU backend evaluate them run by run, the most expensive kernels of a parking
    step (README, Performance)."""
    hit = _points_in_convex(omap.a, quad)  # a vertex of a polygon in the quadrilateral, (P, E)
    for i in range(4):  # an edge of the quadrilateral meets an edge of a polygon
        hit = hit | _segments_meet(quad[i], quad[(i + 1) % 4], omap.a, omap.b)
    quad_in_poly = points_in_polygons(quad, omap)  # a corner of the quadrilateral in a polygon, (4, P)
    return jnp.any(hit & omap.valid) | jnp.any(quad_in_poly)


def obstacle_ahead(pose, shape: RobotShape, direction, omap: ObstacleMap):
    """The detection rule (docs/reproductions/parking.md §3, assumed): an obstacle lies in the half toward ``direction`` (±1)."""
    return quad_hits_map(half_corners(pose, shape, direction), omap)
