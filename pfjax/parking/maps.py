"""Obstacle maps: the source's parallel-parking slot and garage (spec §4) and user maps from files.

A map file is TOML or JSON with a list of polygons, each a closed vertex list (first vertex
repeated last), in metres::

    name = "my_map"                       # optional
    [[obstacles]]
    vertices = [[0.5, -3.0], [3.0, -3.0], [3.0, 0.2], [0.5, 0.2], [0.5, -3.0]]

Validation (NumPy, at the edge) raises :class:`MapError` with one line naming the key: wrong
types, NaN/inf, a polygon that is not closed, fewer than 3 distinct vertices, zero area or
self-intersecting edges, unknown keys.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np

from pfjax.parking.geometry import ObstacleMap

#: Half-size (m) of the box the built-in obstacles extend to (the "everything else" of spec §4).
FAR = 3.0


class MapError(ValueError):
    """A bad obstacle map; the message is one line and names the key."""


def _box(x0, y0, x1, y1):
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


#: Parallel parking (spec §4, source Figs. 3-8): free = road y > 0.2 plus the slot |x| ≤ 0.5, |y| ≤ 0.2.
PARALLEL = {
    "car_behind": _box(-FAR, -FAR, -0.5, 0.2),
    "car_ahead": _box(0.5, -FAR, FAR, 0.2),
    "kerb": _box(-0.5, -FAR, 0.5, -0.2),
}
#: Garage (spec §4, source Figs. 12-17): free = x < −0.5 plus the garage −0.5 ≤ x ≤ 0.3, |y| ≤ 0.3.
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


def _proper_cross(p1, p2, q1, q2) -> bool:
    def orient(o, p, q):
        return (p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])

    d1, d2, d3, d4 = orient(q1, q2, p1), orient(q1, q2, p2), orient(p1, p2, q1), orient(p1, p2, q2)
    if d1 * d2 < 0 and d3 * d4 < 0:
        return True
    # collinear overlap of non-adjacent edges also makes the polygon degenerate
    if d1 == d2 == d3 == d4 == 0:
        lo = max(min(p1[0], p2[0]), min(q1[0], q2[0])), max(min(p1[1], p2[1]), min(q1[1], q2[1]))
        hi = min(max(p1[0], p2[0]), max(q1[0], q2[0])), min(max(p1[1], p2[1]), max(q1[1], q2[1]))
        return lo[0] <= hi[0] and lo[1] <= hi[1]
    return False


def validate_polygon(key: str, vertices) -> list[tuple[float, float]]:
    """A closed vertex list -> its distinct vertices; MapError naming ``key`` if it is not a simple polygon."""
    if not isinstance(vertices, list) or not vertices:
        raise MapError(f"{key}: expected a list of [x, y] vertices, got {vertices!r}")
    pts = []
    for j, v in enumerate(vertices):
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in v)):
            raise MapError(f"{key}[{j}]: expected [x, y] numbers, got {v!r}")
        if not all(math.isfinite(c) for c in v):
            raise MapError(f"{key}[{j}]: expected finite numbers, got {v!r}")
        pts.append((float(v[0]), float(v[1])))
    if len(pts) < 2 or pts[0] != pts[-1]:
        raise MapError(f"{key}: polygon not closed (the last vertex must repeat the first, {list(pts[0])})")
    pts = pts[:-1]
    if len(set(pts)) < 3 or len(set(pts)) != len(pts):
        raise MapError(f"{key}: degenerate polygon (needs >= 3 distinct vertices, none repeated), got {len(set(pts))} distinct")
    v = np.asarray(pts)
    area = 0.5 * float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    if abs(area) < 1e-9:
        raise MapError(f"{key}: degenerate polygon (zero area)")
    n = len(pts)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue
            if _proper_cross(pts[i], pts[(i + 1) % n], pts[j], pts[(j + 1) % n]):
                raise MapError(f"{key}: self-intersecting polygon (edges {i} and {j} cross)")
    return pts


def parse_map(data, source: str = "map") -> tuple[str, dict[str, list]]:
    """A decoded map document -> (name, {obstacle name: vertices}); MapError on any bad value."""
    if not isinstance(data, dict):
        raise MapError(f"{source}: expected a table with 'obstacles', got {type(data).__name__}")
    unknown = set(data) - {"name", "obstacles"}
    if unknown:
        raise MapError(f"{sorted(unknown)[0]}: unknown key (expected 'name', 'obstacles')")
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str):
        raise MapError(f"name: expected a string, got {name!r}")
    obs = data.get("obstacles")
    if not isinstance(obs, list) or not obs:
        raise MapError(f"obstacles: expected a non-empty list of polygons, got {obs!r}")
    out = {}
    for i, o in enumerate(obs):
        if not isinstance(o, dict):
            raise MapError(f"obstacles[{i}]: expected a table with 'vertices', got {o!r}")
        bad = set(o) - {"name", "vertices"}
        if bad:
            raise MapError(f"obstacles[{i}].{sorted(bad)[0]}: unknown key (expected 'name', 'vertices')")
        if "vertices" not in o:
            raise MapError(f"obstacles[{i}].vertices: missing")
        label = o.get("name", f"obstacle_{i}")
        if not isinstance(label, str):
            raise MapError(f"obstacles[{i}].name: expected a string, got {label!r}")
        out[label] = validate_polygon(f"obstacles[{i}].vertices", o["vertices"])
    return name, out


def load_map(spec: str) -> tuple[str, dict[str, list]]:
    """'parallel', 'garage' or a path to a TOML/JSON map file -> (name, polygons)."""
    if spec in BUILTIN:
        return spec, BUILTIN[spec]
    p = Path(spec)
    if not p.is_file():
        raise MapError(f"map: not 'parallel', 'garage' or an existing file: {spec}")
    text = p.read_text()
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else tomllib.loads(text)
    except (json.JSONDecodeError, tomllib.TOMLDecodeError) as e:
        raise MapError(f"map: {p}: invalid {'JSON' if p.suffix.lower() == '.json' else 'TOML'} ({str(e).splitlines()[0]})") from None
    return parse_map(data, str(p))


def point_in_polygon_np(pt, poly) -> bool:
    """Crossing-number test in NumPy (boundary counts as inside), for validation at the edges."""
    import jax
    import jax.numpy as jnp

    from pfjax.parking.geometry import points_in_polygons

    return bool(jax.jit(points_in_polygons)(jnp.asarray([pt], float), to_obstacle_map([poly]))[0, 0])


def check_start(polygons: dict[str, list], x: float, y: float, key: str = "--x0") -> None:
    """MapError when the start point (x, y) lies inside (or on) an obstacle."""
    for name, poly in polygons.items():
        if point_in_polygon_np((x, y), poly):
            raise MapError(f"{key}: start point ({x:g}, {y:g}) lies inside obstacle {name!r}")
