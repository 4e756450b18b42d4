"""``pfjax parking`` (one run, with its switch log) and ``pfjax parking-search`` (GA or grid).

    pfjax parking --map {parallel,garage,FILE} --x0 X Y THETA_DEG --direction {forward,backward}
                  [--alpha-schedule 1,0.5,8,1] [--xs -1.2] [--speed 0.05] [--horizon 200] [--json]
    pfjax parking-search --method {ga,grid} [--n 32] [--generations 100] [--population 20] [--seed 0]
                         [--horizon 200] [--json]

``--t-max`` is a deprecated spelling of ``--horizon`` (the timeout; read for one release).
"""

from __future__ import annotations

import contextlib
import os

from pfjax.cli.common import Aliased, UsageError, add_pose, as_flags
from pfjax.errors import InputError
from pfjax.parking import defaults as D
from pfjax.tables import PARKING_RUN_UNITS, PARKING_SEARCH_UNITS


def _common(p):
    p.add_argument("--k1", type=float, default=D.K1, help=f"gain on y, 1/m^2 (default {D.K1:g})")
    p.add_argument("--k2", type=float, default=D.K2, help=f"gain on tan(theta), 1/m (default {D.K2:g})")
    p.add_argument("--speed", type=float, default=D.SPEED, help=f"|v1|, m/s (default {D.SPEED:g})")
    p.add_argument(
        "--scan-period",
        type=float,
        default=D.SCAN_PERIOD,
        help=f"scanner sampling period, s (default {D.SCAN_PERIOD:g})",
    )
    p.add_argument("--front", type=float, help="a_f: reach of the rectangle ahead of the axle, m (default: calibrated)")
    p.add_argument("--lag", action="store_true", help=f"yaw-rate PI loop (kP {D.KP:g}, kI {D.KI:g} 1/s) on")
    p.add_argument(
        "--horizon",
        "--t-max",
        action=Aliased,
        dest="horizon",
        type=float,
        default=D.T_MAX,
        help=f"horizon: the run's timeout, s (default {D.T_MAX:g})",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object")


#: the garage's start pose as ``--x0`` spells it (x m, y m, theta deg)
_GARAGE_START = " ".join(f"{v:g}" for v in D.GARAGE_START)


def register(sub) -> None:
    p = sub.add_parser(
        "parking",
        help="simulate one parking run (time-state controller with direction/gain switching)",
        description="One run of the switching parking controller (docs/reproductions/parking.md); "
        "prints the outcome, parking time and the log of direction switches.",
    )
    p.add_argument("--map", default="parallel", help="parallel, garage, or a TOML/JSON map file (default parallel)")
    add_pose(p, f"start pose, m m deg (default: case A for parallel, {_GARAGE_START} for garage)")
    p.add_argument(
        "--direction",
        choices=("forward", "backward"),
        default="forward",
        help="first travel direction (default forward)",
    )
    p.add_argument("--alpha-schedule", default="1", help="alpha at the start, then after each switch (default 1)")
    p.add_argument(
        "--xs",
        type=float,
        help=f"garage rule: switch back to forward when backing past x = XS, m (garage default {D.GARAGE_XS:g})",
    )
    _common(p)
    p.set_defaults(func=_cmd_parking, units=PARKING_RUN_UNITS)

    s = sub.add_parser(
        "parking-search",
        help="search (X_s, alpha1, alpha2) for the garage by the 24-bit GA or a grid",
        description="Search of the garage switching parameters (docs/reproductions/parking.md §5): the source's 24-bit GA "
        f"(n = {D.POPULATION}, N = {D.GENERATIONS}) or an exhaustive N x N x N grid on the chromosome lattice.",
    )
    s.add_argument(
        "--method",
        choices=("ga", "grid"),
        required=True,
        help="ga: the source's 24-bit genetic algorithm; grid: every point of an N x N x N grid (--n) on the "
        "chromosome lattice (required; no default)",
    )
    s.add_argument("--map", default="garage", help="garage (default), parallel (with --x0), or a TOML/JSON map file")
    add_pose(s, f"start pose, m m deg (default {_GARAGE_START})")
    s.add_argument("--n", type=int, default=None, help=f"grid: levels per parameter (default {D.GRID_N})")
    s.add_argument("--generations", type=int, default=None, help=f"ga: generations N (default {D.GENERATIONS})")
    s.add_argument("--population", type=int, default=None, help=f"ga: population n (default {D.POPULATION})")
    s.add_argument("--seed", type=int, default=None, help="ga: PRNG seed (default 0)")
    s.add_argument(
        "--weight",
        type=float,
        default=D.WEIGHT,
        help=f"end-error weight w in J = 1/(t_e + w e), s/m (default {D.WEIGHT:g})",
    )
    _common(s)
    s.set_defaults(func=_cmd_search, units=PARKING_SEARCH_UNITS)


#: the flags both commands share, by the argument of :func:`pfjax.parking.run` they set (``map`` aside:
#: see :func:`_flags`)
COMMON_FLAGS = {
    "x0": "--x0",
    "k1": "--k1",
    "k2": "--k2",
    "speed": "--speed",
    "scan_period": "--scan-period",
    "front": "--front",
    "lag": "--lag",
    "t_max": "--horizon",
}
#: ``pfjax parking``'s flags by the argument of :func:`pfjax.parking.run` they set.
RUN_FLAGS = {"direction": "--direction", "alpha_schedule": "--alpha-schedule", "xs": "--xs", **COMMON_FLAGS}
#: ``pfjax parking-search``'s flags by the argument of :func:`pfjax.parking.switch_search` they set.
SEARCH_FLAGS = {
    "method": "--method",
    "n": "--n",
    "generations": "--generations",
    "population": "--population",
    "seed": "--seed",
    "weight": "--weight",
    "population/generations": "--population/--generations",
    **COMMON_FLAGS,
}


@contextlib.contextmanager
def _flags(flags: dict[str, str]):
    """:func:`~pfjax.cli.common.as_flags`, with the map's errors told as the map check tells them:
    a :class:`~pfjax.parking.maps.MapError` (a map file that cannot be read or is invalid, a start
    pose in an obstacle) becomes ``--map: <its message>`` or ``--x0: <its message>``, with the
    names in it (keys of the file, obstacles) left as they are, not read as arguments. ``map`` is
    not in the tables for the same reason: as_flags would rewrite the word in other messages
    (``--x0: required (no default start for map 'parallel')``)."""
    with as_flags(flags):
        try:
            yield
        except InputError as e:
            from pfjax.parking.maps import MapError

            if not isinstance(e, MapError) or e.key not in ("map", "x0"):
                raise
            text = str(e)
            if text.startswith(f"{e.key}: "):  # the load's own "map: <path>: ...", "x0: ..."
                text = text[len(e.key) + 2 :]
            flag = f"--{e.key}"
            raise UsageError(f"{flag}: {text}", flag) from None


def _common_args(args) -> dict:
    return {
        "map": args.map,
        "x0": args.x0,
        "k1": args.k1,
        "k2": args.k2,
        "speed": args.speed,
        "scan_period": args.scan_period,
        "front": args.front,
        "lag": bool(args.lag),
        "t_max": args.horizon,
    }


def _cmd_parking(args) -> dict:
    from pfjax.parking.api import run

    with _flags(RUN_FLAGS):
        out = run(direction=args.direction, alpha_schedule=args.alpha_schedule, xs=args.xs, **_common_args(args))
    args.alpha_schedule, args.xs = out["alpha_schedule"], out["xs"]
    return _ran(args, out)


def _ran(args, out: dict) -> dict:
    """``out``, with ``args`` set to what ran (pfjax.cli.records: the same run gives one config hash,
    defaults given or not): the start pose (m, m, deg), the rectangle's reach ``a_f`` (m) and the
    map's obstacles by their SHA-256 (a map file edited in place is another run), the file's
    path as given, normalised (``./m.toml`` is ``m.toml``)."""
    args.x0 = [out["x0"]["x"], out["x0"]["y"], out["x0"]["theta_deg"]]
    args.front = out["a_f"]
    args.map = os.path.normpath(args.map)
    args.map_sha256 = out["map_sha256"]
    return out


def _cmd_search(args) -> dict:
    from pfjax.parking.api import SEARCH_DEFAULTS, SEARCH_SETTINGS, search

    for key in SEARCH_SETTINGS[args.method]:  # the method's own defaults recorded as they run
        if getattr(args, key) is None:
            setattr(args, key, SEARCH_DEFAULTS[key])
    with _flags(SEARCH_FLAGS):
        out = search(
            args.method,
            n=args.n,
            generations=args.generations,
            population=args.population,
            seed=args.seed,
            weight=args.weight,
            **_common_args(args),
        )
    return _ran(args, out)
