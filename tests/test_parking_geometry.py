"""pfjax.parking geometry and maps: the exact rectangle–polygon test against independent references.

References: Sutherland–Hodgman clipping of the polygon by the convex quadrilateral (NumPy, written
here) — the closed sets meet iff the clipped area is > 0 for generic random configurations (cases
with 0 < area < 1e-8 are skipped as numerically ambiguous); dense point sampling (every sampled
point of the quad inside the polygon, by matplotlib's Path, implies a hit); hand-computed corners.
"""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from pfjax.parking.geometry import half_corners, points_in_polygons, quad_hits_map, rectangle_corners, robot_shape
from pfjax.parking.maps import GARAGE, PARALLEL, MapError, check_start, load_map, parse_map, to_obstacle_map


def clip_area(poly, quad):
    """Area of polygon ∩ convex CCW quad by Sutherland–Hodgman (NumPy reference)."""
    out = [tuple(p) for p in poly]
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        inside = lambda p: (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) >= 0
        inp, out = out, []
        if not inp:
            break
        for j in range(len(inp)):
            cur, prev = inp[j], inp[j - 1]
            if inside(cur):
                if not inside(prev):
                    out.append(_inter(prev, cur, a, b))
                out.append(cur)
            elif inside(prev):
                out.append(_inter(prev, cur, a, b))
    if len(out) < 3:
        return 0.0
    v = np.asarray(out)
    return 0.5 * abs(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))


def _inter(p, q, a, b):
    d1 = np.subtract(q, p)
    d2 = np.subtract(b, a)
    den = d1[0] * d2[1] - d1[1] * d2[0]
    t = ((a[0] - p[0]) * d2[1] - (a[1] - p[1]) * d2[0]) / den
    return (p[0] + t * d1[0], p[1] + t * d1[1])


def star_polygon(rng, n):
    """Random simple (star-shaped, generally non-convex) polygon, CCW."""
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = rng.uniform(0.1, 0.6, n)
    c = rng.uniform(-0.6, 0.6, 2)
    return np.stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang)], axis=1)


def test_half_corners_by_hand():
    shape = robot_shape(0.2, width=0.4, length=0.6)
    front = np.asarray(half_corners(jnp.array([1.0, 2.0, math.pi / 2]), shape, 1.0))
    # body front half x_b in [-0.1, 0.2], y_b in [-0.2, 0.2]; rotated by 90°: (x_b, y_b) -> (-y_b, x_b)
    expect = np.array([[1.2, 1.9], [1.2, 2.2], [0.8, 2.2], [0.8, 1.9]])
    np.testing.assert_allclose(front, expect, atol=1e-12)
    rect = np.asarray(rectangle_corners(jnp.array([0.0, 0.0, 0.0]), shape))
    np.testing.assert_allclose(rect, [[-0.4, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.4, 0.2]], atol=1e-12)


def test_rectangle_polygon_against_clipping_and_sampling():
    rng = np.random.default_rng(5)
    hit_fn = jax.jit(quad_hits_map)
    shape = robot_shape(0.17, width=0.37, length=0.54)
    n_checked = n_hit = 0
    for _ in range(400):
        poly = star_polygon(rng, int(rng.integers(3, 9)))
        pose = jnp.array([rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(-np.pi, np.pi)])
        quad = half_corners(pose, shape, float(rng.choice([-1.0, 1.0])))
        area = clip_area(poly, np.asarray(quad))
        if 0 < area < 1e-8:
            continue
        omap = to_obstacle_map([poly, poly[:3] + 50.0])  # a far second polygon: padding of a 3-gon is exercised
        hit = bool(hit_fn(quad, omap))
        assert hit == (area > 0), (poly, pose, area)
        # sampling: any sampled point of the quad inside the polygon implies a hit
        u, v = np.meshgrid(np.linspace(0, 1, 40), np.linspace(0, 1, 40))
        q = np.asarray(quad)
        pts = (
            q[0] * ((1 - u) * (1 - v))[..., None]
            + q[1] * (u * (1 - v))[..., None]
            + q[2] * (u * v)[..., None]
            + q[3] * ((1 - u) * v)[..., None]
        ).reshape(-1, 2)
        if MplPath(poly).contains_points(pts).any():
            assert hit
        n_checked += 1
        n_hit += hit
    assert n_checked > 350 and 50 < n_hit < n_checked - 50  # both outcomes well represented


def test_points_in_polygons_against_matplotlib():
    rng = np.random.default_rng(1)
    polys = [star_polygon(rng, 7) for _ in range(3)]
    pts = rng.uniform(-1.2, 1.2, (2000, 2))
    got = np.asarray(jax.jit(points_in_polygons)(jnp.asarray(pts), to_obstacle_map(polys)))
    for k, poly in enumerate(polys):
        np.testing.assert_array_equal(got[:, k], MplPath(poly).contains_points(pts))


@pytest.mark.parametrize("x_edge, expect", [(0.21, False), (0.19, True)])
def test_detection_by_hand(x_edge, expect):
    shape = robot_shape(0.2, width=0.4, length=0.6)
    omap = to_obstacle_map([[(x_edge, -1.0), (2.0, -1.0), (2.0, 1.0), (x_edge, 1.0)]])
    hits = jax.jit(lambda d: quad_hits_map(half_corners(jnp.zeros(3), shape, d), omap))
    assert bool(hits(1.0)) is expect
    assert not bool(hits(-1.0))


def test_builtin_maps_free_space():
    points_in = jax.jit(points_in_polygons)
    pm, gm = to_obstacle_map(list(PARALLEL.values())), to_obstacle_map(list(GARAGE.values()))
    free_p = jnp.array([[0.0, 0.0], [0.0, 0.5], [-2.0, 0.5]])
    blocked_p = jnp.array([[0.0, -0.3], [0.7, 0.0], [-0.7, 0.1]])
    assert not np.asarray(points_in(free_p, pm)).any(axis=1).any()
    assert np.asarray(points_in(blocked_p, pm)).any(axis=1).all()
    assert not np.asarray(points_in(jnp.array([[0.0, 0.0], [-0.9, 0.6], [-1.0, -2.0]]), gm)).any()
    assert np.asarray(points_in(jnp.array([[0.0, 0.4], [0.4, 0.0], [0.0, -0.4]]), gm)).any(axis=1).all()


def test_map_files_and_validation(tmp_path):
    ok = {"name": "box", "obstacles": [{"vertices": [[1, 1], [2, 1], [2, 2], [1, 2], [1, 1]]}]}
    f = tmp_path / "m.json"
    f.write_text(json.dumps(ok))
    name, polys = load_map(str(f))
    assert name == "box" and polys["obstacle_0"] == [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)]
    t = tmp_path / "m.toml"
    t.write_text('[[obstacles]]\nname = "wall"\nvertices = [[0, 0], [1, 0], [1, 1], [0, 0]]\n')
    assert list(load_map(str(t))[1]) == ["wall"]
    bad = {
        "not closed": ([[0, 0], [1, 0], [1, 1]], "obstacles[0].vertices: polygon not closed"),
        "degenerate": ([[0, 0], [1, 0], [0, 0]], "obstacles[0].vertices: degenerate"),
        "collinear": ([[0, 0], [1, 0], [2, 0], [0, 0]], "obstacles[0].vertices: degenerate polygon (zero area)"),
        "bow tie": ([[0, 0], [2, 2], [2, 0], [0, 1], [0, 0]], "obstacles[0].vertices: self-intersecting"),
        "nan": ([[0, 0], [1, float("nan")], [1, 1], [0, 0]], "obstacles[0].vertices[1]: expected finite"),
        "type": ([[0, 0], [1, "a"], [1, 1], [0, 0]], "obstacles[0].vertices[1]: expected [x, y] numbers"),
    }
    for label, (verts, msg) in bad.items():
        with pytest.raises(MapError) as e:
            parse_map({"obstacles": [{"vertices": verts}]})
        assert str(e.value).startswith(msg), (label, str(e.value))
        assert "\n" not in str(e.value)
    with pytest.raises(MapError, match="^obstacle: unknown key"):
        parse_map({"obstacle": []})
    with pytest.raises(MapError, match=r"^obstacles\[0\].vertex: unknown key"):
        parse_map({"obstacles": [{"vertex": []}]})
    shape = robot_shape(0.17, width=0.37, length=0.54)
    with pytest.raises(MapError, match="start point .* inside obstacle 'kerb'"):
        check_start(PARALLEL, (0.0, -0.5, 0.0), shape)
    check_start(PARALLEL, (-0.4, 0.5, 0.0), shape)
