"""Gain tuning and worst-case search through the public API."""

from __future__ import annotations

import contextlib
import math

import numpy as np

from pfjax import errors
from pfjax.api.runs import prng_key
from pfjax.api.simulation import resolve_gains, sim_config
from pfjax.errors import arguments_checked
from pfjax.montecarlo.analysis_config import FalsifierSpec

#: A study's ``[falsifier]`` defaults, which :func:`falsify` takes too.
_SEARCH = FalsifierSpec()


@arguments_checked
def tune(
    controller: str = "pi",
    scenario: str = "paper-line",
    method: str | None = None,
    *,
    key=None,
    cost=None,
    config=None,
    n_runs: int | None = None,
    steps: int | None = None,
    n_starts: int | None = None,
    learning_rate: float | None = None,
    generations: int | None = None,
    population: int | None = None,
    multistart=None,
    check=None,
    progress: bool = False,
    model: str | None = None,
    from_default: bool = False,
) -> dict:
    """Tune a controller's gains, or check given gains, as ``pfjax tune`` does.

    Computed in the precision JAX is configured for (float32 unless ``jax_enable_x64``); the
    command line enables float64, and a caller that does the same gets its numbers.

    Args:
        controller: a registered controller with a tuning box (``pi``, ``state_feedback``, ...; the
            command line's spellings too); a design (``lmi``) is refused, as by ``pfjax tune``.
        scenario: ``paper-line`` | ``paper-parabola`` | ``paper-sine`` | ``paper-all`` | a
            registered path's name | a study TOML (``n_runs`` sampled runs per path).
        n_runs: runs per path sampled from a study TOML (``None``: 16); not with a paper set or
            a registered path (one run per path), as ``pfjax tune`` refuses ``--n-runs``.
        method: ``gradient`` (the multi-start tuner: Sobol screening with the controller's
            default gains, successive halving of projected BFGS chains, restarts;
            :mod:`pfjax.tuning.multistart`), ``gradient-plain`` (projected adam from ``n_starts``
            uniform starts), ``ga`` (MATLAB-style GA) or ``ga+gradient`` (the GA, then ``steps``
            adam steps from its best); ``None`` (default): ``gradient``, or a check when ``check`` is
            given (a method and ``check`` together are refused, as ``pfjax tune`` refuses
            ``--method`` with ``--check``).
        key: int seed (or JAX key) of the GA population / the gradient's starts (``None``: 0);
            not with ``check`` (a check draws nothing), as ``pfjax tune`` refuses ``--seed``.
        cost: a :class:`pfjax.tuning.CostSpec` (metric, effort weight, aggregate); default mean IAE.
        config: a :class:`pfjax.sim.SimConfig`, or a dict of its fields that change the default
            settings (20 s at 5 ms) or the study's; on ``st`` and ``std`` its ``dt`` must be a stable RK4 step for the runs
            (:func:`pfjax.tuning.problem.make_problem`; errors name ``config.dt``).
        model: the vehicle model, ``kinematic`` | ``st`` | ``std`` (default: kinematic, or the
            study's ``[vehicle] model``, which ``model`` replaces); a paper set on ``st`` uses the
            robot's parameters, on ``std`` CommonRoad's vehicle2 (:func:`pfjax.tuning.problem.make_problem`).
        steps: gradient steps (``None``: the method's default; multi-start: evaluations of a
            surviving chain, at least ``multistart``'s rounds: rounds above it are refused naming
            ``multistart.rounds``; unset rounds are 3, or ``steps`` below 3).
        n_starts: starts descended together (``None``: the method's default).
        learning_rate: multi-start: first BFGS trust radius; adam: step (box units; ``None``: default).
        multistart: a :class:`pfjax.tuning.MultistartOptions` for ``gradient`` (a bad field is
            named ``multistart.<field>``; ``steps``, ``n_starts`` and ``learning_rate`` replace its own).
        generations: ``ga`` and ``ga+gradient``: the GA's generations (``None``: the source's 100,
            :class:`pfjax.tuning.GAOptions`).
        population: ``ga`` and ``ga+gradient``: the GA's population (``None``: the source's 50).
        check: gains to check instead of tuning (``{field: value}``, its JSON text or numbers in
            field order, inside the tuning box): gradient, projected gradient, active bounds,
            Hessian eigenvalues on the free coordinates, verdict (:mod:`pfjax.tuning.check`).
        progress: True: a progress bar on stderr over the tuner's steps or generations.
        from_default: ``gradient-plain``: the first start is the controller's default gains (the
            others uniform), as ``pfjax tune --from-default``.

    A setting the method does not read (``generations`` with ``gradient``, ``steps`` with ``ga``,
    any of them with ``check``; :data:`pfjax.tuning.problem.METHOD_SETTINGS`) is refused naming it,
    as ``pfjax tune`` refuses its flag.

    Returns:
        :func:`pfjax.tuning.problem.tuned_result`'s ``{"gains", "on_bound", "cost", "n_rollouts",
        "n_forward_passes", "wall_s", "compile_s", "history", "history_rollouts",
        "n_nonfinite_grad"}`` (``on_bound``: the tuned gains that ended on a bound of the tuning
        box; ``history`` and ``history_rollouts`` as NumPy arrays) and ``"result"``, the tuner's
        result; with ``check``: ``{"gains", "cost", "check", "result"}``.

    Raises:
        pfjax.errors.InputError: a bad argument, named as here, before any run is simulated
            (``controller``, ``scenario``, ``method``, ``key``, ``model``, a setting the method does
            not read, ``check`` with ``method``, ``key`` with ``check``, ``n_runs`` with a paper set,
            ``config.<field>`` for a bad field of ``config``, ``multistart.<field>``; ``progress``:
            not True or False).
    """
    from pfjax import controllers as C
    from pfjax.tuning.check import as_dict
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import (
        METHODS,
        check_options,
        check_settings_apply,
        in_words_of,
        make_problem,
        reported_gains,
        scenario_sets,
        tuned_result,
    )
    from pfjax.tuning.problem import check as run_check
    from pfjax.tuning.problem import tune as run_tune

    progress = errors.boolean("progress", progress)
    from_default = errors.boolean("from_default", from_default)
    # a command-line spelling names its registry entry; anything else (a design such as lmi: its
    # gains are designed, not tuned) is refused by make_problem, as `pfjax tune --controller` refuses it
    if not isinstance(controller, str):
        raise errors.InputError(
            f"controller: expected a controller name, got {type(controller).__name__}", "controller"
        )
    name = next((n for n, e in C.REGISTRY.items() if controller in (n, e.cli_name)), controller)
    if check is not None and method is not None:
        raise errors.InputError("check: checks given gains; give method or check, not both", "check")
    method = "gradient" if method is None and check is None else method
    if method is not None and method not in METHODS:
        raise errors.InputError(f"method: value {method!r}, expected one of {', '.join(METHODS)}", "method")
    settings: dict[str, object] = dict(generations=generations, population=population, steps=steps)
    settings.update(n_starts=n_starts, learning_rate=learning_rate, multistart=multistart, key=key)
    settings.update(from_default=from_default or None)  # given when True, as the flag
    # a setting the method (or a check) does not read is refused, as pfjax tune refuses its flag
    check_settings_apply(method, {k for k, v in settings.items() if v is not None})
    if n_runs is not None and isinstance(scenario, str) and scenario in scenario_sets():
        raise errors.InputError(f"n_runs: not with scenario {scenario} (it samples the runs of a study TOML)", "n_runs")
    k = prng_key(0 if key is None else key)
    # a dict changes the default or the study's settings (make_problem); a bad field is named config.<field>
    config = config if isinstance(config, dict) else sim_config(config)
    cost = CostSpec() if cost is None else cost
    ga_options = GAOptions()._replace(
        **({} if population is None else {"population_size": population}),
        **({} if generations is None else {"generations": generations}),
    )
    # the arguments that replace a field of the multi-start options (a field's error is theirs)
    given = {
        a for a, v in (("steps", steps), ("n_starts", n_starts), ("learning_rate", learning_rate)) if v is not None
    }
    own = multistart is not None  # the other fields' errors name multistart.<field>
    if check is None:  # every tuning setting, before the problem is built
        with _named(given, own):
            check_options(method, ga_options, steps, n_starts, learning_rate, multistart)
    try:
        problem = make_problem(
            name, scenario, cost=cost, config=config, model=model, **({} if n_runs is None else {"n_runs": n_runs})
        )
    except errors.InputError as e:  # named by the config fields given, as pfjax tune names its flags
        raise in_words_of(e, config if isinstance(config, dict) else None) from None
    if check is not None:
        r = run_check(problem, check, controller=name)
        return {
            "gains": reported_gains(name, problem, r.theta),
            "cost": r.cost,
            "check": as_dict(r, problem.tunable.fields, problem.tunable.sizes),
            "result": r,
        }
    with _named(given, own):
        res = run_tune(
            problem,
            method or "gradient",  # a method is given or defaults when tuning (check is None here)
            key=k,
            ga_options=ga_options,
            steps=steps,
            n_starts=n_starts,
            learning_rate=learning_rate,
            theta0=problem.tunable.flatten() if from_default else None,
            multistart=multistart,
            progress=progress,
        )
    out = tuned_result(name, problem, res)  # what pfjax tune --json prints, the history as arrays
    return {
        **out,
        "history": np.asarray(out["history"]),
        "history_rollouts": np.asarray(res.history_rollouts),
        "result": res,
    }


@contextlib.contextmanager
def _named(given: set, multistart: bool):
    """The tuner's errors by :func:`tune`'s argument names: the GA's ``population_size`` is
    ``population``; with a ``multistart`` given, a field of it that no argument in ``given``
    (``steps``, ``n_starts``, ``learning_rate``) replaced is ``multistart.<field>``."""
    from pfjax.tuning.multistart import MultistartOptions

    try:
        yield
    except errors.InputError as e:
        if e.key == "population_size":
            raise errors.renamed(e, "population_size", "population") from None
        if multistart and e.key in MultistartOptions._fields and e.key not in given:
            raise errors.renamed(e, e.key, f"multistart.{e.key}") from None
        raise


@arguments_checked
def falsify(
    controller: str = "state_feedback",
    path: str = "sine",
    *,
    gains=None,
    slip_bound_deg: float = _SEARCH.slip_bound_deg,
    f_max_hz: float = _SEARCH.f_max_hz,
    lateral_offset: float = _SEARCH.lateral_offset,
    heading_error_deg: float = _SEARCH.heading_error_deg,
    objective: str = _SEARCH.objective,
    restarts: int = _SEARCH.n_restarts,
    steps: int = _SEARCH.steps,
    key=0,
    config=None,
    speed: float = 1.0,
    L: float = 0.2,
    delta_max_deg: float = 30.0,
):
    """Search for a controller's worst case on a registered path: gradient ascent of ``objective``
    through the simulator over slip profiles bounded by ``slip_bound_deg`` (deg, per axle) with
    frequencies up to ``f_max_hz`` (Hz; 0: constant slip) and start errors within
    ``±lateral_offset`` (m) and ``±heading_error_deg`` (deg), from ``restarts`` random starts of
    ``steps`` adam steps each (:func:`pfjax.falsification.falsify`).

    ``slip_bound_deg``, ``f_max_hz``, ``lateral_offset``, ``heading_error_deg``, ``objective``,
    ``restarts`` and ``steps`` are checked as a study config's ``[falsifier]`` keys are (``restarts``
    is its ``n_restarts``), and default to its defaults (10 deg, 0.5 Hz, 0.5 m, 30 deg, ``iae``, 8
    starts of 40 steps: :class:`pfjax.montecarlo.analysis_config.FalsifierSpec`); ``config`` is a :class:`pfjax.sim.SimConfig` or a dict of its fields.

    Computed in the precision JAX is configured for (float32 unless ``jax_enable_x64``); a study's
    worst-case search (``[falsifier]`` of ``pfjax study``) runs in the study's ``dtype``.

    Args:
        controller: a registered controller or design (the command line's spellings too).
        path: a registered path built without a study config (``sine``, ``line``, ...).
        gains: the controller's gains: None (its defaults; a design is made at ``speed`` and
            ``L``), a dict of some of its gains by name, its parameter pytree, or a synthesis
            result with ``K``.
        key: int seed (or JAX key) of the random starts.
        speed: the rear axle's longitudinal speed, m/s (> 0).
        L: wheelbase, m (> 0).
        delta_max_deg: steering limit, deg (in (0, 90)).

    Returns:
        a :class:`pfjax.falsification.FalsifierResult` (the worst value, its parameters and status).

    Raises:
        pfjax.errors.InputError: a bad argument, named as here, before any run is simulated
            (``controller``, ``path``, ``gains``, ``speed``, ``L``, ``delta_max_deg``, ``key``,
            ``config``, ``restarts`` and the other ``[falsifier]`` keys' arguments).
    """
    from pfjax import controllers as C
    from pfjax import paths
    from pfjax.falsification import falsify as run_falsify
    from pfjax.falsification.search import check_settings
    from pfjax.models.slip import CONVENTIONS, SlipParams
    from pfjax.sim import SimConfig

    e, d = C.resolve(controller)
    entry = paths.fixed_entry(path)
    assert entry.build is not None  # a fixed path (fixed_entry)
    errors.number("speed", speed, positive=True, unit=" m/s")
    errors.number("L", L, positive=True, unit=" m")
    errors.number("delta_max_deg", delta_max_deg, positive=True, below=90, unit=" deg")
    try:
        check_settings(
            slip_bound_deg=slip_bound_deg,
            f_max_hz=f_max_hz,
            lateral_offset=lateral_offset,
            heading_error_deg=heading_error_deg,
            objective=objective,
            n_restarts=restarts,
            steps=steps,
        )
    except errors.InputError as ex:  # the config's n_restarts is this function's restarts
        raise errors.renamed(ex, "n_restarts", "restarts") from None
    k = prng_key(key)
    config = sim_config(config, SimConfig(record=False))
    params, _ = resolve_gains(e, d, gains, speed, L)
    sp = SlipParams(
        v=np.asarray(speed, float),
        L=np.asarray(L, float),
        delta_max=np.asarray(math.radians(delta_max_deg), float),
        convention=np.asarray(CONVENTIONS["source"], np.int32),
    )
    ic = {
        "d": (-lateral_offset, lateral_offset),
        "theta_e_deg": (-heading_error_deg, heading_error_deg),
        "u": entry.start_u,
    }
    return run_falsify(
        e.controller,
        params,
        entry.build(),
        config=config,
        slip_bound_deg=slip_bound_deg,
        f_max_hz=f_max_hz,
        ic_bounds=ic,
        objective=objective,
        n_restarts=restarts,
        steps=steps,
        key=k,
        params=sp,
    )
