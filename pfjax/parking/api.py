"""The parking subsystem's entry points for Python callers: one run (:func:`run`) and the search of
the garage's switching parameters (:func:`search`), checked as the command line checks them.

``pfjax parking`` and ``pfjax parking-search`` are these two functions: every bad argument raises
:class:`~pfjax.errors.InputError` with one line starting with the argument's name (``"x0: ..."``,
``"front: must be < 0.54 ..."``), which the command line reprints with the flag's name. Errors in a
map file, or in the start pose against the map, raise its subclass
:class:`~pfjax.parking.maps.MapError`: the message is the map check's own (it names the key in
the file, e.g. ``obstacles[1].name: ...``) and the ``key`` is ``"map"`` or ``"x0"``.

Nothing is simulated before every argument has been checked. Both check and simulate in float64,
as the command line does, whatever ``jax_enable_x64`` says: the same start pose is refused or run
alike, and the numbers are the command line's.

Only :mod:`pfjax.errors`, :mod:`pfjax.parking.defaults` and :mod:`pfjax.parking.limits` are
imported here at module level: importing :mod:`pfjax.parking` stays cheap. Every default is
:mod:`pfjax.parking.defaults`'s.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any, NamedTuple

from pfjax import errors
from pfjax.errors import InputError
from pfjax.parking import defaults as D
from pfjax.parking.limits import MAX_PERIODS, MAX_SCAN_PERIOD, check_periods

__all__ = ["run", "search"]

#: Travel directions :func:`run` accepts, with their sign.
DIRECTIONS = {"forward": 1, "backward": -1}
#: A direction's name by its sign (:data:`DIRECTIONS` read back; the source's cases give the sign).
DIRECTION_NAMES = {sign: name for name, sign in DIRECTIONS.items()}
#: Search methods :func:`search` accepts.
METHODS = ("ga", "grid")
#: Most scanner periods one search may simulate: its runs (``n^3`` on the grid, at most
#: ``population * (generations + 1)`` for the GA) times ``t_max / scan_period`` each. Measured on a
#: 2-core machine at the defaults (200 s / 0.1 s): the grid's 512 runs take 1.4 s and its 1,728
#: runs 5.4 s (about 3 ms a run), so the default ``n = 32`` (32,768 runs, 6.6e7 periods) takes
#: about 2 minutes and this limit about 3; ``n = 64`` at the defaults (5.2e8) and a GA of
#: 1,000 x 1,000 (2e9) are refused.
MAX_SEARCH_PERIODS = 10**8
#: The scanner period of :func:`run` and :func:`search` unless given, s (the source's).
DEFAULT_SCAN_PERIOD = D.SCAN_PERIOD
#: Garage rule of :func:`run` on the built-in garage: switch back to forward when backing past this x, m.
GARAGE_XS = D.GARAGE_XS


class _Settings(NamedTuple):
    """The run settings :func:`run` and :func:`search` share, as given (checked by :func:`_checked`)."""

    k1: Any  # 1/m², gain on y
    k2: Any  # 1/m, gain on tan θ
    speed: Any  # m/s, |v₁|
    scan_period: Any  # s
    front: Any  # m, or None: the calibrated a_f
    lag: Any  # bool, the yaw-rate PI loop on
    t_max: Any  # s, timeout


def _pose(x0) -> dict:
    """A start pose (x m, y m, θ deg) as the outputs spell it."""
    return {"x": x0[0], "y": x0[1], "theta_deg": x0[2]}


def _map_spec(map) -> str:
    """``map`` as the string :func:`pfjax.parking.maps.load_map` takes (a name or a path)."""
    spec = os.fspath(map) if isinstance(map, (str, os.PathLike)) else None
    if not isinstance(spec, str):
        raise InputError(f"map: expected 'parallel', 'garage' or a TOML/JSON file path, got {map!r:.80}", "map")
    return spec


def _start(x0, spec: str, default_start: dict) -> tuple[float, float, float]:
    """The start pose (x m, y m, theta deg), checked, or the map's default when ``x0`` is None."""
    if x0 is None:
        start = default_start.get(spec)
        if start is None:
            raise InputError(f"x0: required (no default start for map {spec!r})", "x0")
        x, y, theta = (float(v) for v in start)
        return x, y, theta
    try:
        values = None if isinstance(x0, (str, bytes)) else list(x0)
    except TypeError:
        values = None
    if values is None or len(values) != 3:
        raise InputError(f"x0: expected 3 numbers (x m, y m, theta deg), got {x0!r:.80}", "x0")
    x, y, theta = (errors.number("x0", v) for v in values)
    errors.number("x0", theta, below=90.0, unit=" deg")
    return x, y, theta


def _schedule(alpha_schedule):
    """The alpha schedule, padded (:func:`pfjax.parking.schedules.pad_schedule`)."""
    from pfjax.parking.schedules import pad_schedule, parse_schedule

    if isinstance(alpha_schedule, str):
        return parse_schedule(alpha_schedule, "alpha_schedule")
    if errors.is_number(alpha_schedule):
        alpha_schedule = (alpha_schedule,)
    try:
        values = None if isinstance(alpha_schedule, (bytes, Mapping)) else list(alpha_schedule)
    except TypeError:
        values = None
    if values is None:
        raise InputError(
            f"alpha_schedule: expected numbers or a comma-separated string, got {alpha_schedule!r:.80}",
            "alpha_schedule",
        )
    return pad_schedule(values, "alpha_schedule")


def _check_touch(polygons: dict, p0, omap) -> None:
    """MapError ``x0`` when the rectangle at the start pose touches an obstacle (a contact of zero
    area, which :func:`pfjax.parking.maps.check_start` lets pass): the simulation's own start test
    (:func:`pfjax.parking.geometry.obstacle_ahead` on both halves, closed sets, in the run's
    precision) would end the run at once as ``start_overlap``."""
    from pfjax.parking.geometry import obstacle_ahead
    from pfjax.parking.maps import MapError, to_obstacle_map

    def touches(m) -> bool:
        return bool(obstacle_ahead(p0.pose0, p0.shape, 1.0, m) | obstacle_ahead(p0.pose0, p0.shape, -1.0, m))

    if not touches(omap):
        return
    name = next((n for n, poly in polygons.items() if touches(to_obstacle_map([poly]))), "?")
    raise MapError(
        f"x0: the robot's rectangle at the start pose touches obstacle {name!r} (the run would end at once "
        "as start_overlap); move the start away from it",
        "x0",
    )


def map_sha256(polygons: dict) -> str:
    """SHA-256 of a map's obstacles (``{name: vertices}``, m), as canonical JSON: what a run's
    outputs record, so that a map file edited under the same name gives another config hash."""
    from pfjax.provenance import config_hash

    return config_hash({name: [[float(v) for v in p] for p in poly] for name, poly in polygons.items()})


def _checked(map, x0, settings: _Settings, default_start: dict) -> dict:
    """The arguments :func:`run` and :func:`search` share, checked in the command line's order;
    the map loaded and the start pose checked against it."""

    from pfjax.parking.maps import MapError, check_start, load_map, to_obstacle_map

    k1, k2, speed, scan_period, t_max = (
        errors.number(key, getattr(settings, key), positive=True)
        for key in ("k1", "k2", "speed", "scan_period", "t_max")
    )
    front, lag = settings.front, settings.lag
    if front is not None:
        front = errors.number("front", front, positive=True)
        if front >= D.L2_LENGTH:
            raise InputError(
                f"front: must be < {D.L2_LENGTH:g} (the rectangle length), got {errors.shown(front)}", "front"
            )
    if scan_period > MAX_SCAN_PERIOD:
        raise InputError(
            f"scan_period: must be <= {MAX_SCAN_PERIOD:g} s, got {errors.shown(scan_period)}", "scan_period"
        )
    # the product names t_max where the timeout alone is too long for the default period
    check_periods("t_max" if t_max / DEFAULT_SCAN_PERIOD > MAX_PERIODS else "scan_period", t_max, scan_period)
    errors.boolean("lag", lag)
    spec = _map_spec(map)
    try:
        name, polygons = load_map(spec)
    except MapError as e:
        raise MapError(str(e), "map") from None
    x0 = _start(x0, spec, default_start)
    from pfjax.parking.model import control_params
    from pfjax.parking.simulate import run_params

    p0 = run_params(x0, front=front)  # the pose and rectangle the run will simulate
    try:
        check_start(polygons, x0, p0.shape, key="x0")
    except MapError as e:
        raise MapError(str(e), "x0") from None
    omap = to_obstacle_map(list(polygons.values()))
    _check_touch(polygons, p0, omap)
    return {
        "name": name,
        "sha256": map_sha256(polygons),
        "spec": spec,
        "omap": omap,
        "x0": x0,
        "front": front,
        "scan_period": scan_period,
        "t_max": t_max,
        "control": control_params(k1=k1, k2=k2, speed=speed, lag=bool(lag)),
    }


@errors.arguments_checked
def run(
    map="parallel",
    x0=None,
    *,
    direction="forward",
    alpha_schedule=(1.0,),
    xs=None,
    k1=D.K1,
    k2=D.K2,
    speed=D.SPEED,
    scan_period=DEFAULT_SCAN_PERIOD,
    front=None,
    lag=False,
    t_max=D.T_MAX,
) -> dict:
    """One run of the switching parking controller (``pfjax parking``): outcome, parking time and
    the log of direction switches. Checked and simulated in float64, as the command does, whatever
    ``jax_enable_x64`` says.

    Args:
        map: ``"parallel"`` (the parallel-parking slot), ``"garage"``, or the path (str or
            path-like) of a TOML/JSON map file (:mod:`pfjax.parking.maps`).
        x0: start pose (x m, y m, theta deg), ``|theta| < 90 deg``; None: case A's
            (-0.4 m, 0.5 m, 0 deg) on ``"parallel"``, (-0.9 m, 0.6 m, -85 deg) on ``"garage"``
            (required for a map file). The robot's body must not overlap an obstacle there, nor
            its rectangle touch one.
        direction: first travel direction, ``"forward"`` or ``"backward"``.
        alpha_schedule: the gain factor alpha (dimensionless, each in [1e-12, 1e12]) at the start,
            then after each direction switch, the last one holding from then on; 1 to 8 numbers (a
            sequence, not a mapping), or the command line's comma-separated string
            (``"1,0.5,8,1"``), both checked by :func:`pfjax.parking.schedules.pad_schedule`.
        xs: garage rule, m: after the first switch to backward, switch back to forward when
            backing past ``x = xs``; None: no such rule, except on ``"garage"`` (-0.9 m).
        k1: gain on y, 1/m^2 (> 0).
        k2: gain on tan(theta), 1/m (> 0).
        speed: travel speed |v1|, m/s (> 0).
        scan_period: the scanner's sampling period, s (> 0, at most 10 s, and at least
            ``t_max / 20000``: a run is at most 20,000 scanner periods).
        front: reach a_f of the robot's rectangle ahead of the axle, m, in (0, 0.54); None: the
            calibrated value (:mod:`pfjax.parking.calibrate`).
        lag: True: the yaw rate follows the command through the PI loop (kP 0.8, kI 16 1/s).
        t_max: timeout, s (> 0).

    Returns:
        The result ``pfjax parking --json`` prints, beside which the command records its arguments,
        config hash, machine and the ``units`` of every number (:mod:`pfjax.cli.records`; the units
        by key: :data:`pfjax.tables.PARKING_RUN_UNITS`): ``map`` (name), ``map_sha256`` (the obstacles'
        SHA-256, :func:`map_sha256`), ``x0`` ({x m, y m, theta_deg}),
        ``direction``, ``alpha_schedule`` (padded to 8 values), ``xs`` (m or None), ``a_f`` (m),
        then :func:`pfjax.parking.summary.run_summary`: ``converged``, ``status``, ``time_s``,
        ``switches``, ``switch_log`` ([{t s, x m, y m, theta_deg, cause}]), ``final``
        ({x m, y m, theta_deg}), ``error`` (``|x| + sqrt(y^2 + tan^2 theta)``) and ``distance_m``.

    Raises:
        InputError: a bad argument; the message starts with its name. A map file that cannot be
            read or is invalid, and a start pose in an obstacle, raise its subclass
            :class:`~pfjax.parking.maps.MapError` with key ``"map"`` or ``"x0"``.
    """
    from pfjax.parking.schedules import CASES, GARAGE_START

    if not isinstance(direction, str) or direction not in DIRECTIONS:
        raise InputError(f"direction: expected 'forward' or 'backward', got {direction!r:.80}", "direction")
    schedule = _schedule(alpha_schedule)
    xs = None if xs is None else errors.number("xs", xs)
    settings = _Settings(k1, k2, speed, scan_period, front, lag, t_max)
    import jax

    with jax.enable_x64(True):  # as pfjax parking: the same start checks and numbers
        c = _checked(map, x0, settings, {"parallel": CASES["A"]["x0"], "garage": GARAGE_START})
        if xs is None and c["spec"] == "garage":  # the garage always has its X_s rule
            xs = GARAGE_XS
        return _one_run(c, direction, schedule, xs)


def _one_run(c: dict, direction: str, schedule, xs) -> dict:
    """Simulate the checked run :func:`run` describes and summarise it."""
    from pfjax.parking.simulate import ParkingConfig, run_jit, run_params
    from pfjax.parking.summary import run_summary

    x0 = c["x0"]
    p = run_params(
        x0,
        DIRECTIONS[direction],
        list(schedule),
        xs=xs,
        front=c["front"],
        scan_period=c["scan_period"],
        control=c["control"],
    )
    r = run_jit(p, c["omap"], ParkingConfig(t_max=c["t_max"]))
    return {
        "map": c["name"],
        "map_sha256": c["sha256"],
        "x0": _pose(x0),
        "direction": direction,
        "alpha_schedule": [float(a) for a in schedule],
        "xs": xs,
        "a_f": float(p.shape.front),
        **run_summary(r),
    }


#: The settings each search method reads (:func:`search`), and their defaults.
SEARCH_SETTINGS = {"grid": ("n",), "ga": ("generations", "population", "seed")}
SEARCH_DEFAULTS = {"n": D.GRID_N, "generations": D.GENERATIONS, "population": D.POPULATION, "seed": 0}


@errors.arguments_checked
def search(
    method,
    *,
    map="garage",
    x0=None,
    n=None,
    generations=None,
    population=None,
    seed=None,
    weight=D.WEIGHT,
    k1=D.K1,
    k2=D.K2,
    speed=D.SPEED,
    scan_period=DEFAULT_SCAN_PERIOD,
    front=None,
    lag=False,
    t_max=D.T_MAX,
) -> dict:
    """Search of the garage's switching parameters (X_s, alpha1, alpha2) (``pfjax parking-search``):
    the source's 24-bit GA or an exhaustive ``n x n x n`` grid on the chromosome lattice
    (:mod:`pfjax.parking.switch_search`), maximising ``J = 1 / (t_e + weight * e)``.

    Each candidate runs forward from ``x0`` with alpha = 1, then alpha1 after the first switch and
    alpha2 from the second on, and the garage rule at X_s; more than 10 switches fail it. Checked
    and simulated in float64, as the command does, whatever ``jax_enable_x64`` says.

    Args:
        method: ``"ga"`` or ``"grid"``.
        map: ``"garage"``, ``"parallel"`` or the path (str or path-like) of a TOML/JSON map file.
        x0: start pose (x m, y m, theta deg), ``|theta| < 90 deg``; None: (-0.9 m, 0.6 m, -85 deg)
            on ``"garage"`` (required for any other map); checked as for :func:`run`.
        n: grid levels per parameter, 2..64 (grid only; ``n^3`` runs; None: 32).
        generations: GA generations N, >= 1 (GA only; None: 100).
        population: GA population size n, >= 2 (GA only; at most ``population * (generations + 1)``
            runs; None: 20).
        seed: PRNG seed of the GA, 0..2^63 - 1 (GA only; None: 0). A setting of the other method
            given (not None) is refused, naming it: it would be ignored.
        weight: end-error weight w in J, s/m (>= 0).
        k1: gain on y, 1/m^2 (> 0).
        k2: gain on tan(theta), 1/m (> 0).
        speed: travel speed |v1|, m/s (> 0).
        scan_period: the scanner's sampling period, s (> 0, at most 10 s, and at least
            ``t_max / 20000``: a run is at most 20,000 scanner periods).
        front: reach a_f of the robot's rectangle ahead of the axle, m, in (0, 0.54); None: the
            calibrated value.
        lag: True: the yaw rate follows the command through the PI loop (kP 0.8, kI 16 1/s).
        t_max: timeout of each run, s (> 0).

    Returns:
        The result ``pfjax parking-search --json`` prints beside the command's record (as
        :func:`run`'s; units by key: :data:`pfjax.tables.PARKING_SEARCH_UNITS`): ``map`` (name), ``map_sha256``, ``x0`` ({x m, y m,
        theta_deg}), ``method``, the best ``xs`` (m), ``alpha1``, ``alpha2``, its ``fitness``,
        ``time_s``, ``status`` (name), ``converged``, ``switches`` and ``error``,
        ``n_simulations`` and ``a_f`` (m, the rectangle's reach ahead of the axle); the grid adds ``n``, the GA ``bits`` (its best chromosome: 24 values, each 0 or 1), ``history_best_fitness``,
        ``history_mean_fitness`` (per generation) and ``seed``.

    The search's size is checked before anything is simulated: its runs times ``t_max /
    scan_period`` may be at most :data:`MAX_SEARCH_PERIODS` (1e8) scanner periods, so the default
    grid (``n = 32``, 6.6e7 at 200 s / 0.1 s) passes and ``n = 64`` needs ``t_max <= 38 s``.

    Raises:
        InputError: a bad argument, as for :func:`run` (a map or start pose error as its subclass
            :class:`~pfjax.parking.maps.MapError`); ``n`` or ``population/generations`` for a
            search above :data:`MAX_SEARCH_PERIODS`.
    """
    if not isinstance(method, str) or method not in METHODS:
        raise InputError(f"method: expected 'ga' or 'grid', got {method!r:.80}", "method")
    given = {"n": n, "generations": generations, "population": population, "seed": seed}
    for key, value in given.items():
        if value is not None and key not in SEARCH_SETTINGS[method]:
            raise InputError(f"{key}: not with method {method} (a setting of the other method)", key)
    n, generations, population, seed = (SEARCH_DEFAULTS[k] if v is None else v for k, v in given.items())
    weight = errors.number("weight", weight, nonnegative=True)
    n = errors.integer("n", n, low=2, high=D.MAX_GRID_N)
    from pfjax.tuning.ga import MAX_GENERATIONS, MAX_POPULATION

    population = errors.integer("population", population, low=2, high=MAX_POPULATION)
    generations = errors.integer("generations", generations, low=1, high=MAX_GENERATIONS)
    seed = errors.seed("seed", seed)
    from pfjax.parking.schedules import GARAGE_START

    settings = _Settings(k1, k2, speed, scan_period, front, lag, t_max)
    import jax

    with jax.enable_x64(True):  # as pfjax parking-search: the same start checks and numbers
        c = _checked(map, x0, settings, {"garage": GARAGE_START, "parallel": None})
        _check_work(method, n, generations, population, c["t_max"], c["scan_period"])
        out = _search(c, method, n=n, generations=generations, population=population, seed=seed, weight=weight)
    return {"map": c["name"], "map_sha256": c["sha256"], "x0": _pose(c["x0"]), **out}


def _check_work(method: str, n: int, generations: int, population: int, t_max: float, scan_period: float) -> None:
    """:class:`InputError` when the search would simulate more than :data:`MAX_SEARCH_PERIODS`
    scanner periods (named ``n`` on the grid, ``population/generations`` for the GA)."""
    if method == "grid":
        check_search_work("n", n**3, f"n^3 = {n}^3 = {n**3}", t_max, scan_period)
    else:
        runs = population * (generations + 1)
        how = f"population x (generations + 1) = {population} x {generations + 1} = {runs}"
        check_search_work("population/generations", runs, how, t_max, scan_period)


def check_search_work(
    key: str, runs: int, how: str, t_max: float, scan_period: float, what: str = "the search"
) -> None:
    """:class:`InputError` naming ``key`` when ``runs`` runs of ``ceil(t_max / scan_period)``
    scanner periods each exceed :data:`MAX_SEARCH_PERIODS` (``how``: the runs' count as the message
    spells it; ``what``: the work it is). The search's check here and the parking study's
    (:mod:`pfjax.parking.study_config`: its searches and its Monte Carlo)."""
    periods = math.ceil(t_max / scan_period)
    if runs * periods > MAX_SEARCH_PERIODS:
        raise InputError(
            f"{key}: {what} may simulate at most {MAX_SEARCH_PERIODS:.0e} scanner periods (runs x t_max / "
            f"scan_period), got {how} runs x {periods} periods = {runs * periods:.3g}",
            key,
        )


def _search(c: dict, method: str, *, n: int, generations: int, population: int, seed: int, weight: float) -> dict:
    """Run the checked search :func:`search` describes; the best candidate with its status named."""
    import dataclasses

    from pfjax.numerics.random import seed_key
    from pfjax.parking.simulate import STATUS_NAMES
    from pfjax.parking.switch_search import SEARCH_CONFIG, garage_base, search_ga, search_grid

    base = garage_base(c["x0"], front=c["front"], scan_period=c["scan_period"], control=c["control"])
    cfg = dataclasses.replace(SEARCH_CONFIG, t_max=c["t_max"])
    if method == "ga":
        from pfjax.tuning.ga import GAOptions

        out = search_ga(
            c["omap"],
            key=seed_key(seed),
            base=base,
            weight=weight,
            cfg=cfg,
            options=GAOptions(population_size=population, generations=generations),
        )
        out["seed"] = seed
    else:
        out = search_grid(c["omap"], n=n, base=base, weight=weight, cfg=cfg, chunk=min(D.CHUNK, n**3))
        out.pop("table")
    out["status"] = STATUS_NAMES[int(out["status"])]
    out["converged"] = out["status"] == "converged"
    out["a_f"] = float(base.shape.front)
    return out
