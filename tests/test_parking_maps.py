"""pfjax.parking.maps: map files, obstacle names, the self-intersection sweep and the start-pose checks.

References: the quadratic self-intersection test that the sweep replaces (kept here verbatim as
:func:`brute_crossing`), compared pair for pair on random polygons (integer-grid vertices, where
every orientation is exact and collinear edges are common, and random floats); dense sampling of
the robot rectangle (point-in-polygon by matplotlib) for the body overlap; hand-built cases.
"""

from __future__ import annotations

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from pfjax.parking.calibrate import A_F
from pfjax.parking.geometry import L1_WIDTH, L2_LENGTH, points_in_polygons, rectangle_corners, robot_shape
from pfjax.parking.maps import (
    BUILTIN,
    GARAGE,
    MAX_VERTICES,
    PARALLEL,
    MapError,
    body_overlaps,
    check_start,
    load_map,
    overlap_area,
    parse_map,
    points_in_polygon_np,
    robot_rectangle,
    self_crossing,
    to_obstacle_map,
    validate_polygon,
)
from pfjax.parking.schedules import CASES, GARAGE_START
from pfjax.parking.simulate import run_params

# ----------------------------------------------------------------------------- references


def _orient(o, p, q):
    return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])


def brute_conflict(p1, p2, q1, q2):
    """None, 'proper' or 'collinear': the pair test of the quadratic reference."""
    d1, d2, d3, d4 = _orient(q1, q2, p1), _orient(q1, q2, p2), _orient(p1, p2, q1), _orient(p1, p2, q2)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return "proper"
    if d1 == d2 == d3 == d4 == 0:
        lo = max(min(p1[0], p2[0]), min(q1[0], q2[0])), max(min(p1[1], p2[1]), min(q1[1], q2[1]))
        hi = min(max(p1[0], p2[0]), max(q1[0], q2[0])), min(max(p1[1], p2[1]), max(q1[1], q2[1]))
        if lo[0] <= hi[0] and lo[1] <= hi[1]:
            return "collinear"
    return None


def brute_crossing(pts):
    """First (i, j, kind) over all non-adjacent edge pairs in loop order, or None (O(n²))."""
    n = len(pts)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            kind = brute_conflict(pts[i], pts[(i + 1) % n], pts[j], pts[(j + 1) % n])
            if kind:
                return i, j, kind
    return None


def brute_first_with(v, i):
    """(i, j): the first edge j > i + 1 that edge i crosses or overlaps (the reference, one row of it)."""
    n = len(v)
    for j in range(i + 2, n - (i == 0)):
        if brute_conflict(tuple(v[i]), tuple(v[(i + 1) % n]), tuple(v[j]), tuple(v[(j + 1) % n])):
            return i, j
    return None


def closed(poly):
    return [list(map(float, v)) for v in poly] + [list(map(float, poly[0]))]


def regular(n, r=1.0, c=(0.0, 0.0)):
    ang = 2 * np.pi * np.arange(n) / n
    return np.stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang)], axis=1)


def star_polygon(rng, n, centre_box=0.6):
    """Random simple (star-shaped, generally non-convex) polygon, CCW, m."""
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = rng.uniform(0.05, 0.6, n)
    c = rng.uniform(-centre_box, centre_box, 2)
    return np.stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang)], axis=1)


# ----------------------------------------------------------------------------- obstacle names


def _obstacle(name=None, x=0.0):
    o = {"vertices": closed([(x, 0), (x + 1, 0), (x + 1, 1), (x, 1)])}
    if name is not None:
        o["name"] = name
    return o


def test_duplicate_names_rejected():
    with pytest.raises(MapError) as e:
        parse_map({"obstacles": [_obstacle("kerb"), _obstacle("kerb", x=5)]})
    assert str(e.value) == "obstacles[1].name: duplicate obstacle name 'kerb' (also obstacles[0])"
    # an explicit name equal to an earlier obstacle's default name
    with pytest.raises(MapError) as e:
        parse_map({"obstacles": [_obstacle(), _obstacle("obstacle_0", x=5)]})
    assert str(e.value) == (
        "obstacles[1].name: duplicate obstacle name 'obstacle_0' (also obstacles[0], unnamed, which has it by default)"
    )
    # a default name equal to an earlier explicit name
    with pytest.raises(MapError) as e:
        parse_map({"obstacles": [_obstacle("obstacle_1"), _obstacle(x=5)]})
    assert str(e.value).startswith(
        "obstacles[1].name: missing, and the default name 'obstacle_1' is taken by obstacles[0]"
    )
    # distinct names, explicit and default, keep every polygon in file order
    name, polys = parse_map({"obstacles": [_obstacle(), _obstacle("a", x=5), _obstacle(x=10)]})
    assert list(polys) == ["obstacle_0", "a", "obstacle_2"] and polys["obstacle_2"][0] == (10.0, 0.0)


def test_duplicate_names_in_a_file(tmp_path):
    f = tmp_path / "dup.toml"
    f.write_text(
        '[[obstacles]]\nname = "kerb"\nvertices = [[0, 0], [1, 0], [1, 1], [0, 0]]\n'
        '[[obstacles]]\nname = "kerb"\nvertices = [[5, 0], [6, 0], [6, 1], [5, 0]]\n'
    )
    with pytest.raises(
        MapError, match=r"^obstacles\[1\]\.name: duplicate obstacle name 'kerb' \(also obstacles\[0\]\)$"
    ):
        load_map(str(f))


# ----------------------------------------------------------------------------- files


def test_unreadable_files_one_line(tmp_path):
    ok = json.dumps({"obstacles": [_obstacle()]})
    cases = {}
    (tmp_path / "latin1.toml").write_bytes('name = "caf\xe9"\n'.encode("latin-1"))
    cases["latin1.toml"] = "not UTF-8 text (byte 0xe9 at offset 11"
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe" + ok.encode("utf-16-le"))
    cases["bin.json"] = "not UTF-8 text (byte 0xff at offset 0"
    (tmp_path / "dir.json").mkdir()
    cases["dir.json"] = "is a directory"
    (tmp_path / "dupkey.json").write_text('{"obstacles": [], "obstacles": ' + json.dumps([_obstacle()]) + "}")
    cases["dupkey.json"] = "invalid JSON (duplicate key 'obstacles')"
    (tmp_path / "deep.json").write_text("[" * 100_000 + "]" * 100_000)
    cases["deep.json"] = "invalid JSON"
    (tmp_path / "bigint.json").write_text('{"obstacles": [{"vertices": [[1' + "0" * 5000 + ", 0]]}]}")
    cases["bigint.json"] = "invalid JSON"
    (tmp_path / "bad.toml").write_text("obstacles = [\n")
    cases["bad.toml"] = "invalid TOML"
    for fname, msg in cases.items():
        p = tmp_path / fname
        with pytest.raises(MapError) as e:
            load_map(str(p))
        text = str(e.value)
        assert text.startswith(f"map: {p}: {msg}"), (fname, text)
        assert "\n" not in text
    # a byte-order mark is skipped; the file is otherwise UTF-8
    (tmp_path / "bom.json").write_bytes(b"\xef\xbb\xbf" + ok.encode())
    assert list(load_map(str(tmp_path / "bom.json"))[1]) == ["obstacle_0"]


def test_huge_numbers_refused():
    for v in (10**400, 1e300, 2e6, -2e6):
        with pytest.raises(MapError, match=r"^obstacles\[0\]\.vertices\[1\]: expected finite numbers within"):
            parse_map({"obstacles": [{"vertices": [[0, 0], [v, 0], [1, 1], [0, 0]]}]})


# ----------------------------------------------------------------------------- self-intersection


def _random_cases(rng):
    """Polygons as (n, 2) float arrays of distinct vertices: integer grids (exact, many collinear
    edges and crossings), star-shaped grids (mostly simple), spikes and random floats."""
    out = []
    for _ in range(600):  # random order on a small grid
        g = int(rng.integers(3, 7))
        n = int(rng.integers(4, min(10, (g + 1) ** 2)))
        cells = rng.choice((g + 1) ** 2, size=n, replace=False)
        out.append(np.stack([cells // (g + 1), cells % (g + 1)], axis=1).astype(float))
    for _ in range(300):  # star-shaped on a grid: sorted by angle about an interior point
        pts = np.unique(rng.integers(0, 9, (int(rng.integers(4, 16)), 2)), axis=0).astype(float)
        if len(pts) < 3:
            continue
        c = pts.mean(axis=0) + rng.uniform(-0.3, 0.3, 2)
        d = pts - c
        out.append(pts[np.lexsort((np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])))])
    for _ in range(1000):  # rectilinear on a 4 x 4 grid: horizontal edges at one y overlap collinearly
        m = int(rng.integers(2, 6))
        xs, ys = rng.integers(0, 4, m), rng.integers(0, 4, m)
        corners = [((xs[i], ys[i]), (xs[(i + 1) % m], ys[i])) for i in range(m)]  # along x, then along y
        pts = list(dict.fromkeys((float(x), float(y)) for pair in corners for x, y in pair))
        if len(pts) >= 3:
            out.append(np.asarray(pts, float))
    for _ in range(300):  # floats: random order (crossing) or star-shaped (simple)
        n = int(rng.integers(4, 25))
        out.append(rng.uniform(-1, 1, (n, 2)) if rng.random() < 0.5 else star_polygon(rng, n))
    return out


def test_sweep_matches_brute_force_on_random_polygons():
    rng = np.random.default_rng(2024)
    kinds = {"proper": 0, "collinear": 0, None: 0}
    for v in _random_cases(rng):
        ref = brute_crossing([tuple(p) for p in v])
        got, n_pairs = self_crossing(v)
        assert got == (None if ref is None else ref[:2]), (v.tolist(), got, ref)
        assert n_pairs <= len(v) * (len(v) - 1) // 2
        kinds[None if ref is None else ref[2]] += 1
    assert kinds["proper"] > 300 and kinds["collinear"] > 40 and kinds[None] > 300, kinds


def test_sweep_matches_brute_force_on_long_polygons():
    """Bigger polygons where many pairs share x-ranges: combs, random walks, perturbed regular polygons."""
    rng = np.random.default_rng(7)
    cases = []
    for teeth in (5, 20, 40):  # a comb: long horizontal teeth, every tooth shares its x-range with all others
        outline = [(0.0, 0.0)]
        for t in range(teeth):
            outline += [(10.0, 2.0 * t), (10.0, 2.0 * t + 1), (1.0, 2.0 * t + 1), (1.0, 2.0 * t + 2)]
        comb = np.asarray(outline + [(0.0, 2.0 * teeth)], float)
        assert brute_crossing([tuple(p) for p in comb]) is None
        cases.append(comb)
        bad = comb.copy()
        bad[4 * (teeth // 2) + 3, 0] = -0.5  # one tooth's root pulled out through the spine
        assert brute_crossing([tuple(p) for p in bad]) is not None
        cases.append(bad)
    for _ in range(20):  # random walks on a grid: long collinear runs and touching
        steps = rng.choice([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1]], size=int(rng.integers(20, 80)))
        pts = np.unique(np.cumsum(steps, axis=0), axis=0, return_index=True)
        walk = np.cumsum(steps, axis=0)[np.sort(pts[1])].astype(float)
        if len(walk) >= 3:
            cases.append(walk)
    for n in (50, 200):
        p = regular(n) * 100
        cases.append(np.round(p))
        q = p.copy()
        q[[3, n // 2]] = q[[n // 2, 3]]
        cases.append(q)
    seen = set()
    for v in cases:
        ref = brute_crossing([tuple(p) for p in v])
        got, _ = self_crossing(v)
        assert got == (None if ref is None else ref[:2]), (len(v), got, ref)
        seen.add(ref is None)
    assert seen == {True, False}


def test_vertex_touching_an_edge_is_not_a_crossing():
    """A vertex on a non-adjacent edge without crossing it (a touch) is accepted, as by the reference."""
    v = [(0.0, 0.0), (6.0, 0.0), (6.0, 4.0), (3.0, 0.0), (0.0, 4.0)]
    assert brute_crossing(v) is None and self_crossing(np.asarray(v))[0] is None
    assert validate_polygon("k", closed(v)) == v


def test_large_polygons_linear_work_and_vertex_limit():
    # at the limit: accepted
    v = regular(MAX_VERTICES, r=50.0)
    pts = validate_polygon("obstacles[0].vertices", closed(v))
    assert len(pts) == MAX_VERTICES
    # 20 000 vertices (beyond the limit, for the sweep alone): about 3n pair tests where the quadratic
    # reference makes n(n - 3)/2 = 2e8; two swapped vertices add four long chords, each paired with
    # the edges in its x-range, and the first crossing is found
    big = regular(20_000, r=50.0)
    pair, n_pairs = self_crossing(big)
    assert pair is None and n_pairs < 4 * 20_000
    big[[10, 11_000]] = big[[11_000, 10]]
    pair, n_pairs = self_crossing(big)
    assert pair == next(filter(None, (brute_first_with(big, i) for i in range(10)))) and n_pairs < 10 * 20_000
    # and validation refuses it by count, before any geometry
    for n in (MAX_VERTICES + 1, 20_000):
        with pytest.raises(MapError) as e:
            validate_polygon("obstacles[0].vertices", closed(regular(n)))
        assert str(e.value) == f"obstacles[0].vertices: at most {MAX_VERTICES} vertices per polygon, got {n}"


def test_regular_polygon_pair_count():
    for n in (16, 256, MAX_VERTICES):
        pair, n_pairs = self_crossing(regular(n))
        assert pair is None and n_pairs < 4 * n


# ----------------------------------------------------------------------------- points and bodies


def test_numpy_point_in_polygon_matches_jax():
    rng = np.random.default_rng(3)
    polys = [star_polygon(rng, 9) for _ in range(3)] + [np.asarray(PARALLEL["kerb"], float)]
    pts = np.concatenate([rng.uniform(-1.2, 1.2, (2000, 2)), polys[3], [[0.0, -0.2], [0.5, -1.0]]])  # vertices, edges
    got = np.asarray(jax.jit(points_in_polygons)(jnp.asarray(pts), to_obstacle_map(polys)))
    for k, poly in enumerate(polys):
        np.testing.assert_array_equal(points_in_polygon_np(pts, poly), got[:, k])


def test_robot_rectangle_matches_geometry():
    rng = np.random.default_rng(4)
    for _ in range(20):
        x0 = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-179, 179))
        shape = robot_shape(rng.uniform(0.01, 0.5), width=rng.uniform(0.1, 0.5), length=0.54)
        ref = np.asarray(rectangle_corners(jnp.array([x0[0], x0[1], math.radians(x0[2])]), shape))
        np.testing.assert_allclose(robot_rectangle(x0, shape), ref, atol=1e-12)


SHAPE = (0.4, 0.6, 0.2)  # width, length, front (m): body x_b in [-0.4, 0.2], y_b in [-0.2, 0.2]


@pytest.mark.parametrize(
    "label, poly, expect",
    [
        ("flush below", [(-1, -1), (1, -1), (1, -0.2), (-1, -0.2)], False),
        ("flush corner to corner", [(0.2, 0.2), (1, 0.2), (1, 1), (0.2, 1)], False),
        ("vertex touches an edge", [(0.0, -0.2), (0.5, -1), (-0.5, -1)], False),
        ("1 mm in", [(-1, -1), (1, -1), (1, -0.199), (-1, -0.199)], True),
        ("corner inside", [(0.1, 0.1), (1, 0.1), (1, 1), (0.1, 1)], True),
        ("contains the rectangle", [(-5, -5), (5, -5), (5, 5), (-5, 5)], True),
        ("inside the rectangle", [(-0.1, -0.1), (0.1, -0.1), (0.0, 0.1)], True),
        ("the rectangle itself", [(-0.4, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.4, 0.2)], True),
        ("inscribed triangle", [(-0.4, -0.2), (0.2, 0.0), (-0.4, 0.2)], True),
        ("crossing bar, no vertex inside", [(-0.1, -3), (0.1, -3), (0.1, 3), (-0.1, 3)], True),
        (
            "a U around it, no overlap",
            [(-1, -1), (1, -1), (1, 1), (0.3, 1), (0.3, -0.5), (-0.5, -0.5), (-0.5, 1), (-1, 1)],
            False,
        ),
    ],
)
def test_body_overlap_by_hand(label, poly, expect):
    for orientation in (1, -1):  # either vertex order
        p = poly[::orientation]
        assert (body_overlaps({"o": p}, (0.0, 0.0, 0.0), SHAPE) != {}) is expect, label
        # the same configuration rotated and moved: the answer does not depend on the frame
        th = 0.7
        c, s = math.cos(th), math.sin(th)
        moved = [(3 + c * x - s * y, -2 + s * x + c * y) for x, y in p]
        # (touching cases now touch only up to rounding: the area tolerance keeps them touching)
        assert (body_overlaps({"o": moved}, (3.0, -2.0, math.degrees(th)), SHAPE) != {}) is expect, label


def test_body_overlap_against_sampling():
    """Dense sampling of the rectangle is the reference: its area estimate brackets the exact area,
    and a sampled point strictly inside the obstacle means overlap."""
    rng = np.random.default_rng(11)
    m = 150
    u = (np.arange(m) + 0.5) / m
    n_hit = n_free = 0
    for _ in range(300):
        poly = star_polygon(rng, int(rng.integers(3, 12)))
        width, length = rng.uniform(0.1, 0.5), rng.uniform(0.2, 0.7)
        shape = (width, length, rng.uniform(0.0, length))
        x0 = (rng.uniform(-0.9, 0.9), rng.uniform(-0.9, 0.9), rng.uniform(-180, 180))
        q = robot_rectangle(x0, shape)
        pts = (q[0][None, None] + u[:, None, None] * (q[1] - q[0]) + u[None, :, None] * (q[3] - q[0])).reshape(-1, 2)
        inside = MplPath(poly).contains_points(pts)
        sampled = inside.mean() * width * length
        area = overlap_area(poly, q)
        h = max(width, length) / m
        perim = 2 * (width + length) + np.sum(np.hypot(*np.diff(np.vstack([poly, poly[:1]]), axis=0).T))
        assert abs(area - sampled) <= 2 * h * perim, (area, sampled)
        hit = body_overlaps({"o": poly}, x0, shape) != {}
        if inside.any():
            assert hit
        if not hit:
            assert not inside.any() and area <= 1e-12
        n_hit += hit
        n_free += not hit
    assert n_hit > 60 and n_free > 60


def test_check_start_point_and_body():
    shape = run_params((0, 0, 0)).shape
    with pytest.raises(MapError, match=r"^--x0: start point \(0, -0\.5\) lies inside obstacle 'kerb'$"):
        check_start(PARALLEL, (0.0, -0.5, 0.0), shape)
    # axle point in the slot, rear of the body in the kerb
    with pytest.raises(
        MapError, match=r"^--x0: the robot's body at the start pose overlaps obstacle 'kerb' \(intersection area"
    ):
        check_start(PARALLEL, (0.0, 0.0, 60.0), shape)
    # axle point on the road, body into the car ahead; the key is the caller's
    with pytest.raises(
        MapError, match=r"^start_map\.x0\[4\]: the robot's body at the start pose overlaps obstacle 'car_ahead'"
    ):
        check_start(PARALLEL, (0.5, 0.3, 0.0), shape, key="start_map.x0[4]")
    check_start(PARALLEL, (0.0, 0.3, 0.0), shape)  # in the slot and the road, touching nothing
    check_start(PARALLEL, (1e300, 0.0, 0.0), shape)  # far outside the map: free, and no overflow in the tolerance
    # the reach ahead of the axle (--front) moves the body: the same pose overlaps with a long front
    with pytest.raises(MapError, match="overlaps obstacle 'car_ahead'"):
        check_start(PARALLEL, (0.0, 0.3, 0.0), run_params((0, 0, 0), front=0.53).shape)
    with pytest.raises(MapError, match="overlaps obstacle 'car_behind'"):
        check_start(PARALLEL, (0.0, 0.3, 0.0), run_params((0, 0, 0), front=0.01).shape)


@pytest.mark.parametrize("front", [None, 0.01, 0.1, 0.25, 0.4, 0.539])
def test_source_starts_accepted(front):
    """The source's cases and the garage start leave the body clear of every obstacle for any valid a_f."""
    starts = [(c["map"], c["x0"]) for c in CASES.values()] + [("garage", GARAGE_START)]
    for map_name, x0 in starts:
        shape = run_params(x0, front=front).shape
        check_start(BUILTIN[map_name], x0, shape)
        assert body_overlaps(BUILTIN[map_name], x0, (L1_WIDTH, L2_LENGTH, A_F if front is None else front)) == {}
    assert set(GARAGE) == {"wall_left", "wall_right", "garage_end"}
