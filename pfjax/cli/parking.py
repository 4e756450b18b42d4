"""``pfjax parking`` (one run, with its switch log) and ``pfjax parking-search`` (GA or grid).

    pfjax parking --map {parallel,garage,FILE} --x0 X Y THETA_DEG --direction {forward,backward}
                  [--alpha-schedule 1,0.5,8,1] [--xs -1.2] [--json]
    pfjax parking-search --method {ga,grid} [--n 32] [--generations 100] [--population 20] [--seed 0] [--json]
"""

from __future__ import annotations

from pfjax.cli.common import UsageError, finite


def _usage(msg):
    return UsageError(msg)


def _common(p):
    p.add_argument("--k1", type=float, default=32.0, help="gain on y, 1/m^2 (default 32)")
    p.add_argument("--k2", type=float, default=8.0, help="gain on tan(theta), 1/m (default 8)")
    p.add_argument("--speed", type=float, default=0.05, help="|v1|, m/s (default 0.05)")
    p.add_argument("--scan-period", type=float, default=0.1, help="scanner sampling period, s (default 0.1)")
    p.add_argument("--front", type=float, help="a_f: reach of the rectangle ahead of the axle, m (default: calibrated)")
    p.add_argument("--lag", action="store_true", help="yaw-rate PI loop (kP 0.8, kI 16) on")
    p.add_argument("--t-max", type=float, default=200.0, help="timeout, s (default 200)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def register(sub) -> None:
    p = sub.add_parser("parking", help="simulate one parking run (time-state controller with direction/gain switching)",
                       description="One run of the switching parking controller (spec parking-time-state.md); "
                                   "prints the outcome, parking time and the log of direction switches.")
    p.add_argument("--map", default="parallel", help="parallel, garage, or a TOML/JSON map file (default parallel)")
    p.add_argument("--x0", type=float, nargs=3, metavar=("X", "Y", "THETA_DEG"),
                   help="start pose, m m deg (default: case A for parallel, (-0.9, 0.6, -85) for garage)")
    p.add_argument("--direction", choices=("forward", "backward"), default="forward", help="first travel direction")
    p.add_argument("--alpha-schedule", default="1", help="alpha at the start, then after each switch (default 1)")
    p.add_argument("--xs", type=float, help="garage rule: switch back to forward when backing past x = XS, m (garage default -0.9)")
    _common(p)
    p.set_defaults(func=_cmd_parking)

    s = sub.add_parser("parking-search", help="search (X_s, alpha1, alpha2) for the garage by the 24-bit GA or a grid",
                       description="Search of the garage switching parameters (spec §5): the source's 24-bit GA "
                                   "(n = 20, N = 100) or an exhaustive N x N x N grid on the chromosome lattice.")
    s.add_argument("--method", choices=("ga", "grid"), required=True)
    s.add_argument("--map", default="garage", help="garage (default) or a TOML/JSON map file")
    s.add_argument("--x0", type=float, nargs=3, metavar=("X", "Y", "THETA_DEG"), help="start pose (default -0.9 0.6 -85)")
    s.add_argument("--n", type=int, default=32, help="grid levels per parameter (default 32)")
    s.add_argument("--generations", type=int, default=100, help="GA generations N (default 100)")
    s.add_argument("--population", type=int, default=20, help="GA population n (default 20)")
    s.add_argument("--seed", type=int, default=0, help="PRNG seed of the GA (default 0)")
    s.add_argument("--weight", type=float, default=100.0, help="end-error weight w in J = 1/(t_e + w e) (default 100)")
    _common(s)
    s.set_defaults(func=_cmd_search)


def _checked(args, default_start):
    from pfjax.parking.maps import MapError, check_start, load_map, to_obstacle_map

    for flag, v in (("--k1", args.k1), ("--k2", args.k2), ("--speed", args.speed), ("--scan-period", args.scan_period),
                    ("--t-max", args.t_max)):
        finite(flag, v, positive=True)
    if args.front is not None:
        finite("--front", args.front, positive=True)
        if args.front >= 0.540:
            raise _usage(f"--front: must be < 0.54 (the rectangle length), got {args.front:g}")
    if args.scan_period > 10 or args.t_max / args.scan_period > 20000:
        raise _usage(f"--scan-period: value {args.scan_period:g}, expected t_max / scan_period <= 20000 and <= 10 s")
    try:
        name, polygons = load_map(args.map)
    except MapError as e:
        raise _usage(f"--map: {e}") from None
    if args.x0 is None:
        if default_start.get(args.map) is None:
            raise _usage(f"--x0: required (no default start for map {args.map!r})")
        x0 = default_start[args.map]
    else:
        x0 = tuple(finite("--x0", v) for v in args.x0)
        finite("--x0", x0[2], below=90.0, unit=" deg")
    from pfjax.parking.simulate import run_params

    shape = run_params(x0, front=args.front).shape  # the rectangle the run will simulate
    try:
        check_start(polygons, x0, shape)
    except MapError as e:
        raise _usage(str(e)) from None
    return name, polygons, to_obstacle_map(list(polygons.values())), x0


def _control(args):
    from pfjax.parking.model import control_params

    return control_params(k1=args.k1, k2=args.k2, speed=args.speed, lag=bool(args.lag))


def _cmd_parking(args) -> dict:
    from pfjax.parking.schedules import CASES, GARAGE_START, parse_schedule

    try:
        schedule = parse_schedule(args.alpha_schedule)
    except ValueError as e:
        raise _usage(f"--alpha-schedule: {e}") from None
    if args.xs is not None:
        finite("--xs", args.xs)
    name, _, omap, x0 = _checked(args, {"parallel": CASES["A"]["x0"], "garage": GARAGE_START})
    xs = args.xs if args.xs is not None else (-0.9 if args.map == "garage" else None)  # the garage always has its X_s rule

    from pfjax.parking.summary import run_summary
    from pfjax.parking.simulate import ParkingConfig, run_jit, run_params

    p = run_params(x0, 1 if args.direction == "forward" else -1, list(schedule), xs=xs, front=args.front,
                   scan_period=args.scan_period, control=_control(args))
    r = run_jit(p, omap, ParkingConfig(t_max=args.t_max))
    return {"map": name, "x0": {"x": x0[0], "y": x0[1], "theta_deg": x0[2]}, "direction": args.direction,
            "alpha_schedule": [float(a) for a in schedule], "xs": xs, "a_f": float(p.shape.front),
            **run_summary(r)}


def _cmd_search(args) -> dict:
    import dataclasses

    import jax

    from pfjax.parking.schedules import GARAGE_START
    from pfjax.parking.search import SEARCH_CONFIG, search_ga, search_grid

    finite("--weight", args.weight)
    if args.weight < 0:
        raise _usage(f"--weight: must be >= 0, got {args.weight:g}")
    if not 2 <= args.n <= 64:
        raise _usage(f"--n: value {args.n}, expected 2..64")
    if args.population < 2:
        raise _usage(f"--population: value {args.population}, expected >= 2")
    if args.generations < 1:
        raise _usage(f"--generations: value {args.generations}, expected >= 1")
    name, _, omap, x0 = _checked(args, {"garage": GARAGE_START, "parallel": None})
    from pfjax.parking.simulate import run_params

    base = run_params(x0, 1, (1.0,), xs=-1.0, front=args.front, scan_period=args.scan_period, control=_control(args))
    cfg = dataclasses.replace(SEARCH_CONFIG, t_max=args.t_max)
    if args.method == "ga":
        from pfjax.tuning.ga import GAOptions

        out = search_ga(omap, key=jax.random.PRNGKey(args.seed), base=base, weight=args.weight, cfg=cfg,
                        options=GAOptions(population_size=args.population, generations=args.generations))
        out["seed"] = args.seed
    else:
        out = search_grid(omap, n=args.n, base=base, weight=args.weight, cfg=cfg, chunk=min(1024, args.n**3))
        out.pop("table")
    from pfjax.parking.simulate import STATUS_NAMES

    out["status"] = STATUS_NAMES[int(out["status"])]
    out["converged"] = out["status"] == "converged"
    return {"map": name, "x0": {"x": x0[0], "y": x0[1], "theta_deg": x0[2]}, **out}

