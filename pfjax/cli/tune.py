"""``pfjax tune``: tune a controller's gains by the GA or by gradient descent through the simulator,
or check given gains.

    pfjax tune --method {gradient,gradient-plain,ga,ga+gradient} | --check GAINS
               --controller {pi,state-feedback,integral,stanley,pure-pursuit,rear-wheel}
               --scenario {paper-line,paper-parabola,paper-sine,paper-all,CONFIG.toml}
               [--model {kinematic,st,std}]
               [--cost iae] [--aggregate mean] [--effort 0] [--seed 0] [--generations 100] [--population 50]
               [--steps N] [--starts N] [--lr X] [--screen 64] [--sampler sobol] [--rounds 3] [--restarts 3]
               [--polish 8] [--smoothing 0] [--from-default] [--n-runs 16] [--dt 0.005] [--horizon 20] [--json]

A flag the chosen method (or ``--check``), scenario or aggregate does not read is refused
(:func:`method_flags`); ``--dt`` and ``--horizon`` change the default or the study's settings and
the result is checked by :func:`pfjax.tuning.problem.make_problem` (a stable step on ``st`` and ``std``).

Prints the ``method``, the seed and :func:`pfjax.tuning.problem.tuned_result`: ``gains``,
``on_bound``, ``cost``, ``n_rollouts``, ``n_forward_passes``, ``wall_s``, ``compile_s``,
``history``, ``history_rollouts`` and ``n_nonfinite_grad``, as :func:`pfjax.tune` returns them; with ``--check``: the gains' cost and :mod:`pfjax.tuning.check`'s report. A progress bar on stderr when it is a terminal and ``--json``
is not given.
"""

from __future__ import annotations

import sys

from pfjax.cli.common import UsageError, as_flags, controller_hint


def _controllers() -> dict:
    """Command-line name -> registry name of every controller with a tuning box."""
    from pfjax import controllers as C

    return {e.cli_name: n for n, e in C.REGISTRY.items() if e.box is not None}


def register(sub) -> None:
    p = sub.add_parser(
        "tune",
        help="tune controller gains (GA or gradient through the simulator), or check given gains",
        description="Tune a controller's gains on a scenario set by a multi-start gradient tuner through the "
        "simulator or MATLAB-style GA; prints the gains, cost, rollouts and wall time. With --check GAINS: "
        "the gradient and a second-order check of the given gains (is it a local minimum in the box?).",
    )
    p.add_argument(
        "--method",
        default=None,
        help="gradient (multi-start: screening, successive halving of BFGS chains, restarts, compass polish) | "
        "gradient-plain (projected adam from --starts uniform starts) | ga | ga+gradient (GA, then --steps "
        "adam steps from its best); required unless --check",
    )
    p.add_argument(
        "--check",
        default=None,
        metavar="GAINS",
        help="check these gains instead of tuning: numbers in the box's field order ('10,0,2,0') or a JSON "
        "object ('{\"kp_d\": 10, ...}'); prints the gradient, active bounds, Hessian eigenvalues and a verdict",
    )
    p.add_argument("--controller", required=True, help="a controller with a tuning box: " + " | ".join(_controllers()))
    p.add_argument(
        "--scenario",
        default="paper-line",
        help="paper-line | paper-parabola | paper-sine | paper-all | "
        "a registered path's name (one run from its start pose) | a study TOML (CONFIG) | a study packaged "
        "with pfjax, by its name (pfjax examples lists them: heldout, ...) (default paper-line)",
    )
    p.add_argument(
        "--model",
        default=None,
        help="vehicle model: kinematic (declared slip) | st (single-track, slip from linear tyre forces) | std "
        "(single-track drift, Pacejka tyres); a paper set runs st on the robot's parameters, std on CommonRoad's "
        "vehicle2; default: kinematic, or a CONFIG's [vehicle] model (which --model replaces)",
    )
    p.add_argument(
        "--cost", default="iae", help="iae | ise | itae, per run, plus --effort * int delta^2 dt (default iae)"
    )
    p.add_argument("--aggregate", default="mean", help="mean | quantile | cvar over the scenario batch (default mean)")
    p.add_argument("--level", type=float, default=None, help="quantile / CVaR level in (0, 1) (default 0.9)")
    p.add_argument("--effort", type=float, default=0.0, help="control-effort weight, >= 0 (default 0)")
    p.add_argument(
        "--seed", type=int, default=None, help="PRNG seed of the GA population / gradient starts (default 0)"
    )
    p.add_argument(
        "--generations", type=int, default=None, help="ga, ga+gradient: GA generations (default 100, the source's)"
    )
    p.add_argument(
        "--population", type=int, default=None, help="ga, ga+gradient: GA population (default 50, the source's)"
    )
    p.add_argument(
        "--steps",
        type=int,
        default=None,
        help="gradient: evaluations of a surviving chain (default 60); gradient-plain: steps (default 100); "
        "ga+gradient: polishing steps (default 30)",
    )
    p.add_argument(
        "--starts",
        type=int,
        default=None,
        help="gradient, gradient-plain: starts descended together (vmapped; default: gradient 8, gradient-plain 1)",
    )
    p.add_argument(
        "--lr",
        type=float,
        default=None,
        help="gradient: first BFGS trust radius (default 0.1); gradient-plain, ga+gradient: adam step (default 0.05, "
        "0.01); box units",
    )
    _multistart_flags(p)
    p.add_argument("--n-runs", type=int, default=None, help="runs per path sampled from a CONFIG study (default 16)")
    p.add_argument("--dt", type=float, default=None, help="integrator step, s (default: 0.005 or the study's)")
    p.add_argument("--horizon", type=float, default=None, help="simulated time, s (default: 20 or the study's)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd, units=UNITS)


def _multistart_flags(p) -> None:
    """The multi-start tuner's flags (``--method gradient``) and ``--from-default``."""
    p.add_argument("--screen", type=int, default=None, help="gradient: space-filling points screened (default 64)")
    p.add_argument("--sampler", default=None, help="gradient: sobol | lhs | uniform (default sobol)")
    p.add_argument(
        "--rounds",
        type=int,
        default=None,
        help="gradient: successive-halving rounds, at most --steps (default 3, or --steps when below 3; 1: none)",
    )
    p.add_argument(
        "--restarts", type=int, default=None, help="gradient: perturbed restarts of the incumbent (default 3)"
    )
    p.add_argument(
        "--polish",
        type=int,
        default=None,
        help="gradient: value-only compass iterations around the incumbent (default 8; 0: none)",
    )
    p.add_argument(
        "--smoothing",
        type=float,
        default=None,
        help="gradient: randomised-smoothing radius of the first round, box units in [0, 1] (default 0: off)",
    )
    p.add_argument(
        "--from-default",
        action="store_true",
        help="gradient-plain: start from the controller's default gains (gradient always screens them; the GA "
        "starts from a uniform population)",
    )


#: The multi-start tuner's own flags (by destination) and the :class:`~pfjax.tuning.MultistartOptions`
#: field each sets.
MULTISTART_FLAGS = {
    "screen": "n_screen",
    "sampler": "sampler",
    "rounds": "rounds",
    "restarts": "n_restarts",
    "polish": "polish_steps",
    "smoothing": "smoothing",
}
#: The flags the gradient methods read (by destination) and the :func:`pfjax.tuning.problem.tune`
#: argument each sets (the multi-start tuner's option field of the same name).
DESCENT_FLAGS = {"steps": "steps", "starts": "n_starts", "lr": "learning_rate"}


#: ``pfjax tune``'s flags by the library argument they set.
FLAGS = {
    "method": "--method",
    "controller": "--controller",
    "scenario": "--scenario",
    "model": "--model",
    "metric": "--cost",
    "aggregate": "--aggregate",
    "level": "--level",
    "effort": "--effort",
    "population_size": "--population",
    "generations": "--generations",
    **{name: f"--{dest}" for dest, name in {**DESCENT_FLAGS, **MULTISTART_FLAGS}.items()},
    "check": "--check",
    "n_runs": "--n-runs",
    "dt": "--dt",
    "horizon": "--horizon",
}


def _record_settings(args, ms) -> None:
    """The method's settings as they run, in ``args`` (:mod:`pfjax.cli.records`: the same run gives
    one config hash, defaults given or not): the multi-start tuner's from its checked options
    ``ms``, the projected-adam methods' from :data:`pfjax.tuning.problem.DESCENT_DEFAULTS`."""
    from pfjax.tuning.problem import DESCENT_DEFAULTS

    if args.method == "gradient":
        ran = {flag: getattr(ms, name) for flag, name in {**DESCENT_FLAGS, **MULTISTART_FLAGS}.items()}
    else:
        d = DESCENT_DEFAULTS.get(args.method, {})
        ran = {flag: d[name] for flag, name in DESCENT_FLAGS.items() if name in d}
    for dest, value in ran.items():
        if getattr(args, dest) is None:
            setattr(args, dest, value)


def _multistart(args):
    """The multi-start tuner's options set by the flags (the rest at their defaults), unchecked:
    :func:`pfjax.tuning.problem.check_options` checks them once ``--steps``, ``--starts`` and ``--lr``
    are applied."""
    from pfjax.tuning.multistart import MultistartOptions

    given = {name: getattr(args, flag) for flag, name in MULTISTART_FLAGS.items()}
    return MultistartOptions(**{k: v for k, v in given.items() if v is not None})


#: The cost's unit: its metric's, aggregated over the runs (pfjax.tuning.cost).
COST = "the metric's (iae m s, ise m^2 s, itae m s^2; effort: per rad^2 s of steering)"
#: The unit of each number ``_cmd`` returns (:func:`pfjax.cli.records.units`); the gains', the
#: bounds' and the check's coordinates' are the controller's, added as it runs (:func:`gain_units`).
UNITS = {
    "cost": COST,
    "history": COST,
    "cost_spec.fail_penalty": COST,
    "cost_spec.effort": "cost per rad^2 s",
    "cost_spec.level": "1",
    "check.projected_gradient_norm": "cost per box width",
    "check.hessian_eigenvalues": "cost per box width^2",
    "check.newton_decrease_relative": "1",
    "check.probe_decrease_relative": "1",
    "dt": "s",
    "horizon": "s",
    "wall_s": "s",
    "compile_s": "s",
    "arguments.*": {
        "level": "1",
        "seed": "1 (the random seed)",
        "effort": "cost per rad^2 s",
        "generations": "GA generations (count)",
        "population": "GA individuals (count)",
        "steps": "steps (count; --method gradient: evaluations of a surviving chain)",
        "starts": "starts (count)",
        "lr": "box widths",
        "screen": "points (count)",
        "rounds": "rounds (count)",
        "restarts": "restarts (count)",
        "polish": "iterations (count)",
        "smoothing": "box widths",
        "n_runs": "runs per path (count)",
        "dt": "s",
        "horizon": "s",
    },
}


def _cmd(args) -> dict:

    from pfjax import __version__, errors
    from pfjax.numerics.random import seed_key
    from pfjax.tuning.check import as_dict
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import check, check_options, in_words_of, make_problem, reported_gains, tune, tuned_result

    controllers = _controllers()
    _check_flags(args, controllers)
    for dest, value in DEFAULTS.items():  # the defaults of the flags this run reads (the rest stay None)
        if getattr(args, dest) is None and _reads(args, dest):
            setattr(args, dest, value)
    key = seed_key(errors.seed("--seed", args.seed)) if args.seed is not None else None
    with as_flags(FLAGS):
        cost = CostSpec(metric=args.cost, effort=args.effort, aggregate=args.aggregate, level=args.level).check()
        args.level = cost.level  # the quantile's or CVaR's level as it ran (one config hash, given or not)
        multistart = _multistart(args)
        ga = {"population_size": args.population, "generations": args.generations}
        options = GAOptions(**{k: v for k, v in ga.items() if v is not None})
        if args.method is not None:  # every tuning setting, once, with --steps, --starts and --lr applied
            ms = check_options(args.method, options, args.steps, args.starts, args.lr, multistart)
            _record_settings(args, ms)
        changes = {k: v for k, v in (("dt", args.dt), ("horizon", args.horizon)) if v is not None}
        try:  # the study's or the default settings with --dt and --horizon, checked as a whole
            problem = make_problem(
                controllers[args.controller],
                _scenario(args.scenario),
                cost=cost,
                config=changes or None,
                **({} if args.n_runs is None else {"n_runs": args.n_runs}),
                model=args.model,
            )
        except errors.InputError as e:  # named by the flags given (in_words_of), as the API names its arguments
            e = in_words_of(e, changes)
            named = e.key or ""
            setting = {"config.dt": "dt", "config.horizon": "horizon"}.get(named)
            if setting is None:
                raise e from None
            # SimConfig's messages that name the other setting too
            words = ("whole number of steps", "into whole steps", "horizon / dt", "must be <= horizon", "must be >= dt")
            if not any(w in str(e) for w in words):
                raise errors.renamed(e, named, f"--{setting}") from None
            # the step count's dt and horizon by their flags too, as pfjax simulate words them; too many
            # steps is the two flags' together (--horizon/--dt), as in pfjax simulate and pfjax track
            both = "horizon / dt" in str(e)
            with as_flags({"dt": "--dt", "horizon": "--horizon", "horizon/dt": "--horizon/--dt"}):
                raise errors.renamed(e, named, "horizon/dt" if both else setting) from None
        # as they ran (the scenario set's): one config hash, given or not
        args.dt, args.horizon, args.model = problem.config.dt, problem.config.horizon, _model_of(problem)
        # a study TOML's contents enter the record and its hash, not only its path
        args.scenario_sha256 = _file_sha256(_scenario(args.scenario))
        args.units = gain_units(args.units, controllers[args.controller], problem.tunable)
        common = {
            "controller": args.controller,
            "scenario": args.scenario,
            "model": _model_of(problem),
            "cost_spec": cost._asdict(),
            "bounds": {
                "lower": problem.lower.tolist(),
                "upper": problem.upper.tolist(),
                "fields": list(problem.tunable.fields),
            },
            "rollouts_per_evaluation": problem.n_per_eval,
            "dt": problem.config.dt,
            "horizon": problem.config.horizon,
            "pfjax_version": __version__,
        }
        if args.check is not None:
            c = check(problem, args.check, controller=controllers[args.controller])
            return {
                "gains": reported_gains(controllers[args.controller], problem, c.theta),
                "cost": c.cost,
                "check": as_dict(c, problem.tunable.fields, problem.tunable.sizes),
                **common,
            }
        progress = (not args.json) and sys.stderr.isatty()
        theta0 = problem.tunable.flatten() if args.from_default else None
        r = tune(
            problem,
            args.method,
            key=key,
            ga_options=options,
            steps=args.steps,
            n_starts=args.starts,
            learning_rate=args.lr,
            theta0=theta0,
            multistart=multistart,
            progress=progress,
        )
    return {
        "method": args.method,
        **tuned_result(controllers[args.controller], problem, r),
        "seed": args.seed,
        **common,
    }


def gain_units(table: dict, controller: str, tunable) -> dict:
    """``table`` with the units of the controller's gains (:func:`pfjax.controllers.gain_units`): the
    reported gains', the box's bounds (one per element, in ``bounds.fields`` order) and the check's
    coordinates (the gradient's, cost per gain unit, and the best probe's)."""
    from pfjax import controllers as C
    from pfjax.tuning.check import coordinate_names

    e = C.entry(controller)
    box = C.box_units(e, tunable.fields)
    coordinates = coordinate_names(tunable.fields, tunable.sizes)
    return {
        **table,
        "gains.*": C.gain_units(e),
        **dict.fromkeys(("bounds.lower", "bounds.upper"), ", ".join(box)),
        "check.gradient.*": {n: "cost" if u == "1" else f"cost per {u}" for n, u in zip(coordinates, box)},
        "check.best_probe.*": dict(zip(coordinates, box)),
    }


def _scenario(name: str) -> str:
    """``--scenario``: a study packaged with pfjax by its name (:mod:`pfjax.examples`) as the path of
    its TOML; any other value as given (a scenario set, a path's name, a TOML path)."""
    from pfjax import examples

    return str(examples.path(name)) if name in examples.FILES else name


def _file_sha256(scenario: str) -> str | None:
    """The SHA-256 of a scenario given as a study TOML (its bytes), or None for a named set or path."""
    import hashlib
    from pathlib import Path

    path = Path(scenario)
    if path.suffix != ".toml" or not path.is_file():
        return None
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _model_of(problem) -> str:
    """The vehicle model a problem's runs simulate: ``kinematic``, ``st`` or ``std``."""
    from pfjax.models.single_track import STDParams
    from pfjax.sim.dynamic import DynamicScenario

    sc = problem.scenarios[0]
    if not isinstance(sc, DynamicScenario):
        return "kinematic"
    return "std" if isinstance(sc.vehicle, STDParams) else "st"


#: The defaults of the flags that only some methods or scenarios read (``None`` in the parser, so
#: that a given one can be told apart; filled in only where the run reads them, so that the JSON's
#: ``arguments`` and its hash hold only what the run used).
DEFAULTS = {"seed": 0, "generations": 100, "population": 50, "n_runs": 16}


def _reads(args, dest: str) -> bool:
    """Whether this run reads flag ``dest``: a method flag if the method reads it
    (:func:`method_flags`; ``--check`` reads none), ``--n-runs`` if the scenario is a study TOML."""
    from pfjax.tuning.problem import scenario_sets

    flags = method_flags()
    if dest in flags:
        return args.method in flags[dest]
    return dest == "n_runs" and args.scenario not in scenario_sets()


def method_flags() -> dict[str, tuple[str, ...]]:
    """The methods that read each method-specific flag (by its destination; ``--check`` reads none):
    the library's :data:`pfjax.tuning.problem.METHOD_SETTINGS` under the flags' names, and the
    flags the command line alone has (``--seed``, the multi-start tuner's settings one by one)."""
    from pfjax.tuning.problem import METHOD_SETTINGS

    m = METHOD_SETTINGS
    return {
        "seed": m["key"],
        "generations": m["generations"],
        "population": m["population"],
        **{dest: m[name] for dest, name in DESCENT_FLAGS.items()},
        **dict.fromkeys(MULTISTART_FLAGS, m["multistart"]),
        "from_default": m["from_default"],
    }


def _check_flags(args, controllers: dict) -> None:
    """:class:`UsageError` naming the first bad flag among ``--controller``, ``--method``, ``--check``
    and ``--model``, or the first flag given that the chosen method (or ``--check``), scenario or
    aggregate does not read."""
    from pfjax.tuning.problem import METHODS, MODELS

    if args.controller not in controllers:
        raise UsageError(
            f"--controller: value {args.controller!r}, expected one of {', '.join(controllers)}"
            + controller_hint(args.controller, controllers)
        )
    if args.check is None and args.method is None:
        raise UsageError(f"--method: required unless --check is given; one of {', '.join(METHODS)}")
    if args.check is not None and args.method is not None:
        raise UsageError("--check: checks given gains; give --method or --check, not both")
    if args.method is not None and args.method not in METHODS:
        raise UsageError(f"--method: value {args.method!r}, expected one of {', '.join(METHODS)}")
    if args.model is not None and args.model not in MODELS:
        raise UsageError(f"--model: value {args.model!r}, expected one of {', '.join(MODELS)}")
    for dest, methods in method_flags().items():
        given = getattr(args, dest) is not None and getattr(args, dest) is not False  # 0 is given
        if given and not _reads(args, dest):
            mode = "--check" if args.method is None else f"--method {args.method}"
            raise UsageError(f"--{dest.replace('_', '-')}: not with {mode} (only with --method {', '.join(methods)})")
    if args.n_runs is not None and not _reads(args, "n_runs"):
        raise UsageError(f"--n-runs: not with --scenario {args.scenario} (it samples the runs of a study TOML)")
