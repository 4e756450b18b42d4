"""Tuning problems: controller + scenario set + cost -> one call to the GA or to gradient descent.

A :class:`Problem` bundles what both optimisers need; :func:`tune` runs either on it and returns
a :class:`~pfjax.tuning.gradient.TuneResult` (same fields for both, so they compare directly).

Scenario sets (``scenario`` argument):

* ``"paper-line"``, ``"paper-parabola"``, ``"paper-sine"``: the source's test (docs/reproductions/path-following.md §6, constant
  slip 5°, one rollout per cost evaluation);
* ``"paper-all"``: the three tests pooled (3 rollouts per evaluation);
* a study TOML path (``CONFIG``): ``n_runs`` runs per path sampled by
  :func:`pfjax.montecarlo.sampling.sample_runs` with the study's seed (a training set; held-out
  sets use other run indices), the study's simulation settings.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np

from pfjax import controllers as C
from pfjax import errors
from pfjax.models import DEFAULT_PARAMETER_SET, MODELS
from pfjax.sim.simulate import SimConfig
from pfjax.tuning.cost import CostSpec, Tunable, batch_cost, n_scenarios, population_cost
from pfjax.tuning.ga import GAOptions
from pfjax.tuning.gradient import TuneResult, ga_tune, gradient_tune
from pfjax.tuning.multistart import MultistartOptions, multistart_tune


def scenario_sets() -> dict[str, tuple[str, ...]]:
    """Named scenario sets (one run per path, from its start pose with the source's 5 deg slip):
    ``paper-<test>`` and ``paper-all`` for the source's tests, and every fixed path
    (:func:`pfjax.paths.fixed_paths`) by its own name."""
    from pfjax import paths

    tests = paths.source_tests()
    return {**{f"paper-{t}": (t,) for t in tests}, "paper-all": tests, **{n: (n,) for n in paths.fixed_paths()}}


class Problem(NamedTuple):
    controller: Any  # pfjax Controller
    tunable: Tunable
    scenarios: list  # batched Scenarios, one per path shape
    config: SimConfig
    cost: CostSpec
    lower: np.ndarray
    upper: np.ndarray

    @property
    def n_per_eval(self) -> int:
        return n_scenarios(self.scenarios)


def in_words_of(e: errors.InputError, changes: dict | None) -> errors.InputError:
    """:func:`make_problem`'s error named by what the caller changed (``changes``: its ``config``
    dict): a scenario set's window that a shorter ``horizon`` no longer holds, and a run of too many
    integrator steps when only the horizon was changed, name ``config.horizon``, not a key the
    caller did not give."""
    changes = changes or {}
    if "horizon" not in changes:
        return e
    if e.key in ("config.success_from", "config.steady_window"):
        return errors.InputError(
            f"config.horizon: {changes['horizon']:g} s is too short for the scenario set ({e})", "config.horizon"
        )
    if e.key == "config.dt" and "dt" not in changes and "horizon / dt" in str(e):
        return errors.renamed(e, "config.dt", "config.horizon")
    return e


def make_problem(
    controller: str,
    scenario: str,
    *,
    cost: CostSpec = CostSpec(),
    config: SimConfig | dict | None = None,
    n_runs: int = 16,
    run_offset: int = 0,
    base_gains=None,
    box=None,
    model: str | None = None,
) -> Problem:
    """Build a problem (``controller``: a :data:`pfjax.controllers.REGISTRY` name).

    Args:
        controller: registry name with a tuning box (``pi``, ``state_feedback``, ``integral``, ``stanley``, ...).
        scenario: a paper set name or a study TOML path (module docstring).
        cost: what is minimised.
        config: simulation settings (``record`` is forced off): a ``SimConfig``, or a dict of its
            fields that change the default ones (``{"dt": 0.01}``, as ``pfjax tune --dt``); default
            ``SimConfig()`` for paper sets, the study's for a TOML. On a study a horizon beyond the
            study's draws its OU slip sequences for the longer horizon. On ``st`` and ``std`` the
            step must be a stable RK4 step for the runs' worst case (highest friction, lowest speed;
            :func:`pfjax.models.single_track.max_stable_step`, as ``pfjax simulate`` and a study
            require); :class:`~pfjax.errors.InputError` naming ``config.dt`` otherwise.
        n_runs: runs per path sampled from a study TOML; ``run_offset``: first run index.
        base_gains: gains pytree for the untuned fields (default: the registry's defaults).
        box: ``(fields, lower, upper)`` overriding the registry entry's ``box``.
        model: the vehicle model, ``kinematic`` | ``st`` | ``std`` (:data:`pfjax.models.MODELS`; ``None``: the
            kinematic model for a paper set, the study's ``[vehicle] model`` for a TOML, which
            ``model`` replaces when given). On ``st`` and ``std`` a paper set's runs start from the
            same poses on the same paths with the parameter set of :data:`pfjax.models.DEFAULT_PARAMETER_SET` (the
            ``robot``; ``vehicle2`` for the drift model, CommonRoad's vehicles only) at 1 m/s, their
            slip coming from the tyre forces instead of the declared 5°.
    """
    import dataclasses

    ctrl, lo, hi, tun = _tunable(controller, base_gains, box)
    if not isinstance(cost, CostSpec):
        raise errors.InputError(f"cost: expected a pfjax.tuning.CostSpec, got {type(cost).__name__}", "cost")
    _check_inputs(scenario, n_runs, run_offset, model)
    if config is not None and not isinstance(config, (SimConfig, dict)):
        raise errors.InputError(f"config: expected a SimConfig or a dict, got {type(config).__name__}", "config")
    if scenario in scenario_sets():
        cfg = _settings(config, SimConfig(record=False))
        batches = _paper_batches(scenario, tun.base, model or "kinematic")
    else:
        batches, cfg = _study_batches(scenario, tun.base, n_runs, run_offset, model, config)
    cfg = dataclasses.replace(cfg, record=False)
    _check_step(batches, cfg)
    return Problem(ctrl, tun, batches, cfg, cost.check(), np.asarray(lo, float), np.asarray(hi, float))


def _settings(config, base: SimConfig) -> SimConfig:
    """``config`` (a SimConfig) or ``base`` with the fields of a dict ``config`` changed
    (:func:`pfjax.sim.settings.changed`: a bad field is named ``config.<field>``)."""
    from pfjax.sim.settings import changed

    if not isinstance(config, dict):
        return base if config is None else config
    return changed(base, config)


def _check_step(batches: list, cfg: SimConfig) -> None:
    """:class:`~pfjax.errors.InputError` naming ``config.dt`` if ``cfg.dt`` is beyond the stable RK4
    step (:func:`pfjax.models.single_track.max_stable_step`) of a dynamic batch's worst case: its
    highest friction and lowest speed, shortest steering time constant and stiffest speed loop
    (the kinematic model has no such bound)."""
    from pfjax.sim.dynamic import DynamicScenario, check_step

    for b in batches:
        if isinstance(b, DynamicScenario):
            check_step(b, cfg)


def _tunable(controller: str, base_gains, box):
    """(controller function, lower, upper, :class:`Tunable`) of a registered controller with a tuning box."""
    from pfjax import errors

    tunable = [n for n, e in C.REGISTRY.items() if e.box is not None]
    if controller not in tunable:
        raise errors.InputError(f"controller: value {controller!r}, expected one of {', '.join(tunable)}")
    ctrl, factory = C.REGISTRY[controller][:2]
    if box is not None:  # the caller's own box, checked as a registered one is
        box = C.check_box(box, factory, C.REGISTRY[controller].labels)
    box = box or C.REGISTRY[controller].box
    if box is None:
        raise errors.InputError(
            f"controller: {controller!r} has no tuning box; give box=(fields, lower, upper)", "controller"
        )
    fields, lo, hi = box
    base = factory() if base_gains is None else base_gains
    return ctrl, lo, hi, Tunable(base, tuple(fields))


def _check_inputs(scenario: str, n_runs: int, run_offset: int, model: str | None) -> None:
    from pfjax import errors

    sets = scenario_sets()
    if not isinstance(scenario, (str, os.PathLike)):
        raise errors.InputError(
            f"scenario: expected one of {', '.join(sets)} or the path of a study .toml, got {type(scenario).__name__}",
            "scenario",
        )
    if scenario not in sets and not (Path(scenario).suffix == ".toml" and Path(scenario).is_file()):
        raise errors.InputError(
            f"scenario: value {scenario!r}, expected one of {', '.join(sets)} or an existing study .toml"
        )
    if model is not None and model not in MODELS:
        raise errors.InputError(f"model: value {model!r}, expected one of {', '.join(MODELS)}", "model")
    check_runs(n_runs, run_offset)


#: The most runs per path a problem samples from a study TOML (:func:`make_problem`'s ``n_runs``).
MAX_RUNS = 1_000_000


def check_runs(n_runs: int, run_offset: int = 0) -> None:
    """:class:`~pfjax.errors.InputError` naming ``n_runs`` or ``run_offset`` unless ``n_runs`` runs
    per path from run index ``run_offset`` can be sampled from a study TOML (:func:`make_problem`)."""
    from pfjax import errors

    errors.integer("n_runs", n_runs, low=1, high=MAX_RUNS)
    errors.integer("run_offset", run_offset, low=0, high=errors.MAX_SEED - n_runs)


def _paper_batches(scenario: str, base, model: str) -> list:
    """One batch of one run per path of a paper set: the kinematic model at the source's 5° slip, or
    the dynamic model (:func:`pfjax.sim.scenario.make_dynamic_scenario`) from the same start."""
    from pfjax import paths
    from pfjax.sim.scenario import make_dynamic_scenario, paper_scenario
    from pfjax.sim.simulate import stack

    if model == "kinematic":
        return [stack([paper_scenario(t, base)]) for t in scenario_sets()[scenario]]
    out = []
    for t in scenario_sets()[scenario]:
        e = paths.entry(t)
        assert e.build is not None and e.start_pose is not None  # a paper set's paths are fixed paths
        out.append(
            stack(
                [make_dynamic_scenario(e.build(), e.start_pose, base, params=DEFAULT_PARAMETER_SET[model], model=model)]
            )
        )
    return out


def _study_batches(scenario: str, base, n_runs: int, run_offset: int, model: str | None, config=None):
    """(batches of ``n_runs`` sampled runs per path from ``run_offset``, the final SimConfig: the
    study's, or ``config`` as :func:`make_problem` reads it) of a study TOML; a horizon beyond the
    study's draws the runs' OU slip sequences for it.
    The runs of one evaluation are checked against the memory budget before any is drawn (the
    methods' own checks, :func:`check_memory`, follow once the problem is built)."""
    from pfjax import errors, resources
    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.runner import sim_config
    from pfjax.montecarlo.sampling import sample_runs

    try:
        spec, _ = load_study(Path(scenario), [] if model is None else [f'vehicle.model="{model}"'])
    except errors.InputError as e:
        raise errors.InputError(f"scenario: {e}", "scenario") from None
    cfg = _settings(config, sim_config(spec))
    n = n_runs * len(spec.paths)
    resources.check_memory(
        "n_runs",
        2 * n * resources.run_bytes(cfg.n_steps),
        f"one evaluation of {n_runs} runs x {len(spec.paths)} paths",
        "lower n_runs",
    )
    if cfg.horizon > spec.sim.horizon:  # slip sequences for the whole run (shorter runs: the study's, cut)
        if spec.slip.kind == "ou" and cfg.horizon / spec.slip.seq_dt > resources.MAX_STEPS:
            raise errors.InputError(
                f"config.horizon: horizon / slip.seq_dt (the study's OU slip samples per run) may be at most "
                f"{resources.MAX_STEPS:.0e}, got {cfg.horizon:g} / {spec.slip.seq_dt:g}",
                "config.horizon",
            )
        spec = spec.model_copy(update={"sim": spec.sim.model_copy(update={"horizon": cfg.horizon})})
    runs = np.arange(run_offset, run_offset + n_runs)
    batches = []
    for i in range(len(spec.paths)):
        sc = sample_runs(spec, i, runs).scenarios
        batches.append(
            sc._replace(gains=jax.tree_util.tree_map(lambda g: np.broadcast_to(g, (n_runs,) + np.shape(g)), base))
        )
    return batches, cfg


def evaluate(problem: Problem, theta) -> float:
    """The problem's cost at ``theta`` (one evaluation, ``n_per_eval`` rollouts)."""
    import jax.numpy as jnp

    cost_functions(problem)
    return float(_COSTS[id(problem)][3](jnp.asarray(theta, jnp.result_type(float))))


_COSTS: dict = {}


def cost_functions(problem: Problem):
    """(scalar cost, population cost) of a problem, built once per Problem object so repeated
    tuning runs (seeds) reuse the compiled functions."""
    entry = _COSTS.get(id(problem))
    if entry is None or entry[0] is not problem:
        args = (problem.controller, problem.tunable, problem.scenarios, problem.config, problem.cost)
        f = batch_cost(*args)
        entry = (problem, f, population_cost(*args), jax.jit(f))
        _COSTS[id(problem)] = entry
    return entry[1], entry[2]


#: Tuning methods of :func:`tune`.
METHODS = ("ga", "gradient", "gradient-plain", "ga+gradient")
#: The projected-adam methods' settings where :func:`tune` is given none (the multi-start tuner's
#: are :class:`~pfjax.tuning.MultistartOptions`' fields, the GA's :class:`~pfjax.tuning.ga.GAOptions`').
DESCENT_DEFAULTS: dict[str, dict[str, Any]] = {
    "gradient-plain": {"steps": 100, "n_starts": 1, "learning_rate": 0.05},
    "ga+gradient": {"steps": 30, "learning_rate": 0.01},
}
#: The methods that read each method-specific setting (by :func:`pfjax.tune`'s argument names;
#: ``pfjax tune``'s flags are these under their own names, :func:`pfjax.cli.tune.method_flags`;
#: ``key`` is ``--seed``). A check (``check=``) reads none of them.
METHOD_SETTINGS = {
    "generations": ("ga", "ga+gradient"),
    "population": ("ga", "ga+gradient"),
    "steps": ("gradient", "gradient-plain", "ga+gradient"),
    "n_starts": ("gradient", "gradient-plain"),
    "learning_rate": ("gradient", "gradient-plain", "ga+gradient"),
    "multistart": ("gradient",),
    "from_default": ("gradient-plain",),
    "key": METHODS,
}


def check_settings_apply(method: str | None, given, name=lambda setting: setting) -> None:
    """:class:`~pfjax.errors.InputError` naming the first setting of :data:`METHOD_SETTINGS` in
    ``given`` (the settings a caller gave) that ``method`` does not read (``None``: a check, which
    reads none); ``name(setting)`` is the caller's name for it (a flag)."""
    from pfjax import errors

    for setting, methods in METHOD_SETTINGS.items():
        if setting in given and method not in methods:
            mode = "a check" if method is None else f"method {method}"
            raise errors.InputError(
                f"{name(setting)}: not with {mode} (only with method {', '.join(methods)})", name(setting)
            )


def tune(
    problem: Problem,
    method: str,
    *,
    key,
    ga_options: GAOptions = GAOptions(),
    steps: int | None = None,
    n_starts: int | None = None,
    learning_rate: float | None = None,
    theta0=None,
    multistart: MultistartOptions | None = None,
    shared_programs: bool = True,
    progress: bool = False,
) -> TuneResult:
    """Run ``method`` on ``problem``.

    Methods:

    * ``"ga"``: MATLAB-style GA (:mod:`pfjax.tuning.ga`, ``ga_options``);
    * ``"gradient"``: the multi-start gradient tuner (:mod:`pfjax.tuning.multistart`: Sobol
      screening with the controller's default gains (the source's gains or LMI design) and
      ``theta0`` as candidates, successive halving, smoothing, restarts); ``steps``, ``n_starts``
      and ``learning_rate`` override the fields of ``multistart`` (its ``rounds`` at most the
      final ``steps``; unset, 3, or ``steps`` when ``steps`` is below 3);
    * ``"gradient-plain"``: projected adam from ``n_starts`` (default 1) starts, ``theta0`` or
      uniform in the box from ``key`` (:func:`pfjax.tuning.gradient.gradient_tune`; ``steps``
      default 100, ``learning_rate`` 0.05);
    * ``"ga+gradient"``: the GA, then ``steps`` (default 30) projected adam steps from its best
      at ``learning_rate`` (default 0.01): a gradient polish of the GA's answer.

    ``shared_programs``: when the padded rollouts are cheap, the multi-start tuner runs its
    halving rounds and restarts on the first round's compiled program and its polish on the
    screening's (:func:`~pfjax.tuning.multistart.multistart_tune`'s ``rollout_steps``), and the GA
    its generations' children on the population's program (:func:`~pfjax.tuning.gradient.ga_tune`'s):
    the quickest first answer; ``False``: one program per batch shape, for many runs on one
    problem (a study's seeds) that reuse the compiled programs. The results agree (to the bit in
    the tests; in general up to float rounding).

    Refused before any work (:class:`~pfjax.errors.InputError` naming the argument) for an unknown
    method or settings, or batches beyond the memory budget (:mod:`pfjax.resources`: the GA
    simulates a whole population at once, the gradient every start with one tangent per tuned
    gain)."""
    ms = check_tune(
        method,
        problem.n_per_eval,
        problem.lower.size,
        problem.config.n_steps,
        ga_options=ga_options,
        steps=steps,
        n_starts=n_starts,
        learning_rate=learning_rate,
        multistart=multistart,
    )
    f_scalar, f_pop = cost_functions(problem)
    box = (problem.lower, problem.upper)
    rollout_steps = problem.n_per_eval * problem.config.n_steps if shared_programs else None
    if method == "gradient":
        cand = [problem.tunable.flatten()] + ([] if theta0 is None else [np.asarray(theta0, np.float64)])
        return multistart_tune(
            f_scalar,
            *box,
            key=key,
            options=ms,
            candidates=np.stack(cand),
            n_per_eval=problem.n_per_eval,
            rollout_steps=rollout_steps,
            progress=progress,
        )
    if method == "gradient-plain":
        return gradient_tune(
            f_scalar,
            *box,
            theta0=theta0,
            key=key,
            steps=steps or DESCENT_DEFAULTS[method]["steps"],
            n_starts=n_starts or DESCENT_DEFAULTS[method]["n_starts"],
            n_per_eval=problem.n_per_eval,
            learning_rate=learning_rate or DESCENT_DEFAULTS[method]["learning_rate"],
            progress=progress,
        )
    r = ga_tune(
        f_pop,
        *box,
        key=key,
        options=ga_options,
        n_per_eval=problem.n_per_eval,
        rollout_steps=rollout_steps,
        progress=progress,
    )
    if method == "ga":
        return r
    p = gradient_tune(
        f_scalar,
        *box,
        theta0=r.theta,
        key=key,
        steps=steps or DESCENT_DEFAULTS["ga+gradient"]["steps"],
        n_per_eval=problem.n_per_eval,
        learning_rate=learning_rate or DESCENT_DEFAULTS["ga+gradient"]["learning_rate"],
        progress=progress,
    )
    return _chained(r, p)


def check_tune(
    method: str,
    n_per_eval: int,
    n_gains: int,
    n_steps: int,
    *,
    ga_options: GAOptions = GAOptions(),
    steps: int | None = None,
    n_starts: int | None = None,
    learning_rate: float | None = None,
    multistart: MultistartOptions | None = None,
) -> MultistartOptions:
    """Every check :func:`tune` makes before any work, on a problem of ``n_per_eval`` rollouts per
    evaluation of ``n_steps`` steps and ``n_gains`` tuned gains (which need not be built): the
    settings (:func:`check_options`) and the memory budget; returns the multi-start tuner's options
    as :func:`tune` runs them."""
    ms = check_options(method, ga_options, steps, n_starts, learning_rate, multistart)
    check_memory(method, n_per_eval, n_gains, n_steps, ga_options, ms, n_starts)
    return ms


def check_options(method, ga_options, steps, n_starts, learning_rate, multistart) -> MultistartOptions:
    """:func:`tune`'s settings checked (:class:`~pfjax.errors.InputError` naming the argument); the
    multi-start tuner's options with ``steps``, ``n_starts`` and ``learning_rate`` applied, checked
    once as a whole (:meth:`~pfjax.tuning.MultistartOptions.check`: ``rounds`` above the final
    ``steps`` is refused naming ``rounds``; unset, they fall to ``steps`` below 3)."""
    from pfjax import errors
    from pfjax.tuning.ga import validate_options

    if method not in METHODS:
        raise errors.InputError(f"method: value {method!r}, expected one of {', '.join(METHODS)}")
    validate_options(ga_options)  # every setting is checked, whichever method uses it
    for name, v in (("steps", steps), ("n_starts", n_starts)):
        if v is not None:
            errors.integer(name, v, low=1, high=1_000_000)
    if learning_rate is not None:
        errors.number("learning_rate", learning_rate, positive=True)
    if multistart is not None and not isinstance(multistart, MultistartOptions):
        raise errors.InputError(
            f"multistart: expected a pfjax.tuning.MultistartOptions, got {type(multistart).__name__}", "multistart"
        )
    ms = multistart or MultistartOptions()
    given: dict[str, Any] = {
        k: v for k, v in (("steps", steps), ("n_starts", n_starts), ("learning_rate", learning_rate)) if v is not None
    }
    ms = ms._replace(**given)
    if method == "gradient":
        ms = ms.check()
    return ms


def check_memory(
    method: str,
    n_per_eval: int,
    n_gains: int,
    n_steps: int,
    ga_options: GAOptions = GAOptions(),
    ms: MultistartOptions | None = None,
    n_starts=None,
) -> None:
    """Refuse batches beyond the memory budget (:mod:`pfjax.resources`) of ``method`` (or
    ``"check"``) on a problem of ``n_per_eval`` rollouts per evaluation of ``n_steps`` steps and
    ``n_gains`` tuned gains: the GA simulates a whole population at once, the gradient every start
    with one tangent per tuned gain, a ``check`` its Hessian's gradients at once and then its
    probes (value only)."""
    from pfjax import resources
    from pfjax.tuning.check import RADII, probe_directions
    from pfjax.tuning.ga import validate_options

    D = n_gains
    per_run = resources.run_bytes(n_steps)
    if method == "check":  # check_point: 2 D central differences of the gradient, then the probes
        resources.check_memory(
            "check",
            2 * 2 * D * n_per_eval * per_run * (1 + D),
            f"the Hessian's {2 * D} gradients x {n_per_eval} runs with {D} tangents",
        )
        n_probes = len(RADII) * len(probe_directions(D))
        resources.check_memory("check", 2 * n_probes * n_per_eval * per_run, f"{n_probes} probes x {n_per_eval} runs")
        return
    ms = ms or MultistartOptions()
    if method in ("ga", "ga+gradient"):
        population = validate_options(ga_options)[0]
        resources.check_memory(
            "population_size",
            2 * population * n_per_eval * per_run,
            f"a GA population of {population} x {n_per_eval} runs",
        )
    n_chains = {"gradient": max(ms.n_starts, ms.n_restarts + 1), "gradient-plain": n_starts or 1}.get(method, 1)
    # named by the setting that sets the number of chains descended at once: the restarts' at the end
    # (the incumbent and its perturbations) where they outnumber the starts
    restarts = method == "gradient" and ms.n_restarts + 1 > ms.n_starts
    resources.check_memory(
        "n_restarts" if restarts else "n_starts",
        2 * n_chains * n_per_eval * per_run * (1 + D),
        f"{n_chains} {'restart chains (the incumbent and its restarts)' if restarts else 'starts'} x {n_per_eval} "
        f"runs with {D} tangents",
    )
    if method == "gradient":
        resources.check_memory(
            "n_screen",
            2 * (ms.n_screen + 2) * n_per_eval * per_run,
            f"{ms.n_screen} screened points x {n_per_eval} runs",
        )


def _chained(r: TuneResult, p: TuneResult) -> TuneResult:
    """The GA's result ``r`` followed by the gradient polish ``p`` from its best: the better answer,
    the histories joined, the budgets added."""
    best = p if p.cost < r.cost else r
    return TuneResult(
        best.theta,
        best.cost,
        np.concatenate([r.history, np.minimum(p.history, r.cost)]),
        np.concatenate([r.history_rollouts, r.n_rollouts + p.history_rollouts]),
        np.concatenate([r.history_wall_s, r.wall_s + p.history_wall_s]),
        r.n_rollouts + p.n_rollouts,
        r.wall_s + p.wall_s,
        p.n_nonfinite_grad,
        r.n_forward_passes + p.n_forward_passes,
        r.compile_s + p.compile_s,
    )


def reported_gains(controller: str, problem: Problem, theta) -> dict[str, float]:
    """The gains a tuning or a check reports: every gain of ``controller`` (a registry name) by its
    scalar name (:func:`pfjax.controllers.flat_gains`: what ``--gains``, :func:`pfjax.simulate` and
    :func:`check` take), the tuned ones from ``theta`` in float64, the others the problem's."""
    with jax.enable_x64(True):
        g = problem.tunable.gains(np.asarray(theta, np.float64))
    return C.flat_gains(C.entry(controller), g)


def tuned_result(controller: str, problem: Problem, res) -> dict:
    """What a tuning reports, the same in :func:`pfjax.tune` and ``pfjax tune --json``: ``gains``
    (:func:`reported_gains`), ``on_bound`` (:func:`on_bound`), ``cost``, ``n_rollouts`` (every
    rollout evaluated, value-only or with a gradient; the padding of a shared program's batch not
    counted), ``n_forward_passes`` (a rollout with its gradient counted as ``1 + D`` forward passes
    in forward mode), ``wall_s`` (s, compilation excluded), ``compile_s`` (s), ``history`` (best
    cost so far per generation or step), ``history_rollouts`` and ``n_nonfinite_grad`` (gradient
    components replaced by 0), from the tuner's result ``res``."""
    return {
        "gains": reported_gains(controller, problem, res.theta),
        "on_bound": on_bound(controller, problem, res.theta),
        "cost": float(res.cost),
        "n_rollouts": int(res.n_rollouts),
        "n_forward_passes": int(res.n_forward_passes),
        "wall_s": float(res.wall_s),
        "compile_s": float(res.compile_s),
        "history": np.asarray(res.history, np.float64).tolist(),
        "history_rollouts": np.asarray(res.history_rollouts).tolist(),
        "n_nonfinite_grad": int(res.n_nonfinite_grad),
    }


def on_bound(controller: str, problem: Problem, theta) -> list[str]:
    """The tuned gains (scalar names, the box's order) that ``theta`` puts on a bound of the tuning
    box (``problem.lower`` / ``problem.upper``): where the box, not the cost, stopped the tuner, so
    a wider box may lower the cost further."""
    names = C.gain_names(C.entry(controller), problem.tunable.fields)
    th = np.ravel(np.asarray(theta, np.float64))
    return [n for n, x, lo, hi in zip(names, th, problem.lower, problem.upper, strict=True) if x <= lo or x >= hi]


def _tuned_fields(controller: str, problem: Problem, gains, key: str = "check"):
    """``gains`` given by scalar names (what :func:`reported_gains` reports; also as JSON text) as
    ``{tuned field: value}``: every tuned gain given, an untuned one left out or at the problem's
    value; :class:`~pfjax.errors.InputError` naming ``key`` otherwise. Anything else unchanged."""
    import json
    from collections.abc import Mapping

    from pfjax import errors

    g = gains
    if isinstance(g, str) and g.strip().startswith("{"):
        try:
            g = json.loads(g)
        except json.JSONDecodeError:
            return gains  # parse_gains names the error
    if not isinstance(g, Mapping) or set(g) <= set(problem.tunable.fields):
        return gains
    e = C.entry(controller)
    vectors = [k for k in g if k in e.labels]  # a vector field among scalar gains: two forms mixed
    if vectors:
        raise errors.InputError(
            f"{key}: mixes the field {vectors[0]} with gains by name ({', '.join(k for k in g if k not in vectors)}); "
            f"give the tuned fields ({', '.join(problem.tunable.fields)}) or every gain by name "
            f"({', '.join(C.gain_names(e, problem.tunable.fields))}, ...)",
            key,
        )
    params = C.params_from_flat(e, g, key)
    tuned = C.gain_names(e, problem.tunable.fields)
    missing = [n for n in tuned if n not in g]
    if missing:
        raise errors.InputError(f"{key}: {', '.join(missing)} missing; the tuned gains are {', '.join(tuned)}", key)
    base = C.flat_gains(e, problem.tunable.base)
    for n, v in C.flat_gains(e, params).items():
        if n in g and n not in tuned and v != base[n]:
            raise errors.InputError(
                f"{key}: {n} is not tuned here (the tuned gains are {', '.join(tuned)}); give it as {base[n]:g} "
                "or leave it out",
                key,
            )
    return {f: np.ravel(np.asarray(getattr(params, f), np.float64)).tolist() for f in problem.tunable.fields}


def check(problem: Problem, gains, *, h: float = 1e-4, rtol: float = 1e-4, controller: str | None = None):
    """First- and second-order check of ``gains`` on ``problem`` (:func:`pfjax.tuning.check.check_point`):
    ``gains`` as :func:`pfjax.tuning.check.parse_gains` reads them (a ``{field: value}`` mapping of
    the tuned fields, its JSON text or numbers in field order), inside the problem's box; with
    ``controller`` (its registry name) also every gain by its scalar name, as a tuning reports them
    (:func:`reported_gains`)."""
    from pfjax.tuning.check import check_point, parse_gains

    if controller is not None:
        gains = _tuned_fields(controller, problem, gains)
    th = parse_gains(gains, problem.tunable.fields, problem.tunable.sizes, problem.lower, problem.upper)
    # before anything is compiled or simulated
    check_memory("check", problem.n_per_eval, problem.lower.size, problem.config.n_steps)
    f_scalar, _ = cost_functions(problem)
    return check_point(
        f_scalar,
        th,
        problem.lower,
        problem.upper,
        h=h,
        rtol=rtol,
        n_per_eval=problem.n_per_eval,
        rollout_steps=problem.n_per_eval * problem.config.n_steps,
    )
