"""Obstacle maps: the source's parallel-parking slot and garage (docs/reproductions/parking.md §4) and user maps from files.

A map file is UTF-8 TOML or JSON with a list of polygons, each a closed vertex list (first vertex
repeated last), in metres::

    name = "my_map"                       # optional
    [[obstacles]]
    name = "car_ahead"                    # optional; obstacle i is called "obstacle_<i>" otherwise
    vertices = [[0.5, -3.0], [3.0, -3.0], [3.0, 0.2], [0.5, 0.2], [0.5, -3.0]]

Validation (NumPy, at the edge) raises :class:`MapError` with one line naming the key: a file
that cannot be read, is not UTF-8 or is not valid TOML/JSON (a JSON object with a repeated key
included); wrong types, NaN/inf or coordinates beyond ±:data:`MAX_COORD`; a polygon that is not
closed, has fewer than 3 distinct vertices or more than :data:`MAX_VERTICES`, zero area or
self-intersecting edges; more than :data:`MAX_OBSTACLES` obstacles; unknown keys; two obstacles
with the same name. :func:`check_start`
rejects a start pose whose axle point lies in an obstacle or whose rectangle overlaps one.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np

from pfjax.errors import InputError
from pfjax.parking.geometry import ObstacleMap
from pfjax.parking.overlap import (  # noqa: F401  (re-exported: the start check's NumPy geometry)
    OVERLAP_AREA_TOL,
    body_overlaps,
    orient,
    overlap_area,
    point_in_polygon_np,
    points_in_polygon_np,
    robot_rectangle,
)

#: Half-size (m) of the box the built-in obstacles extend to (the "everything else" of docs/reproductions/parking.md §4).
FAR = 3.0


class MapError(InputError):
    """A bad obstacle map; the message is one line and names the key."""


def _box(x0, y0, x1, y1):
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


#: Parallel parking (docs/reproductions/parking.md §4, source Figs. 3-8): free = road y > 0.2 plus the slot |x| ≤ 0.5, |y| ≤ 0.2.
PARALLEL = {
    "car_behind": _box(-FAR, -FAR, -0.5, 0.2),
    "car_ahead": _box(0.5, -FAR, FAR, 0.2),
    "kerb": _box(-0.5, -FAR, 0.5, -0.2),
}
#: Garage (docs/reproductions/parking.md §4, source Figs. 12-17): free = x < −0.5 plus the garage −0.5 ≤ x ≤ 0.3, |y| ≤ 0.3.
GARAGE = {
    "wall_left": _box(-0.5, 0.3, FAR, FAR),
    "wall_right": _box(-0.5, -FAR, FAR, -0.3),
    "garage_end": _box(0.3, -0.3, FAR, 0.3),
}
BUILTIN = {"parallel": PARALLEL, "garage": GARAGE}


def to_obstacle_map(polygons: list, dtype=float) -> ObstacleMap:
    """Polygons (each an (n, 2) vertex list, not repeated last) -> padded :class:`ObstacleMap`."""
    import jax.numpy as jnp

    n_e = max(len(p) for p in polygons)
    a = np.zeros((len(polygons), n_e, 2))
    b = np.zeros_like(a)
    valid = np.zeros((len(polygons), n_e), bool)
    for i, p in enumerate(polygons):
        v = np.asarray(p, float)
        a[i, : len(v)], b[i, : len(v)], valid[i, : len(v)] = v, np.roll(v, -1, axis=0), True
    return ObstacleMap(jnp.asarray(a, dtype), jnp.asarray(b, dtype), jnp.asarray(valid))


#: Most vertices one polygon may have. The simulator unrolls its loop over a polygon's edges
#: (:func:`pfjax.parking.geometry.points_in_polygons`), so its compile time grows quickly with the
#: longest polygon (measured, compiling the map test alone on a 2-core machine: 1.5 s at 16 edges,
#: 16 s at 128, 285 s at 512): the limit keeps a map simulable. The self-intersection test
#: (:func:`self_crossing`) visits the pairs of edges whose x-ranges overlap: about 3 n for a convex
#: or star-shaped polygon, at worst n (n − 1) / 2.
MAX_VERTICES = 128
#: Most obstacles one map may have (checked before any polygon is validated). Measured on a 2-core
#: machine, one run at a 2 s horizon: reading and validating 200 obstacles of 128 vertices takes
#: 0.14 s, 2,000 take 1.45 s (20,000 of 16 vertices 3.7 s); the run itself is dominated by the
#: compilation for the longest polygon (about 115 s and 3 GB at 128 vertices, 8-17 s and 0.5 GB at
#: 16 vertices from 200 to 20,000 obstacles). The simulator pads every polygon to the longest, so
#: the cap bounds its arrays at 1,000 x 128 edges, far beyond any parking scene (the built-in maps
#: have 3 obstacles).
MAX_OBSTACLES = 1000
#: Largest coordinate magnitude of a map vertex, m (orientation products stay far from overflow
#: and the zero-area test keeps its meaning).
MAX_COORD = 1e6
#: Largest map file :func:`load_map` reads, bytes.
MAX_FILE_BYTES = 64 * 2**20
_PAIR_CHUNK = 2**20  # edge pairs tested per whole-array block


def _segments_conflict(p1, p2, q1, q2):
    """(K,) bool: segments p1p2 and q1q2 ((K, 2) arrays, m) cross properly or overlap collinearly.

    Proper crossing: each segment's end points strictly on opposite sides of the other's line (and
    their bounding boxes overlap, which exact arithmetic implies). Collinear overlap: all four
    orientations zero and the closed bounding boxes overlap. A segment end point on the other
    segment without crossing it (a touch) is neither.
    """
    d1, d2, d3, d4 = orient(q1, q2, p1), orient(q1, q2, p2), orient(p1, p2, q1), orient(p1, p2, q2)
    lo = np.maximum(np.minimum(p1, p2), np.minimum(q1, q2))
    hi = np.minimum(np.maximum(p1, p2), np.maximum(q1, q2))
    boxes = np.all(lo <= hi, axis=-1)
    proper = (d1 * d2 < 0) & (d3 * d4 < 0)
    collinear = (d1 == 0) & (d2 == 0) & (d3 == 0) & (d4 == 0)
    return (proper | collinear) & boxes


def self_crossing(v) -> tuple[tuple[int, int] | None, int]:
    """The first pair of non-adjacent edges of a closed polygon that cross or overlap (sort and sweep).

    Edge i runs from ``v[i]`` to ``v[(i + 1) % n]``. The edges are sorted by their smallest x, and
    each is paired with the edges after it in that order whose smallest x lies within its x-range:
    every pair with overlapping closed x-ranges, once (O(n log n) plus the number of such pairs).
    Pairs with disjoint y-ranges and adjacent edges are dropped, and the rest are tested exactly in
    blocks of whole-array operations by :func:`_segments_conflict` (proper crossing or collinear
    overlap; a vertex touching a non-adjacent edge without crossing it is not reported).

    Args:
        v: (n, 2) distinct vertices, m, the first not repeated last; n >= 3.

    Returns:
        ``(pair, n_pairs)``: ``pair = (i, j)``, the lexicographically smallest reported pair with
        i < j, or None for a simple polygon; ``n_pairs``, the number of edge pairs the x sweep
        produced (the work done; at most n (n − 1) / 2).
    """
    v = np.asarray(v, float)
    n = len(v)
    a, b = v, np.roll(v, -1, axis=0)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.argsort(lo[:, 0], kind="stable")
    xs = lo[order, 0]
    # sorted edges k + 1 .. reach[k] − 1 start within edge k's x-range (reach[k] > k as xs[k] <= its max x)
    reach = np.searchsorted(xs, hi[order, 0], side="right")
    counts = reach - np.arange(n) - 1
    cum = np.cumsum(counts)
    best = None
    r0 = 0
    while r0 < n:
        done = int(cum[r0 - 1]) if r0 else 0
        r1 = max(r0 + 1, int(np.searchsorted(cum, done + _PAIR_CHUNK, side="right")))
        c = counts[r0:r1]
        k = np.repeat(np.arange(r0, r1), c)
        m = k + 1 + np.arange(len(k)) - np.repeat(np.cumsum(c) - c, c)
        i, j = order[k], order[m]
        keep = np.maximum(lo[i, 1], lo[j, 1]) <= np.minimum(hi[i, 1], hi[j, 1])
        i, j = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
        keep = (j != i + 1) & ~((i == 0) & (j == n - 1))
        i, j = i[keep], j[keep]
        hit = _segments_conflict(a[i], b[i], a[j], b[j])
        if hit.any():
            code = int(np.min(i[hit] * n + j[hit]))
            best = code if best is None else min(best, code)
        r0 = r1
    return (None if best is None else divmod(best, n)), int(cum[-1])


def _coordinate(c) -> float | None:
    """A JSON/TOML number as a float within ±MAX_COORD, else None (bool, string, NaN, inf, huge int)."""
    if isinstance(c, bool) or not isinstance(c, (int, float)):
        return None
    try:
        f = float(c)
    except OverflowError:
        return None
    return f if math.isfinite(f) and abs(f) <= MAX_COORD else None


def validate_polygon(key: str, vertices) -> list[tuple[float, float]]:
    """A closed vertex list -> its distinct vertices; MapError naming ``key`` if it is not a simple polygon.

    Args:
        key: the key the messages start with (``obstacles[i].vertices``).
        vertices: ``[[x, y], ...]`` in m, the first vertex repeated last; at most
            :data:`MAX_VERTICES` distinct vertices, coordinates finite and within ±:data:`MAX_COORD`.

    Returns:
        The distinct vertices as (x, y) float tuples, m, without the repeated last one.
    """
    if not isinstance(vertices, list) or not vertices:
        raise MapError(f"{key}: expected a list of [x, y] vertices, got {vertices!r:.80}")
    n_given = len(vertices) - 1 if len(vertices) > 1 and vertices[0] == vertices[-1] else len(vertices)
    if n_given > MAX_VERTICES:
        raise MapError(f"{key}: at most {MAX_VERTICES} vertices per polygon, got {n_given}")
    pts = []
    for j, v in enumerate(vertices):
        if not (
            isinstance(v, list)
            and len(v) == 2
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)
        ):
            raise MapError(f"{key}[{j}]: expected [x, y] numbers, got {v!r:.80}")
        x, y = (_coordinate(c) for c in v)
        if x is None or y is None:
            raise MapError(f"{key}[{j}]: expected finite numbers within ±{MAX_COORD:g} m, got {v!r:.80}")
        pts.append((x, y))
    if len(pts) < 2 or pts[0] != pts[-1]:
        raise MapError(f"{key}: polygon not closed (the last vertex must repeat the first, {list(pts[0])})")
    pts = pts[:-1]
    if len(set(pts)) < 3 or len(set(pts)) != len(pts):
        raise MapError(
            f"{key}: degenerate polygon (needs >= 3 distinct vertices, none repeated), got {len(set(pts))} distinct"
        )
    v = np.asarray(pts)
    area = 0.5 * float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    if abs(area) < 1e-9:
        raise MapError(f"{key}: degenerate polygon (zero area)")
    pair, _ = self_crossing(v)
    if pair is not None:
        raise MapError(f"{key}: self-intersecting polygon (edges {pair[0]} and {pair[1]} cross)")
    return pts


def parse_map(data, source: str = "map") -> tuple[str, dict[str, list]]:
    """A decoded map document -> (name, {obstacle name: vertices}); MapError on any bad value.

    Obstacle names are unique. An obstacle without ``name`` is called ``obstacle_<i>`` (i its index
    in ``obstacles``); when that name is also given explicitly to another obstacle the map is
    rejected rather than the default renamed, so the default names stay predictable (obstacle i is
    ``obstacle_<i>`` or the map is refused) and a name in a message (for example from
    :func:`check_start`) designates exactly one polygon of the file.

    Args:
        data: the decoded TOML/JSON document.
        source: the file it came from; its stem is the map's name when ``name`` is absent.

    Returns:
        ``(name, polygons)``: the map's name and the validated polygons in file order, each a list of
        distinct (x, y) vertices in m (:func:`validate_polygon`); 1 to :data:`MAX_OBSTACLES` of them.
    """
    if not isinstance(data, dict):
        raise MapError(f"{source}: expected a table with 'obstacles', got {type(data).__name__}")
    unknown = set(data) - {"name", "obstacles"}
    if unknown:
        raise MapError(f"{sorted(unknown)[0]}: unknown key (expected 'name', 'obstacles')")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise MapError(f"name: expected a string, got {name!r:.80}")
    obs = data.get("obstacles")
    if not isinstance(obs, list) or not obs:
        raise MapError(f"obstacles: expected a non-empty list of polygons, got {obs!r:.80}")
    if len(obs) > MAX_OBSTACLES:
        raise MapError(f"obstacles: at most {MAX_OBSTACLES} obstacles per map, got {len(obs)}")
    out = {}
    owner: dict[str, tuple[int, bool]] = {}  # name -> (index of the obstacle that has it, given explicitly)
    for i, o in enumerate(obs):
        if not isinstance(o, dict):
            raise MapError(f"obstacles[{i}]: expected a table with 'vertices', got {o!r:.80}")
        bad = set(o) - {"name", "vertices"}
        if bad:
            raise MapError(f"obstacles[{i}].{sorted(bad)[0]}: unknown key (expected 'name', 'vertices')")
        if "vertices" not in o:
            raise MapError(f"obstacles[{i}].vertices: missing")
        explicit = "name" in o
        label = o["name"] if explicit else f"obstacle_{i}"
        if not isinstance(label, str):
            raise MapError(f"obstacles[{i}].name: expected a string, got {label!r:.80}")
        if label in owner:
            k, k_explicit = owner[label]
            if explicit:
                also = f"obstacles[{k}]" if k_explicit else f"obstacles[{k}], unnamed, which has it by default"
                raise MapError(f"obstacles[{i}].name: duplicate obstacle name {label!r} (also {also})")
            raise MapError(
                f"obstacles[{i}].name: missing, and the default name {label!r} is taken by obstacles[{k}]; "
                f"name obstacles[{i}] explicitly"
            )
        owner[label] = (i, explicit)
        out[label] = validate_polygon(f"obstacles[{i}].vertices", o["vertices"])
    return name, out


def _no_duplicate_keys(pairs):
    """JSON object hook: the object as a dict; ValueError on a key given twice."""
    seen = {}
    for k, v in pairs:
        if k in seen:
            raise ValueError(f"duplicate key {k!r}")
        seen[k] = v
    return seen


def load_map(spec: str) -> tuple[str, dict[str, list]]:
    """'parallel', 'garage' or a path to a TOML/JSON map file -> (name, polygons).

    The file is read as UTF-8 (a leading byte-order mark is skipped), at most
    :data:`MAX_FILE_BYTES`; ``.json`` files are JSON (an object with a repeated key is refused),
    anything else TOML. Every failure is a one-line MapError starting with ``map: <path>:`` (``map:``
    alone for an empty ``spec``).
    """
    if spec in BUILTIN:
        return spec, BUILTIN[spec]
    if not spec:
        raise MapError("map: expected 'parallel', 'garage' or a TOML/JSON map file, got ''")
    p = Path(spec)
    if p.is_dir():
        raise MapError(f"map: {p}: is a directory, expected a TOML or JSON file")
    if not p.is_file():
        raise MapError(f"map: {spec}: not 'parallel', 'garage' or an existing TOML/JSON map file")
    kind = "JSON" if p.suffix.lower() == ".json" else "TOML"
    try:
        size = p.stat().st_size
        if size > MAX_FILE_BYTES:
            raise MapError(f"map: {p}: file too large ({size} bytes, at most {MAX_FILE_BYTES})")
        raw = p.read_bytes()
    except OSError as e:
        raise MapError(f"map: {p}: cannot read ({e.strerror or type(e).__name__})") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise MapError(
            f"map: {p}: not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}: {e.reason})"
        ) from None
    try:
        data = json.loads(text, object_pairs_hook=_no_duplicate_keys) if kind == "JSON" else tomllib.loads(text)
    except RecursionError:
        raise MapError(f"map: {p}: invalid {kind} (nested too deeply)") from None
    except ValueError as e:  # JSONDecodeError, TOMLDecodeError, a duplicate key, an integer too long to convert
        first = (str(e).splitlines() or [type(e).__name__])[0]
        raise MapError(f"map: {p}: invalid {kind} ({first})") from None
    return parse_map(data, str(p))


def check_start(polygons: dict[str, list], x0, shape, key: str = "--x0") -> None:
    """MapError naming ``key`` when the start pose puts the robot in an obstacle.

    First the axle point (x, y): inside or on an obstacle is refused
    (:func:`~pfjax.parking.overlap.point_in_polygon_np`). Then the body: the rectangle at the pose overlapping an
    obstacle is refused (:func:`~pfjax.parking.overlap.body_overlaps`; touching is allowed here, and
    refused after this check by the single-run entry points of :mod:`pfjax.parking.api`, with the
    simulation's own closed-set start test, which would end such a run at once).

    Args:
        polygons: {name: (n, 2) vertices, m}, as :func:`load_map` returns.
        x0: start pose (x m, y m, θ deg).
        shape: the simulated robot's (width m, length m, front m), e.g. ``run_params(x0, front=...).shape``.
    """
    x, y = float(x0[0]), float(x0[1])
    for name, poly in polygons.items():
        if point_in_polygon_np((x, y), poly):
            raise MapError(f"{key}: start point ({x:g}, {y:g}) lies inside obstacle {name!r}")
    hits = body_overlaps(polygons, x0, shape)
    if hits:
        name, area = next(iter(hits.items()))
        more = f"; also {len(hits) - 1} other obstacle{'s' if len(hits) > 2 else ''}" if len(hits) > 1 else ""
        raise MapError(
            f"{key}: the robot's body at the start pose overlaps obstacle {name!r} "
            f"(intersection area {area:.3g} m^2{more})"
        )
