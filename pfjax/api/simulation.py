"""Closed-loop simulation of a batch of runs, replays of a study's runs, success rates."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from pfjax import errors
from pfjax.api.runs import Scenarios
from pfjax.errors import arguments_checked


class Simulation(NamedTuple):
    """The outcome of :func:`simulate` (and :func:`replay`).

    Attributes:
        table: a pandas DataFrame, one row per run: the sampled values (``*_deg`` in degrees, the
            rest in SI units), every metric (:data:`pfjax.tables.COLUMNS` gives each unit),
            ``success``, ``status_code``, ``status`` and ``fail_time`` (s; NaN for a run that ran
            the whole horizon).
        result: the simulator's output, a :class:`pfjax.sim.SimResult` of NumPy arrays with one
            entry per run (``final``, ``metrics``, ``status``, ``fail_time``; ``trajectory`` only
            with ``trajectories=True``).
        controller: the controller's registry name (``state_feedback`` for a design such as ``lmi``).
        gains: the scalar gains simulated, by name (``{"k_d": ..., "k_theta": ...}``; rad/m, rad/rad
            for a state feedback).
    """

    table: Any  # pandas DataFrame: one row per run: sampled values, metrics, status, fail_time
    result: Any  # pfjax.sim.SimResult (NumPy arrays; trajectory only if asked for)
    controller: str  # the controller's registry name
    gains: dict  # the scalar gains simulated


def resolve_gains(e, d, gains, v: float, L: float) -> tuple[Any, dict]:
    """``(parameter pytree, flat gains)`` from a design, a flat dict, a parameter pytree or a
    synthesis result with ``K`` (as many elements as the controller's ``K``). ``gains`` is checked
    before the design ``d`` is made; its gains replace the design's."""
    from pfjax import controllers as C

    given: dict = {}
    if gains is None:
        pass
    elif isinstance(gains, dict):
        given = gains
    elif hasattr(gains, "_asdict") and (e.controller.params is None or isinstance(gains, e.controller.params)):
        given = C.flat_gains(e, gains)
    elif hasattr(gains, "K") and "K" in e.labels:
        names, K = e.labels["K"], np.ravel(np.asarray(gains.K, float))
        if K.size != len(names):  # a design for another plant (an integral design for state feedback)
            raise errors.InputError(
                f"gains: the {e.name} controller takes {len(names)} gains K ({', '.join(names)}), got {K.size}",
                "gains",
            )
        given = dict(zip(names, K.tolist()))
    else:
        kind = e.controller.params.__name__ if e.controller.params is not None else "parameter pytree"
        raise errors.InputError(
            f"gains: expected a dict of {', '.join(e.gains)}, a {kind} or a design with K, got {type(gains).__name__}",
            "gains",
        )
    flat = C.flat_gains(e)
    if d is not None:
        flat.update(C.design_gains(d, v, L, "controller", operating=("speed", "L")))  # scenarios' names
    flat.update(given)
    # the scalar gains simulated: the controller's own and every one given (feedforward, k_aw, ...)
    return C.params_from_flat(e, flat), {k: float(v) for k, v in flat.items() if k in e.gains or k in given}


def sim_config(config, default=None):
    """``config`` (a :class:`pfjax.sim.SimConfig`, a dict of its fields changing ``default`` or, with
    no ``default``, ``SimConfig()``), or ``default`` for None, as a ``SimConfig``;
    :class:`~pfjax.errors.InputError` naming ``config`` otherwise (the fields are checked by
    ``SimConfig``)."""
    from pfjax.sim import SimConfig
    from pfjax.sim.settings import changed

    if config is None:
        return default
    if isinstance(config, dict):
        return changed(SimConfig() if default is None else default, config)
    if not isinstance(config, SimConfig):
        raise errors.InputError(f"config: expected a SimConfig or a dict, got {type(config).__name__}", "config")
    return config


def _at_step(config: dict, dt: float):
    """``config`` (a dict of :class:`pfjax.sim.SimConfig` fields) at the step ``dt`` (s) the runs'
    tyre modes allow; :class:`~pfjax.errors.InputError` naming ``config.horizon`` when that step
    makes a run of more integrator steps than :data:`pfjax.resources.MAX_STEPS`."""
    from pfjax.resources import MAX_STEPS
    from pfjax.sim import SimConfig

    try:
        return sim_config({**config, "dt": dt})
    except errors.InputError as e:
        if e.key != "config.dt" or "horizon / dt" not in str(e):
            raise
        horizon = config.get("horizon", SimConfig.horizon)
        raise errors.InputError(
            f"config.horizon: must be at most {MAX_STEPS * dt:g} s ({MAX_STEPS:.0e} steps of {dt:g} s, the "
            f"stable step of the runs' worst case, pfjax.models.single_track.stable_step), got {errors.shown(horizon)} s",
            "config.horizon",
        ) from None


@arguments_checked
def simulate(
    scenarios: Scenarios, controller="state_feedback", gains=None, config=None, *, trajectories: bool = False
) -> Simulation:
    """Simulate every run of ``scenarios`` in closed loop with ``controller``.

    Args:
        scenarios: from :func:`scenarios`.
        controller: a registered controller or design name (``state_feedback``, ``pi``,
            ``integral``, ``stanley``, ``pure_pursuit``, ``rear_wheel``, ``lmi``, ``paper_k``, ...;
            :func:`pfjax.controllers.controller_types`).
        gains: the controller's gains: a dict of scalar gains (the others keep their defaults), its
            parameter pytree, or a design with ``K`` (:func:`design_mixed`; as many elements as the
            controller's ``K``: two for ``state_feedback``, three for ``integral``). A design name
            (``lmi``) is designed at the runs' mean speed and wheelbase.
        config: a :class:`pfjax.sim.SimConfig` or a dict of its fields (``horizon``, s; ``dt``, s;
            ``success_band``, m; ...; not ``record``: that is ``trajectories``); default 20 s at 5 ms.
            Runs of the single-track models (``scenarios(model="st" | "std")``) without a ``dt``
            take the largest stable step of 0.005, 0.002, 0.001, 0.0005, ... s for the runs' worst
            case (:func:`pfjax.models.single_track.stable_step`), as ``pfjax simulate --model``
            does; ``horizon`` is then a whole number of those steps and ``control_every`` counts
            them.
        trajectories: ``True`` also records every run's trajectory (memory grows with the horizon).

    Computed in the precision JAX is configured for (float32 unless ``jax_enable_x64``); the command
    line enables float64, and a caller that does the same gets its numbers.

    Returns:
        the per-run table with metrics and statuses, and the simulator's raw result.

    Raises:
        InputError: a bad argument, named (``controller``, ``gains.k_d``, ``config.dt``,
            ``trajectories``: also when recording would exceed the memory budget). A run that fails
            numerically is not an error: its ``status`` says how it failed.
    """
    import dataclasses

    import jax

    from pfjax import controllers as C
    from pfjax.models import DYNAMIC_MODELS
    from pfjax.montecarlo.runner import add_results, batch_size, check_record, simulate_scenarios
    from pfjax.sim import SimConfig

    if not isinstance(scenarios, Scenarios):
        raise errors.InputError(
            f"scenarios: expected the result of pfjax.scenarios(...), got {type(scenarios).__name__}", "scenarios"
        )
    e, d = C.resolve(controller) if isinstance(controller, str) else (None, None)
    if e is None:
        raise errors.InputError(
            f"controller: expected a controller name, got {type(controller).__name__}", "controller"
        )
    trajectories = errors.boolean("trajectories", trajectories)
    if isinstance(config, dict) and "record" in config:  # one way to ask for trajectories, not two
        raise errors.InputError("config.record: pass trajectories=True to record the runs", "config.record")
    t = scenarios.table
    dynamic = scenarios.spec.vehicle.model in DYNAMIC_MODELS
    if dynamic:  # the step pfjax simulate --model takes without --dt, for the runs' worst case
        from pfjax.models.single_track import check_step, stable_step, with_mu

        veh = scenarios.spec.vehicle
        st_params = with_mu(veh.model_params(), float(t["mu"].max()))
        v_lo = float(t["speed"].min())
        if config is None or (isinstance(config, dict) and "dt" not in config):
            config = _at_step({} if config is None else config, stable_step(st_params, v_lo, veh.tau_delta_s, veh.k_v))
    config = dataclasses.replace(sim_config(config, SimConfig()), record=trajectories)
    if dynamic and config.control_every is None:
        raise errors.InputError(
            "config.control_every: the single-track models take a sampled controller (>= 1 steps); a "
            "continuous one (None) is not supported",
            "config.control_every",
        )
    if dynamic:
        check_step("config.dt", config.dt, st_params, v_lo, veh.tau_delta_s, veh.k_v, worst_case="the runs' worst case")
    params, flat = resolve_gains(e, d, gains, float(t["speed"].mean()), float(t["L"].mean()))
    n = scenarios.n
    m = batch_size(n)  # padded like a study's chunks: every run takes the same vector code
    pad = lambda a: np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[:1], m - n, axis=0)])
    batch = jax.tree_util.tree_map(pad, scenarios.batch)
    batch = batch._replace(
        gains=jax.tree_util.tree_map(lambda g: np.broadcast_to(np.asarray(g), (m,) + np.shape(g)), params)
    )
    if config.record:
        check_record(
            batch,
            config,
            key="trajectories",
            runs=n,
            hint="pass trajectories=False (the metrics need none), or fewer runs",
        )
    res = simulate_scenarios(batch, controller=e.controller, config=config)
    res = jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], res)
    return Simulation(add_results(t.copy(), res, n), res, e.name, flat)


@arguments_checked
def replay(study, path: str, controller: str, runs, *, trajectories: bool = True) -> Simulation:
    """Simulate runs of a finished study again, with their trajectories: the same scenarios (the
    study's draws for these run indices), gains, settings and precision as the study.

    Args:
        study: a :class:`StudyResult`, its output directory, or its config (``StudySpec``).
        path: the path's label in the study.
        controller: the controller's name in the study.
        runs: run indices (an int or a sequence).
        trajectories: ``True`` (default) also records the runs' trajectories.

    Returns:
        these runs, their rows as the study's ``runs.parquet`` holds them
        (bit for bit with ``trajectories=False``; recording the runs changes the order of a few
        float32 sums, so ``steady_abs_d`` and ``steady_abs_theta_e_rad`` may differ by a rounding,
        about 1e-7 relative), and with ``trajectories`` the recorded runs in ``result.trajectory``.

    Raises:
        InputError: ``study`` is not a study (or a directory without one), ``path`` or
            ``controller`` is not one of the study's, or ``runs`` is empty or out of range.
    """
    import dataclasses
    import os

    import jax
    import pandas as pd

    from pfjax.api.studies import StudyResult, read_result
    from pfjax.montecarlo.config import StudySpec
    from pfjax.montecarlo.config import load_study as load_config
    from pfjax.montecarlo.runner import (
        add_results,
        controller_of,
        precision,
        sample_few,
        sim_config,
        simulate_scenarios,
        with_gains,
    )

    trajectories = errors.boolean("trajectories", trajectories)
    if isinstance(study, (str, os.PathLike)):  # the study's own files, as load_study reads them
        study = read_result(study, "study", "pfjax.replay reads")
    if not isinstance(study, (StudyResult, StudySpec)):
        raise errors.InputError(
            f"study: expected a StudyResult, a study's output directory or a StudySpec, got {type(study).__name__}",
            "study",
        )
    spec = study if isinstance(study, StudySpec) else load_config(data=study.summary["config"])[0]
    labels = [p.label for p in spec.paths]
    names = [c.name for c in spec.controllers]
    if path not in labels:
        raise errors.InputError(
            f"path: {path!r} is not a path of study {spec.name!r}; expected one of {', '.join(labels)}", "path"
        )
    if controller not in names:
        raise errors.InputError(
            f"controller: {controller!r} is not a controller of study {spec.name!r}; expected one of "
            f"{', '.join(names)}",
            "controller",
        )
    single = isinstance(runs, (bool, int, np.integer))  # a bool is refused as an integer below
    try:  # each item as given: np.asarray would make True a 1, and 0 a 0.0 beside a 1.5
        items = [runs] if single else list(runs)
    except TypeError:
        items = []
    if not items or any(isinstance(r, (list, tuple, np.ndarray)) for r in items):
        raise errors.InputError(f"runs: expected a run index or a non-empty sequence of them, got {runs!r}", "runs")
    for i, r in enumerate(items):
        errors.integer("runs" if single else f"runs[{i}]", r, low=0, high=spec.n_runs - 1)
    idx = np.asarray([int(r) for r in items], np.int64)
    p, c = labels.index(path), names.index(controller)
    with precision(spec):
        sampled = sample_few(spec, p, idx.astype(np.int64))
        ctrl, gains, flat = controller_of(spec.controllers[c], spec, c)
        m = jax.tree_util.tree_leaves(sampled.scenarios)[0].shape[0]
        cfg = dataclasses.replace(sim_config(spec), record=trajectories)
        res = simulate_scenarios(with_gains(sampled.scenarios, gains, m), controller=ctrl, config=cfg)
    n = len(idx)
    res = jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], res)
    table = pd.DataFrame(
        {
            "path": path,
            "controller": controller,
            "run": idx,
            **{k: np.asarray(v) for k, v in sampled.columns.items()},
        }
    )
    return Simulation(add_results(table, res, n), res, spec.controllers[c].type, flat)


class SuccessRate(NamedTuple):
    """A success rate with its Clopper-Pearson interval (:func:`success_rate`); ``str()`` gives it in
    one line.

    Attributes:
        rate: successes over runs, ``k / n`` (a fraction, 0 to 1).
        lo: the interval's lower end (a fraction).
        hi: the interval's upper end (a fraction).
        k: the number of successful runs.
        n: the number of runs.
        conf: the interval's confidence level (a fraction, e.g. 0.95).
    """

    rate: float
    lo: float
    hi: float
    k: int  # successes
    n: int  # runs
    conf: float

    def __str__(self) -> str:
        return (
            f"{100 * self.rate:.1f} % of {self.n} runs succeed "
            f"({100 * self.conf:g} % interval {100 * self.lo:.1f}-{100 * self.hi:.1f} %)"
        )


@arguments_checked
def success_rate(x, conf: float = 0.95) -> SuccessRate:
    """The success rate of a :class:`Simulation` (or a table with a ``success`` column, or a
    boolean array) with its exact (Clopper-Pearson) ``conf`` interval.

    Args:
        x: a :class:`Simulation`, a pandas DataFrame with a ``success`` column (a study's run table,
            ``StudyResult.runs``), or booleans, one per run (True: the run succeeded).
        conf: the interval's two-sided confidence level, in (0, 1) (default 0.95).

    Returns:
        ``rate``, ``lo``, ``hi`` (fractions), ``k`` successes in ``n`` runs, ``conf``.

    Raises:
        InputError: no runs, or successes that are not booleans (``success: ...``); ``conf`` not in (0, 1).
    """
    from pfjax.metrics.robustness import clopper_pearson

    if hasattr(x, "columns") and "success" not in x.columns:
        raise errors.InputError("success: the table has no 'success' column", "success")
    s = x.table["success"] if isinstance(x, Simulation) else (x["success"] if hasattr(x, "columns") else x)
    try:
        a = np.asarray(s).ravel()
    except ValueError:  # a ragged nest of lists
        a = np.asarray(s, dtype=object).ravel()
    if a.size == 0:
        raise errors.InputError("success: no runs", "success")
    if a.dtype != bool:  # only a boolean is an outcome (NumPy would read any non-empty string as True)
        items = np.asarray(s, dtype=object).ravel().tolist()  # the values given, not NumPy's common type
        i = next((i for i, v in enumerate(items) if not isinstance(v, (bool, np.bool_))), None)
        if i is not None:
            raise errors.InputError(
                f"success[{i}]: expected a boolean (True: the run succeeded), got {items[i]!r}", "success"
            )
        a = a.astype(bool)  # booleans of an object array
    if not 0.0 < errors.number("conf", conf) < 1.0:
        raise errors.InputError(f"conf: expected in (0, 1), got {errors.shown(conf)}", "conf")
    k, n = int(a.sum()), int(a.size)
    lo, hi = clopper_pearson(k, n, conf)
    return SuccessRate(k / n, float(lo), float(hi), k, n, float(conf))
