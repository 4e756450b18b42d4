"""``pfjax tune``: tune a controller's gains by the GA or by gradient descent through the simulator.

    pfjax tune --method {ga,gradient} --controller {pi,state-feedback,integral,stanley,pure-pursuit,rear-wheel}
               --scenario {paper-line,paper-parabola,paper-sine,paper-all,CONFIG.toml}
               [--cost iae] [--aggregate mean] [--effort 0] [--seed 0] [--generations 100] [--population 50]
               [--steps 100] [--lr 0.05] [--n-runs 16] [--dt 0.005] [--horizon 20] [--json]

Prints ``gains``, ``cost``, ``n_rollouts_simulated``, ``wall_s``, ``history`` (best cost so far per
generation / step) and ``history_rollouts``; a progress bar on stderr when it is a terminal and
``--json`` is not given.
"""

from __future__ import annotations

import sys

from pfjax.cli.common import UsageError, as_flags


def _controllers() -> dict:
    """Command-line name -> registry name of every controller with a tuning box."""
    from pfjax import controllers as C

    return {e.cli_name: n for n, e in C.REGISTRY.items() if e.box is not None}


def register(sub) -> None:
    p = sub.add_parser(
        "tune",
        help="tune controller gains (GA or gradient through the simulator)",
        description="Tune a controller's gains on a scenario set by MATLAB-style GA or projected adam on "
        "jax.grad of the simulated cost; prints the gains, cost, rollouts and wall time.",
    )
    p.add_argument("--method", required=True, help="ga | gradient")
    p.add_argument("--controller", required=True, help="a controller with a tuning box: " + " | ".join(_controllers()))
    p.add_argument(
        "--scenario",
        default="paper-line",
        help="paper-line | paper-parabola | paper-sine | paper-all | "
        "a registered path's name (one run from its start pose) | a study TOML (CONFIG)",
    )
    p.add_argument("--cost", default="iae", help="iae | ise | itae (per run, plus --effort * int delta^2 dt)")
    p.add_argument("--aggregate", default="mean", help="mean | quantile | cvar over the scenario batch")
    p.add_argument("--level", type=float, default=0.9, help="quantile / CVaR level in (0, 1)")
    p.add_argument("--effort", type=float, default=0.0, help="control-effort weight (>= 0)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (GA population / gradient start)")
    p.add_argument("--generations", type=int, default=100, help="GA generations (source: 100)")
    p.add_argument("--population", type=int, default=50, help="GA population (source: 50)")
    p.add_argument("--steps", type=int, default=100, help="gradient steps")
    p.add_argument("--starts", type=int, default=1, help="gradient: starts descended together (vmapped)")
    p.add_argument("--lr", type=float, default=0.05, help="adam step in normalised box units")
    p.add_argument("--from-default", action="store_true", help="gradient: start from the controller's default gains")
    p.add_argument("--n-runs", type=int, default=16, help="runs per path sampled from a CONFIG study")
    p.add_argument("--dt", type=float, default=None, help="integrator step, s (default: 0.005 or the study's)")
    p.add_argument("--horizon", type=float, default=None, help="simulated time, s (default: 20 or the study's)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd)


#: ``pfjax tune``'s flags by the library argument they set.
FLAGS = {
    "method": "--method",
    "controller": "--controller",
    "scenario": "--scenario",
    "metric": "--cost",
    "aggregate": "--aggregate",
    "level": "--level",
    "effort": "--effort",
    "population_size": "--population",
    "generations": "--generations",
    "steps": "--steps",
    "n_starts": "--starts",
    "learning_rate": "--lr",
    "n_runs": "--n-runs",
    "dt": "--dt",
    "horizon": "--horizon",
}


def _cmd(args) -> dict:
    import dataclasses

    import jax

    from pfjax import __version__, errors
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import make_problem, tune

    controllers = _controllers()
    if args.controller not in controllers:
        raise UsageError(f"--controller: value {args.controller!r}, expected one of {', '.join(controllers)}")
    if args.method not in ("ga", "gradient"):
        raise UsageError(f"--method: value {args.method!r}, expected ga or gradient")
    key = jax.random.PRNGKey(errors.seed("--seed", args.seed))
    with as_flags(FLAGS):
        cost = CostSpec(metric=args.cost, effort=args.effort, aggregate=args.aggregate, level=args.level).check()
        problem = make_problem(controllers[args.controller], args.scenario, cost=cost, n_runs=args.n_runs)
        changes = {k: v for k, v in (("dt", args.dt), ("horizon", args.horizon)) if v is not None}
        if changes:
            problem = problem._replace(config=dataclasses.replace(problem.config, **changes))
        progress = (not args.json) and sys.stderr.isatty()
        theta0 = problem.tunable.flatten() if args.from_default else None
        options = GAOptions(population_size=args.population, generations=args.generations)
        r = tune(
            problem,
            args.method,
            key=key,
            ga_options=options,
            steps=args.steps,
            n_starts=args.starts,
            learning_rate=args.lr,
            theta0=theta0,
            progress=progress,
        )
    return {
        "method": args.method,
        "controller": args.controller,
        "scenario": args.scenario,
        "cost_spec": cost._asdict(),
        "gains": problem.tunable.named(r.theta),
        "cost": r.cost,
        "n_rollouts_simulated": r.n_rollouts,
        "rollouts_per_evaluation": problem.n_per_eval,
        "wall_s": r.wall_s,
        "history": r.history.tolist(),
        "history_rollouts": r.history_rollouts.tolist(),
        "bounds": {
            "lower": problem.lower.tolist(),
            "upper": problem.upper.tolist(),
            "fields": list(problem.tunable.fields),
        },
        "seed": args.seed,
        "dt": problem.config.dt,
        "horizon": problem.config.horizon,
        "n_nonfinite_grad": r.n_nonfinite_grad,
        "pfjax_version": __version__,
    }
