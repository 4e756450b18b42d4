"""``pfjax simulate``: one closed-loop run of a paper scenario, its final state and metrics.

    pfjax simulate --path {line,parabola,sine,circle} --controller NAME [--gains G,...]
                   [--x0 X Y THETA_DEG] [--beta-r-deg 5] [--beta-f-deg 5] [--horizon 20] [--dt 0.005]
                   [--speed 1] [--wheelbase 0.2] [--delta-max-deg 30] [--json]
    pfjax simulate --model st [--vehicle robot|vehicle1|vehicle2|vehicle3] [--mu MU]
                   [--tau-delta 0.05] [--k-v 5] --path ... --controller NAME [...]

``--model st`` simulates CommonRoad's single-track model (:mod:`pfjax.sim.dynamic`; ``std`` its
drift model): the slip comes from the tyre forces, so the slip flags, ``--wheelbase``,
``--delta-max-deg``, ``--convention`` and ``--continuous`` are refused with it (the set's wheelbase
and steering limit), and the output adds the slip the run produced. Without ``--dt`` the step is
the largest stable one of 0.005, 0.002, 0.001, 0.0005, ... s
(:func:`pfjax.models.single_track.stable_step`).

``--T``, ``--v`` and ``--L`` are deprecated spellings of ``--horizon``, ``--speed`` and
``--wheelbase`` (read for one release). ``--x0``'s THETA is in degrees, as in ``pfjax parking``.
"""

from __future__ import annotations

import math

from pfjax.cli.common import Aliased, UsageError, add_pose, as_flags, controller_hint, finite
from pfjax.cli.synth import SYNTH_FLAGS
from pfjax.tables import COLUMNS


def _gain_names(controller: str) -> tuple[tuple[str, ...], list[str]]:
    """The gains ``--gains`` takes for a command-line controller name: by position, in order, and
    by name (every gain, :func:`pfjax.controllers.registry.gain_names`)."""
    from pfjax import controllers as C
    from pfjax.controllers.registry import gain_names

    e = C.resolve(controller, "--controller")[0]
    return e.gains, gain_names(e)


#: Modules that add subcommands: each has ``register(sub)`` which calls ``sub.add_parser(...)``
#: (the parser class is this module's ``_Parser``) and ``set_defaults(func=...)``; ``func(args)``
#: returns a dict (printed as JSON with ``--json``) and raises :class:`UsageError` for bad values.


def _parse_gains(controller: str, text: str | None) -> dict:
    """``--gains``: the controller's gains as comma-separated numbers in order, or any of its gains
    as ``name=value`` pairs (the others keep their defaults); values checked by the library."""
    names, every = _gain_names(controller)
    if text is None:
        return {}
    parts = [p.strip() for p in text.split(",")]
    if not any(parts):
        raise UsageError(f"--gains: empty; expected {','.join(names)} or name=value pairs")
    if "" in parts:
        raise UsageError(f"--gains: an empty item in {text!r}")
    named = ["=" in p for p in parts]
    if any(named) and not all(named):
        raise UsageError(f"--gains: mixes name=value pairs and bare numbers in {text!r}; use one form")
    if all(named):
        pairs = [tuple(s.strip() for s in p.split("=", 1)) for p in parts]
    else:
        if len(parts) != len(names):
            raise UsageError(
                f"--gains: expected all {len(names)} gains of --controller {controller} in order "
                f"({','.join(names)}), got {len(parts)}; give some as name=value pairs instead"
            )
        pairs = list(zip(names, parts))
    out = {}
    for k, v in pairs:
        if k not in every:
            raise UsageError(f"--gains: unknown gain {k!r} for --controller {controller}; expected {', '.join(every)}")
        if k in out:
            raise UsageError(f"--gains: {k} is given twice")
        try:
            out[k] = float(v)
        except ValueError:
            raise UsageError(f"--gains: {k}={v!r} is not a number") from None
    return out


def _controller_and_gains(args, wheelbase: float):
    """``(controller, parameter pytree, gains shown)``: the registry entry's defaults, a design's
    gains (:data:`pfjax.controllers.DESIGNS`, made at ``--speed`` and ``wheelbase``: ``--wheelbase``
    or the vehicle's) and ``--gains`` on top."""
    from pfjax import controllers as C

    e, d = C.resolve(args.controller, "--controller")
    given = _parse_gains(args.controller, args.gains)
    with as_flags({"gains": "--gains", "K": "--gains"}):
        flat = C.flat_gains(e)
        if d is not None and not set(e.gains) <= set(given):
            with as_flags(SYNTH_FLAGS):
                flat.update(C.design_gains(d, args.speed, wheelbase, "--controller"))
        flat.update(given)
        gains = C.params_from_flat(e, flat)
    shown = dict(flat)  # every gain by name, as pfjax tune reports them
    # recorded as they ran (pfjax.cli.records): "-4,-1.5", "k_d=-4,k_theta=-1.5" and the defaults
    # (or the design's gains) given or not, alike
    args.gains = shown
    # each gain's unit, by the controller's registration (the same name has other units elsewhere)
    args.units = {**args.units, "gains.*": C.gain_units(e), "arguments.gains.*": C.gain_units(e)}
    return e.controller, gains, shown


#: The kinematic flags' defaults (``None`` in the parser, so that a given one can be told apart).
KINEMATIC_DEFAULTS = {
    "beta_r_deg": 5.0,
    "beta_f_deg": 5.0,
    "wheelbase": 0.2,
    "delta_max_deg": 30.0,
    "convention": "source",
}


def _check_model_flags(args) -> None:
    """:class:`UsageError` naming the first flag given that the chosen ``--model`` does not take
    (:data:`pfjax.montecarlo.config.MODEL_SETTINGS`, the table the study config and
    :func:`pfjax.scenarios` refuse from); the kinematic model's flags' defaults filled in (for the
    kinematic model only, so that the recorded arguments run again)."""
    from pfjax.montecarlo.scenario_config import other_models_settings

    for setting in other_models_settings(args.model):
        if setting.flag is None:
            continue
        value = getattr(args, setting.flag[2:].replace("-", "_"))
        if value is not None and value is not False:  # by identity: a given 0 is given
            raise UsageError(f"{setting.flag}: not with --model {args.model} ({setting.refusal(args.model)})")
    if args.model == "kinematic":  # the ST flags stay None (recorded as not given: pfjax.cli.records)
        for dest, value in KINEMATIC_DEFAULTS.items():
            if getattr(args, dest) is None:
                setattr(args, dest, value)


SIMULATE_FLAGS = {
    "v": "--speed",
    "L": "--wheelbase",
    "beta_r_deg": "--beta-r-deg",
    "beta_f_deg": "--beta-f-deg",
    "delta_max_deg": "--delta-max-deg",
    "pose0": "--x0",
    "horizon": "--horizon",
    "dt": "--dt",
    "horizon/dt": "--horizon/--dt",
    "control_every": "--control-every",
    "convention": "--convention",
    "gains": "--gains",
    "params": "--vehicle",
    "mu": "--mu",
    "tau_delta": "--tau-delta",
    "k_v": "--k-v",
}


#: The unit of each number ``cmd`` returns (:func:`pfjax.cli.records.units`); the gains' are the
#: controller's (:func:`pfjax.controllers.gain_units`), added as it runs.
UNITS = {
    "x0.x": "m",
    "x0.y": "m",
    "x0.theta_deg": "deg",
    "beta_r": "rad",
    "beta_f": "rad",
    "mu": "1",
    "T": "s",
    "dt": "s",
    "final.*": {"x": "m", "y": "m", "theta": "rad", "d": "m", "theta_e": "rad", "delta": "rad", "s": "m"},
    "metrics.*": {name: unit for name, (unit, _) in COLUMNS.items()},
    "slip.*": {name: unit for name, (unit, _) in COLUMNS.items()},
    "fail_time": "s",
    "arguments.*": {
        "x0": "m, m, deg",
        "beta_r_deg": "deg",
        "beta_f_deg": "deg",
        "horizon": "s",
        "dt": "s",
        "control_every": "steps (of dt)",
        "speed": "m/s",
        "wheelbase": "m",
        "delta_max_deg": "deg",
        "mu": "1",
        "tau_delta": "s",
        "k_v": "1/s",
    },
}


def cmd(args) -> dict:
    import jax
    import numpy as np

    from pfjax.metrics import METRIC_NAMES
    from pfjax.models import DYNAMIC_MODELS
    from pfjax.sim import STATUS_NAMES, SimConfig
    from pfjax.sim.scenario import paper_scenario
    from pfjax.sim.simulate import simulate_one

    _check_model_flags(args)
    if args.continuous and args.control_every is not None:
        raise UsageError(
            "--control-every: not with --continuous (a continuous controller is evaluated inside every "
            "RK4 stage, not sampled)"
        )
    pose0 = None
    if args.x0 is not None:  # THETA in degrees, checked as given; the library takes radians
        x, y, theta_deg = (finite(f"--x0[{i}]", v, unit=" deg" if i == 2 else "") for i, v in enumerate(args.x0))
        pose0 = (x, y, math.radians(theta_deg))
    with as_flags(SIMULATE_FLAGS):
        if args.model in DYNAMIC_MODELS:
            return _simulate_st(args, pose0)
        cfg = _config(args, SimConfig().dt if args.dt is None else args.dt)  # the kinematic model's default
        controller, gains, shown = _controller_and_gains(args, args.wheelbase)
        sc = paper_scenario(
            args.path,
            gains,
            beta_r_deg=args.beta_r_deg,
            beta_f_deg=args.beta_f_deg,
            pose0=pose0,
            v=args.speed,
            L=args.wheelbase,
            delta_max_deg=args.delta_max_deg,
            convention=args.convention,
        )
    r = jax.device_get(simulate_one(sc, controller=controller, config=cfg))
    status = int(r.status)
    metrics: dict[str, bool | float | str] = {
        k: (bool if k == "success" else float)(getattr(r.metrics, k)) for k in METRIC_NAMES
    }
    metrics["status"] = STATUS_NAMES[status]
    x0 = _start(args)
    return {
        "path": args.path,
        "controller": args.controller,
        "gains": shown,
        "x0": {"x": x0[0], "y": x0[1], "theta_deg": x0[2]},
        "beta_r": math.radians(args.beta_r_deg),
        "beta_f": math.radians(args.beta_f_deg),
        "T": cfg.n_steps * cfg.dt,
        "dt": cfg.dt,
        "final": {k: float(v) for k, v in r.final._asdict().items()},
        "metrics": metrics,
        "status_code": status,
        "fail_time": float(r.fail_time) if np.isfinite(r.fail_time) else None,
    }


def _start(args) -> list[float]:
    """The start pose that ran (x m, y m, θ deg): ``--x0``, else the path's own start, recorded
    in ``args`` as ``--x0`` (:mod:`pfjax.cli.records`: the same run gives one config hash, the
    default start given or not)."""
    from pfjax import paths

    if args.x0 is None:
        start = paths.entry(args.path).start_pose
        assert start is not None  # --path takes fixed paths, which have a start pose
        args.x0 = [float(start[0]), float(start[1]), math.degrees(start[2])]
    return [float(v) for v in args.x0]


def _config(args, dt: float):
    """The run's :class:`~pfjax.sim.SimConfig`: ``--horizon``, the step ``dt`` and the control
    flags (``--control-every`` 1 unless ``--continuous``), ``dt`` and ``--control-every`` recorded
    as they ran (:mod:`pfjax.cli.records`: the same run gives one config hash, flags given or not)."""
    from pfjax.errors import InputError, renamed
    from pfjax.sim import SimConfig

    args.dt = dt
    if not args.continuous and args.control_every is None:
        args.control_every = 1
    try:
        return SimConfig(
            dt=dt,
            horizon=args.horizon,
            record=False,
            control_every=None if args.continuous else args.control_every,
        )
    except InputError as e:  # too many steps: --horizon and --dt together (as pfjax track names them)
        raise renamed(e, "dt", "horizon/dt") if "horizon / dt" in str(e) else e from None


def _simulate_st(args, pose0) -> dict:
    """One run of the ST or STD model (``--model st``, ``std``): the output of the kinematic model's run plus the
    model, its parameter set and the slip the run produced (``slip``, degrees). Without ``--dt`` the
    step is :func:`pfjax.models.single_track.stable_step` for the vehicle at ``--speed``."""
    import jax
    import numpy as np

    from pfjax import paths
    from pfjax.metrics import METRIC_NAMES
    from pfjax.models import DEFAULT_PARAMETER_SET
    from pfjax.models import single_track as st
    from pfjax.sim import STATUS_NAMES
    from pfjax.sim import dynamic as dyn
    from pfjax.sim.scenario import make_dynamic_scenario

    name = args.vehicle or DEFAULT_PARAMETER_SET[args.model]
    if args.model == "std" and name not in st.COMMONROAD_DRIFT_VEHICLES:
        raise UsageError(f"--vehicle: --model std takes {', '.join(st.COMMONROAD_DRIFT_VEHICLES)}, got {name}")
    vehicle = st.parameter_set(name)
    controller, gains, shown = _controller_and_gains(args, float(vehicle.l_f + vehicle.l_r))  # the set's wheelbase
    e = paths.entry(args.path)
    assert e.build is not None and e.start_pose is not None  # --path takes fixed paths
    sc = make_dynamic_scenario(
        e.build(),
        e.start_pose if pose0 is None else pose0,
        gains,
        params=name,
        mu=args.mu,
        v=args.speed,
        tau_delta=0.05 if args.tau_delta is None else args.tau_delta,
        k_v=5.0 if args.k_v is None else args.k_v,
        model=args.model,
    )
    mu = float(st.body(sc.vehicle).mu)
    step = (float(sc.tau_delta), float(sc.k_v))
    args.vehicle, args.mu, args.tau_delta, args.k_v = name, mu, *step  # as they ran: one hash, given or not
    st.check_speed("--speed", args.speed, sc.vehicle)
    cfg = _config(args, st.stable_step(sc.vehicle, args.speed, *step) if args.dt is None else args.dt)
    st.check_step("--dt", cfg.dt, sc.vehicle, args.speed, *step)
    r = jax.device_get(dyn.simulate_one(sc, controller=controller, config=cfg))
    status = int(r.status)
    metrics: dict[str, bool | float | str] = {
        k: (bool if k == "success" else float)(getattr(r.metrics, k)) for k in METRIC_NAMES
    }
    metrics["status"] = STATUS_NAMES[status]
    x0 = _start(args)
    return {
        "model": args.model,
        "vehicle": name,
        "mu": mu,
        "path": args.path,
        "controller": args.controller,
        "gains": shown,
        "x0": {"x": x0[0], "y": x0[1], "theta_deg": x0[2]},
        "T": cfg.n_steps * cfg.dt,
        "dt": cfg.dt,
        "final": {k: float(v) for k, v in r.final._asdict().items()},
        "metrics": metrics,
        "slip": {k: float(v) for k, v in r.slip._asdict().items()},
        "status_code": status,
        "fail_time": float(r.fail_time) if np.isfinite(r.fail_time) else None,
    }


def register(sub) -> None:
    m = sub.add_parser(
        "simulate",
        help="simulate one run of a paper scenario and print final state and metrics",
        description="One closed-loop run of a vehicle model on a path: the kinematic model with declared slip, "
        "or CommonRoad's single-track models with tyre slip (--model); SI units, the flags take angles in degrees, "
        "and --json gives the unit of every number it prints.",
    )
    from pfjax import paths

    m.add_argument(
        "--path",
        choices=paths.fixed_paths(),
        required=True,
        help="a registered path: the source's line, parabola, sine; pfjax's circle (radius 2 m)",
    )
    add_pose(m, "initial pose (m, m, deg); default: the source's")
    m.add_argument("--beta-r-deg", type=float, help="rear slip angle, deg (default 5; kinematic model)")
    m.add_argument("--beta-f-deg", type=float, help="front slip angle, deg (default 5; kinematic model)")
    from pfjax import controllers as C

    designs = "; ".join(f"{d.cli_name}: {d.style['label']}" for d in C.DESIGNS.values())
    registered = ", ".join(e.cli_name for e in C.REGISTRY.values())
    m.add_argument(
        "--controller",
        choices=C.cli_names(),
        required=True,
        help=f"a design ({designs}; the LMI designs are made at --speed and --wheelbase) or a registered "
        f"controller with its default gains ({registered})",
    ).hint = controller_hint
    m.add_argument(
        "--gains",
        help="comma-separated gains in order (or name=value pairs, any of the controller's gains, e.g. "
        "feedforward): " + "; ".join(f"{c}: {','.join(_gain_names(c)[0])}" for c in C.cli_names()),
    )
    m.add_argument(
        "--horizon", "--T", action=Aliased, dest="horizon", type=float, default=20.0, help="horizon, s (default 20)"
    )
    m.add_argument(
        "--dt",
        type=float,
        help="RK4 step, s (default 0.005; st and std: the largest of 0.005, 0.002, 0.001, 0.0005, ... s that "
        "is stable for the vehicle's tyre modes at --speed, e.g. 0.0002 for std at 1 m/s; a --dt given is checked)",
    )
    m.add_argument("--control-every", type=int, help="controller sampling period in steps (default 1)")
    m.add_argument("--continuous", action="store_true", help="evaluate the controller inside every RK4 stage")
    m.add_argument(
        "--speed", "--v", action=Aliased, dest="speed", type=float, default=1.0, help="speed, m/s (default 1)"
    )
    m.add_argument(
        "--wheelbase",
        "--L",
        action=Aliased,
        dest="wheelbase",
        type=float,
        help="wheelbase, m (default 0.2; kinematic model)",
    )
    m.add_argument("--delta-max-deg", type=float, help="steering limit, deg (default 30; kinematic model)")
    m.add_argument(
        "--convention",
        choices=("source", "lenain"),
        help="front-slip sign convention (default source; kinematic model)",
    )
    from pfjax.models import DEFAULT_PARAMETER_SET, MODELS, PARAMETER_SETS

    m.add_argument(
        "--model",
        choices=MODELS,
        default="kinematic",
        help="vehicle model: kinematic (declared slip), st (CommonRoad's single-track model, slip from linear "
        "tyre forces) or std (its single-track drift model, Pacejka tyres and wheel speeds) (default kinematic)",
    )
    m.add_argument(
        "--vehicle",
        choices=PARAMETER_SETS,
        help="st, std: parameter set (default "
        + ", ".join(f"{name} for {model}" for model, name in DEFAULT_PARAMETER_SET.items())
        + ")",
    )
    m.add_argument("--mu", type=float, help="st, std: friction coefficient (default the set's)")
    m.add_argument("--tau-delta", type=float, help="st, std: steering actuator time constant, s (default 0.05)")
    m.add_argument("--k-v", type=float, help="st, std: speed loop gain, 1/s (default 5)")
    m.add_argument("--json", action="store_true", help="print one JSON object")
    m.set_defaults(func=cmd, units=UNITS)
