"""pfjax's public Python API: design, sample, simulate, summarise (re-exported by :mod:`pfjax`).

A user's script needs nothing else::

    import pfjax

    design = pfjax.design_mixed(v=1.0, L=0.2)                       # LMI state feedback
    runs = pfjax.scenarios("sine", n=1000, beta_r_deg=pfjax.uniform(-8, 8),
                           beta_f_deg=pfjax.uniform(-8, 8), key=0)   # 1,000 slipping runs
    sim = pfjax.simulate(runs, "state_feedback", gains=design)
    print(pfjax.success_rate(sim))

Every argument is checked as the command line checks it: a bad value raises
:class:`pfjax.InputError` (a ``ValueError``) whose message starts with the argument's name.
Angles are in degrees where the name ends in ``_deg``, everything else in SI units.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from pfjax import errors
from pfjax.resources import MAX_STEPS

# ----------------------------------------------------------------------------- distributions


def uniform(low: float, high: float):
    """A uniform distribution on ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="uniform", low=low, high=high)


def normal(mean: float, std: float):
    """A normal distribution (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="normal", mean=mean, std=std)


def truncnormal(mean: float, std: float, low: float, high: float):
    """A normal distribution truncated to ``[low, high]`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="truncnormal", mean=mean, std=std, low=low, high=high)


def choice(values):
    """A uniform choice among ``values`` (for :func:`scenarios`)."""
    from pfjax.montecarlo.config import Dist

    return _dist(Dist, dist="choice", values=[float(v) for v in values])


def _dist(cls, **kw):
    from pydantic import ValidationError

    try:
        return cls.model_validate(kw)
    except ValidationError as e:
        from pfjax.montecarlo.config import _format

        raise errors.InputError(f"{kw['dist']}: {_format(e)}", kw["dist"]) from None


# ----------------------------------------------------------------------------- design


def design_mixed(v: float = 1.0, L: float = 0.2, alpha: float = 10.0, beta: float = 1.0, region=None):
    """The mixed H2/H∞ state feedback of the slip plant at speed ``v`` (m/s) and wheelbase ``L``
    (m), minimising ``alpha γ∞² + beta γ₂²`` by LMIs (cvxpy + Clarabel).

    Returns:
        a :class:`pfjax.synthesis.Design`: ``K`` (1×2: rad/m, rad/rad, for ``[d, θ_e]``), the LMI
        bounds ``gamma_inf``, ``gamma_2``, the closed loop's true norms ``hinf_norm``,
        ``h2_norm`` and its poles. Pass it as ``gains`` to :func:`simulate` with ``"state_feedback"``.

    Raises:
        InputError: a bad argument. SynthesisError: the LMIs are infeasible.
    """
    from pfjax.synthesis import synthesize

    return synthesize("mixed", v=v, L=L, alpha=alpha, beta=beta, region=region)


# ----------------------------------------------------------------------------- scenarios

#: :func:`scenarios`'s arguments -> the study config's keys.
_SCENARIO_KEYS = {
    "speed": "vehicle.speed",
    "L": "vehicle.L",
    "delta_max_deg": "vehicle.delta_max_deg",
    "beta_r_deg": "slip.beta_r_deg",
    "beta_f_deg": "slip.beta_f_deg",
    "start_along_m": "initial.start_along_m",
    "lateral_offset": "initial.lateral_offset",
    "heading_error_deg": "initial.heading_error_deg",
    "mu": "vehicle.mu",
    "vehicle_params": "vehicle.params",
    "tau_delta_s": "vehicle.tau_delta_s",
    "k_v": "vehicle.k_v",
    "model": "vehicle.model",
}


class Scenarios(NamedTuple):
    """A batch of runs of one path (:func:`scenarios`)."""

    batch: Any  # pfjax.sim.Scenario (model st: pfjax.sim.dynamic.DynamicScenario) with a leading run axis (gains None)
    table: Any  # pandas DataFrame: one row per run, the sampled values (config units)
    spec: Any  # the study config that describes them (pfjax.montecarlo.config.StudySpec)

    @property
    def n(self) -> int:
        return len(self.table)


def scenarios(
    path: str = "sine",
    n: int = 1,
    *,
    beta_r_deg=None,
    beta_f_deg=None,
    lateral_offset=0.0,
    heading_error_deg=0.0,
    start_along_m=0.0,
    speed=1.0,
    L=None,
    delta_max_deg=None,
    convention: str | None = None,
    horizon: float = 20.0,
    key=0,
    model: str = "kinematic",
    vehicle_params: str | None = None,
    mu=None,
    tau_delta_s: float | None = None,
    k_v: float | None = None,
) -> Scenarios:
    """``n`` runs on a registered path (:data:`pfjax.paths.PATHS`), vectorised: each quantity is a
    number (every run), an array of ``n`` numbers (run by run), or a distribution
    (:func:`uniform`, :func:`normal`, :func:`truncnormal`, :func:`choice`, or a study config's
    ``{"dist": ...}`` dict) drawn per run. One jitted program draws them all; no Python loop.

    Args:
        path: a registered path kind (``line``, ``parabola``, ``sine``, ``circle``, ...).
        n: number of runs.
        beta_r_deg: constant rear slip angle, deg (kinematic model; default 5).
        beta_f_deg: constant front slip angle, deg (kinematic model; default 5).
        lateral_offset: start offset left of the path, m.
        heading_error_deg: start heading error, deg.
        start_along_m: start, m along the path from its nominal start.
        speed: rear-axle speed, m/s.
        L: wheelbase, m (kinematic model; default 0.2).
        delta_max_deg: steering limit, deg (kinematic model; default 30).
        convention: front-slip sign convention (``source`` or ``lenain``; kinematic model).
        horizon: s, only to size slip sequences (the simulation's horizon is :func:`simulate`'s).
        key: an int seed or a JAX PRNG key; run ``i`` draws from ``fold_in(key, i)``, so the first
            runs of a larger ``n`` are the same runs.
        model: ``"kinematic"`` (slip declared by ``beta_r_deg``, ``beta_f_deg``) or ``"st"``
            (CommonRoad's single-track model, :mod:`pfjax.sim.dynamic`: the slip comes from the tyre
            forces, so the slip, ``L``, ``delta_max_deg`` and ``convention`` are refused with it).
        vehicle_params: st: parameter set, ``robot`` (default) or ``vehicle1``-``vehicle3``.
        mu: st: friction coefficient (default the set's). tau_delta_s: st: steering actuator time
            constant, s (default 0.05). k_v: st: speed loop gain, 1/s (default 5).

    The arguments are checked as a study config's ``[vehicle]``, ``[slip]`` and ``[initial]`` keys
    are (the same validation, the message naming the argument).
    """
    import pandas as pd

    from pfjax.montecarlo.config import Dist, load_study
    from pfjax.montecarlo.sampling import sample_runs

    n = errors.integer("n", n, low=1, high=100_000_000)
    if model == "kinematic":  # the kinematic defaults (None: not given, so the ST model can refuse a given one)
        beta_r_deg = 5.0 if beta_r_deg is None else beta_r_deg
        beta_f_deg = 5.0 if beta_f_deg is None else beta_f_deg
    values = dict(
        speed=speed,
        L=L,
        delta_max_deg=delta_max_deg,
        beta_r_deg=beta_r_deg,
        beta_f_deg=beta_f_deg,
        start_along_m=start_along_m,
        lateral_offset=lateral_offset,
        heading_error_deg=heading_error_deg,
        mu=mu,
    )
    dists, given = {}, {}
    for name, v in values.items():
        if v is None:
            continue
        if isinstance(v, (Dist, dict)):
            dists[name] = v.model_dump() if isinstance(v, Dist) else v
            continue
        a = np.asarray(errors.numbers(name, v), dtype=float)
        if a.ndim == 0:
            dists[name] = {"dist": "constant", "value": float(a)}
        elif a.shape != (n,):
            raise errors.InputError(
                f"{name}: expected a number or {n} numbers (one per run), got shape {a.shape}", name
            )
        else:  # the config sees the values' range (its bounds are checked), the runs get the values
            lo, hi = float(a.min()), float(a.max())
            dists[name] = {"dist": "constant", "value": lo} if lo == hi else {"dist": "uniform", "low": lo, "high": hi}
            given[name] = a
    seed = key if isinstance(key, (int, np.integer)) and not isinstance(key, bool) else 0
    errors.seed("key", seed)
    data: dict[str, Any] = {
        "name": "scenarios",
        "n_runs": n,
        "seed": int(seed),
        "paths": [{"kind": path}],
        "controllers": [{"name": "none", "type": "state_feedback"}],
        "sim": {"horizon": horizon},
        "vehicle": {
            "model": model,
            **{k: dists[k] for k in ("speed", "L", "delta_max_deg", "mu") if k in dists},
            **{
                k: v
                for k, v in (
                    ("convention", convention),
                    ("params", vehicle_params),
                    ("tau_delta_s", tau_delta_s),
                    ("k_v", k_v),
                )
                if v is not None
            },
        },
        "slip": {k: dists[k] for k in ("beta_r_deg", "beta_f_deg") if k in dists},
        "initial": {k: dists[k] for k in ("start_along_m", "lateral_offset", "heading_error_deg")},
    }
    if model in ("st", "std"):
        data["margin"] = {"enabled": False}
        # the step is simulate()'s, which checks it against the tyre modes; here the finest allowed
        data["sim"]["dt"] = horizon / MAX_STEPS
    try:
        spec, _ = load_study(data=data)
    except errors.InputError as e:
        raise _renamed(e) from None
    jkey = None if isinstance(key, (int, np.integer)) else key
    sampled = sample_runs(spec, 0, np.arange(n), key=jkey, given=given)
    table = pd.DataFrame({"run": np.arange(n), **{k: np.asarray(v, float) for k, v in sampled.columns.items()}})
    return Scenarios(sampled.scenarios, table, spec)


def _renamed(e: errors.InputError) -> errors.InputError:
    """A study-config error named by :func:`scenarios`'s argument (``slip.beta_r_deg`` -> ``beta_r_deg``)."""
    text = str(e)
    for arg, key in _SCENARIO_KEYS.items():
        text = text.replace(key, arg)
    text = (
        text.replace("paths[0].kind", "path")
        .replace("sim.horizon", "horizon")
        .replace("vehicle.convention", "convention")
    )
    return errors.InputError(text, text.split(":", 1)[0].split(".", 1)[0])


# ----------------------------------------------------------------------------- simulate


class Simulation(NamedTuple):
    """The outcome of :func:`simulate`."""

    table: Any  # pandas DataFrame: one row per run: sampled values, metrics, status, fail_time
    result: Any  # pfjax.sim.SimResult (NumPy arrays; trajectory only if asked for)
    controller: str  # the controller's registry name
    gains: dict  # the scalar gains simulated


def _gains_of(e, d, gains, v: float, L: float) -> tuple[Any, dict]:
    """``(parameter pytree, flat gains)`` from a design, a flat dict, a parameter pytree or a
    synthesis result with ``K``."""
    from pfjax import controllers as C

    flat = C.flat_gains(e)
    if d is not None:
        flat.update(d.make(v, L))
    if gains is None:
        pass
    elif isinstance(gains, dict):
        flat.update(gains)
    elif hasattr(gains, "_asdict") and (e.controller.params is None or isinstance(gains, e.controller.params)):
        flat = C.flat_gains(e, gains)
    elif hasattr(gains, "K") and "K" in e.labels:
        flat.update(zip(e.labels["K"], np.ravel(np.asarray(gains.K, float)).tolist()))
    else:
        kind = e.controller.params.__name__ if e.controller.params is not None else "parameter pytree"
        raise errors.InputError(
            f"gains: expected a dict of {', '.join(e.gains)}, a {kind} or a design with K, got {type(gains).__name__}",
            "gains",
        )
    return C.params_from_flat(e, flat), {k: float(v) for k, v in flat.items()}


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
            parameter pytree, or a design with ``K`` (:func:`design_mixed`). A design name
            (``lmi``) is designed at the runs' mean speed and wheelbase.
        config: a :class:`pfjax.sim.SimConfig` or a dict of its fields (``horizon``, ``dt``,
            ``success_band``, ...); default 20 s at 5 ms.
        trajectories: also record every run's trajectory (memory grows with the horizon).

    Returns:
        a :class:`Simulation` (per-run table with metrics and statuses, the raw result).
    """
    import dataclasses

    import jax

    from pfjax import controllers as C
    from pfjax.montecarlo.runner import add_results, batch_size, simulate_scenarios
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
    if config is None:
        config = SimConfig()
    elif isinstance(config, dict):
        unknown = set(config) - {f.name for f in dataclasses.fields(SimConfig)}
        if unknown:
            raise errors.InputError(
                f"config.{sorted(unknown)[0]}: unknown setting; expected one of "
                f"{', '.join(f.name for f in dataclasses.fields(SimConfig))}",
                "config",
            )
        config = SimConfig(**config)
    elif not isinstance(config, SimConfig):
        raise errors.InputError(f"config: expected a SimConfig or a dict, got {type(config).__name__}", "config")
    config = dataclasses.replace(config, record=bool(trajectories))
    t = scenarios.table
    if scenarios.spec.vehicle.model in ("st", "std"):
        from pfjax.models.single_track import max_stable_step, with_mu

        veh = scenarios.spec.vehicle
        mu_hi = float(t["mu"].max())
        dt_max = max_stable_step(with_mu(veh.model_params(), mu_hi), float(t["speed"].min()), veh.tau_delta_s, veh.k_v)
        if config.dt > dt_max:
            raise errors.InputError(
                f"config.dt: the {veh.model.upper()} model at mu = {mu_hi:g} and speed {float(t['speed'].min()):g} m/s (the runs' "
                f"worst case) needs dt <= {dt_max:.3g} s for a stable RK4 step, got {config.dt:g}",
                "config",
            )
    params, flat = _gains_of(e, d, gains, float(t["speed"].mean()), float(t["L"].mean()))
    n = scenarios.n
    m = batch_size(n)  # padded like a study's chunks: every run takes the same vector code
    pad = lambda a: np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[:1], m - n, axis=0)])
    batch = jax.tree_util.tree_map(pad, scenarios.batch)
    batch = batch._replace(
        gains=jax.tree_util.tree_map(lambda g: np.broadcast_to(np.asarray(g), (m,) + np.shape(g)), params)
    )
    res = jax.tree_util.tree_map(
        lambda a: np.asarray(a)[:n], simulate_scenarios(batch, controller=e.controller, config=config)
    )
    return Simulation(add_results(t.copy(), res, n), res, e.name, {k: flat[k] for k in e.gains})


def replay(study, path: str, controller: str, runs, *, trajectories: bool = True) -> Simulation:
    """Simulate runs of a finished study again, with their trajectories: the same scenarios (the
    study's draws for these run indices), gains, settings and precision as the study.

    Args:
        study: a :class:`StudyResult`, its output directory, or its config (``StudySpec``).
        path: the path's label in the study. controller: the controller's name in the study.
        runs: run indices (an int or a sequence).
    """
    import dataclasses
    from pathlib import Path

    import jax
    import pandas as pd

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

    if isinstance(study, (str, Path)):
        study = load_study(study)
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
    idx = np.atleast_1d(np.asarray(runs))
    for r in idx.tolist():
        errors.integer("runs", r, low=0, high=spec.n_runs - 1)
    p, c = labels.index(path), names.index(controller)
    with precision(spec):
        sampled = sample_few(spec, p, idx.astype(np.int64))
        ctrl, gains, flat = controller_of(spec.controllers[c], spec, c)
        m = jax.tree_util.tree_leaves(sampled.scenarios)[0].shape[0]
        cfg = dataclasses.replace(sim_config(spec), record=bool(trajectories))
        res = simulate_scenarios(with_gains(sampled.scenarios, gains, m), controller=ctrl, config=cfg)
    n = len(idx)
    res = jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], res)
    table = pd.DataFrame(
        {
            "path": path,
            "controller": controller,
            "run": idx,
            **{k: np.asarray(v, float) for k, v in sampled.columns.items()},
        }
    )
    return Simulation(add_results(table, res, n), res, spec.controllers[c].type, flat)


class SuccessRate(NamedTuple):
    """A success rate with its Clopper-Pearson interval."""

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


def success_rate(x, conf: float = 0.95) -> SuccessRate:
    """The success rate of a :class:`Simulation` (or a table with a ``success`` column, or a
    boolean array) with its exact (Clopper-Pearson) ``conf`` interval."""
    from pfjax.metrics.robustness import clopper_pearson

    s = x.table["success"] if isinstance(x, Simulation) else (x["success"] if hasattr(x, "columns") else x)
    s = np.asarray(s, dtype=bool).ravel()
    if s.size == 0:
        raise errors.InputError("success: no runs", "success")
    if not 0.0 < errors.number("conf", conf) < 1.0:
        raise errors.InputError(f"conf: expected in (0, 1), got {conf:g}", "conf")
    k, n = int(s.sum()), int(s.size)
    lo, hi = clopper_pearson(k, n, conf)
    return SuccessRate(k / n, float(lo), float(hi), k, n, float(conf))


# ----------------------------------------------------------------------------- studies


class StudyResult(NamedTuple):
    """A study's outputs (:func:`run_study`, :func:`load_study`)."""

    out: Any  # pathlib.Path of the output directory
    summary: dict  # summary.json
    runs: Any  # pandas DataFrame: runs.parquet
    margin: Any  # pandas DataFrame: margin.parquet (None without a margin sweep)
    headline: Any  # pandas DataFrame: one row per controller (success rate, interval, margin)


def load_study(out) -> StudyResult:
    """Read a finished study's outputs from its directory ``out``."""
    import json
    from pathlib import Path

    import pandas as pd

    from pfjax.montecarlo.summary import headline

    out = Path(out)
    if not (out / "summary.json").is_file() or not (out / "runs.parquet").is_file():
        raise errors.InputError(f"out: {out} holds no finished study (summary.json and runs.parquet)", "out")
    summary = json.loads((out / "summary.json").read_text())
    margin = pd.read_parquet(out / "margin.parquet") if (out / "margin.parquet").is_file() else None
    return StudyResult(out, summary, pd.read_parquet(out / "runs.parquet"), margin, headline(summary))


def run_study(
    config,
    out=None,
    *,
    overwrite: bool = False,
    fresh: bool = False,
    progress: bool | None = None,
    report: bool = True,
    **overrides,
) -> StudyResult:
    """Run a Monte Carlo study and return its outputs, as ``pfjax study`` does.

    Args:
        config: a study TOML path, a config dict, or a :class:`pfjax.montecarlo.config.StudySpec`.
        out: output directory (default ``results/<name>``), written with pfjax's output rules
            (:mod:`pfjax.outputs`: another pfjax output is replaced only with ``overwrite``).
        fresh: discard the finished chunks of an interrupted run instead of resuming.
        progress: progress bars (default: when stderr is a terminal). report: write report.html.
        overrides: config values by key, nested keys with ``__`` (``n_runs=1000``,
            ``sim__horizon=30``, ``paths=[{"kind": "line"}]``), as ``--set key=value`` but with
            Python values.
    """
    from pathlib import Path

    from pfjax.montecarlo.study import run

    spec = _study_spec(config, {k.replace("__", "."): v for k, v in overrides.items()})
    out = Path("results") / spec.name if out is None else Path(out)
    run(spec, out, progress=progress, report=report, fresh=fresh, overwrite=overwrite)
    return load_study(out)


def rare_event(
    config,
    *,
    controller: str | None = None,
    method: str | None = None,
    target_rel_error: float | None = None,
    max_rollouts: int | None = None,
    seed: int | None = None,
    progress: bool | None = None,
    **overrides,
) -> dict:
    """Each controller's probability of failure under a study's uncertain inputs, down to 1e-6 and
    below, with a 95 % interval (:mod:`pfjax.rare`), as ``pfjax rare-event`` does.

    A run fails where its status is a failure or the study's ``rare_event.metric`` exceeds
    ``rare_event.threshold`` (default: ``late_max_abs_d`` above ``success.band``, m). The keyword
    arguments override the config's ``[rare_event]`` table.

    Args:
        config: a study TOML path, a config dict, or a :class:`pfjax.montecarlo.config.StudySpec`.
        controller: only this controller of the study (default: all).
        method: ``is`` (cross-entropy importance sampling), ``subset`` (subset simulation) or
            ``mc`` (plain Monte Carlo, exact binomial interval).
        target_rel_error: stop once the relative error (coefficient of variation) is at most this.
        max_rollouts: rollouts per controller at most.
        seed: seed of the estimator's draws.
        progress: a progress bar on stderr (default: when it is a terminal).
        overrides: config values by key, nested keys with ``__``, as :func:`run_study`.

    Returns:
        ``{"study", "config_sha256", "units", "controllers": {name: {"p_fail", "ci95",
        "rel_error", "n_rollouts", "method", "wall_s", "strata", "failure_points"}}}``.
    """
    from pfjax.montecarlo.config import study_hash
    from pfjax.montecarlo.runner import controllers_of
    from pfjax.rare import METHODS
    from pfjax.rare.study import estimate_study
    from pfjax.rare.transform import study_inputs

    values = {k.replace("__", "."): v for k, v in overrides.items()}
    if method is not None:
        if method not in METHODS:
            raise errors.InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}", "method")
        values["rare_event.method"] = method
    if target_rel_error is not None:
        values["rare_event.target_rel_error"] = errors.number("target_rel_error", target_rel_error, positive=True)
        if target_rel_error > 10:
            raise errors.InputError(f"target_rel_error: must be <= 10, got {target_rel_error:g}", "target_rel_error")
    if max_rollouts is not None:
        values["rare_event.max_rollouts"] = errors.integer("max_rollouts", max_rollouts, low=100, high=100_000_000)
    if seed is not None:
        values["rare_event.seed"] = errors.seed("seed", seed)
    spec = _study_spec(config, values)
    names = [c.name for c in spec.controllers]
    if controller is not None and controller not in names:
        raise errors.InputError(
            f"controller: {controller!r} is not one of study {spec.name!r}'s controllers: {', '.join(names)}",
            "controller",
        )
    study_inputs(spec)  # an unsupported study fails here, before anything is simulated
    controllers = controllers_of(spec)
    chosen = names if controller is None else [controller]
    return {
        "study": spec.name,
        "config_sha256": study_hash(spec),
        "units": {"p_fail": "probability per run", "ci95": "probability", "rel_error": "1", "wall_s": "s"},
        "controllers": estimate_study(spec, controllers, names=chosen, progress=progress),
    }


def _study_spec(config, values: dict):
    """A validated study config from a TOML path, a dict or a StudySpec, with ``values`` overriding."""
    from pathlib import Path

    from pfjax.montecarlo.config import StudySpec
    from pfjax.montecarlo.config import load_study as load_config

    if isinstance(config, StudySpec):
        return load_config(data=config.model_dump(mode="json"), values=values)[0]
    if isinstance(config, dict):
        return load_config(data=config, values=values)[0]
    if isinstance(config, (str, Path)):
        if not Path(config).is_file():
            raise errors.InputError(f"config: no such file {str(config)!r}", "config")
        return load_config(Path(config), values=values)[0]
    raise errors.InputError(
        f"config: expected a TOML path, a dict or a StudySpec, got {type(config).__name__}", "config"
    )


def tune(
    controller: str = "pi",
    scenario: str = "paper-line",
    method: str = "gradient",
    *,
    key=0,
    cost=None,
    config=None,
    n_runs: int = 16,
    steps: int | None = None,
    n_starts: int | None = None,
    learning_rate: float | None = None,
    generations: int = 100,
    population: int = 50,
    multistart=None,
    check=None,
    progress: bool = False,
) -> dict:
    """Tune a controller's gains, or check given gains, as ``pfjax tune`` does.

    Args:
        controller: a registered controller with a tuning box (``pi``, ``state_feedback``, ...).
        scenario: ``paper-line`` | ``paper-parabola`` | ``paper-sine`` | ``paper-all`` | a
            registered path's name | a study TOML (``n_runs`` sampled runs per path).
        method: ``gradient`` (the multi-start tuner: Sobol screening with the controller's
            default gains, successive halving of projected BFGS chains, restarts;
            :mod:`pfjax.tuning.multistart`), ``gradient-plain`` (projected adam from ``n_starts``
            uniform starts), ``ga`` (MATLAB-style GA) or ``ga+gradient`` (the GA, then ``steps``
            adam steps from its best).
        key: int seed (or JAX key) of the GA population / the gradient's starts.
        cost: a :class:`pfjax.tuning.CostSpec` (metric, effort weight, aggregate); default mean IAE.
        config: a :class:`pfjax.sim.SimConfig` (default 20 s at 5 ms, or the study's).
        steps: gradient steps (``None``: the method's default; multi-start: evaluations of a
            surviving chain).
        n_starts: starts descended together (``None``: the method's default).
        learning_rate: multi-start: first BFGS trust radius; adam: step (box units; ``None``: default).
        multistart: a :class:`pfjax.tuning.MultistartOptions` for ``gradient``.
        check: gains to check instead of tuning (``{field: value}``, its JSON text or numbers in
            field order, inside the tuning box): gradient, projected gradient, active bounds,
            Hessian eigenvalues on the free coordinates, verdict (:mod:`pfjax.tuning.check`).

    Returns:
        ``{"gains", "cost", "n_rollouts", "n_forward_passes", "wall_s", "compile_s", "history",
        "history_rollouts", "result"}``; with ``check``: ``{"gains", "cost", "check", "result"}``.
    """
    import jax

    from pfjax import controllers as C
    from pfjax.tuning.check import as_dict
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import check as run_check
    from pfjax.tuning.problem import make_problem
    from pfjax.tuning.problem import tune as run_tune

    name = C.resolve(controller)[0].name if isinstance(controller, str) else controller
    problem = make_problem(name, scenario, cost=cost or CostSpec(), config=config, n_runs=n_runs)
    if check is not None:
        r = run_check(problem, check)
        return {
            "gains": C.flat_gains(C.entry(name), problem.tunable.gains(r.theta)),
            "cost": r.cost,
            "check": as_dict(r, problem.tunable.fields, problem.tunable.sizes),
            "result": r,
        }
    k = jax.random.PRNGKey(errors.seed("key", key)) if isinstance(key, (int, np.integer)) else key
    res = run_tune(
        problem,
        method,
        key=k,
        ga_options=GAOptions(population_size=population, generations=generations),
        steps=steps,
        n_starts=n_starts,
        learning_rate=learning_rate,
        multistart=multistart,
        progress=progress,
    )
    gains = C.flat_gains(C.entry(name), problem.tunable.gains(res.theta))
    return {
        "gains": gains,
        "cost": float(res.cost),
        "n_rollouts": int(res.n_rollouts),
        "n_forward_passes": int(res.n_forward_passes),
        "wall_s": float(res.wall_s),
        "compile_s": float(res.compile_s),
        "history": np.asarray(res.history),
        "history_rollouts": np.asarray(res.history_rollouts),
        "result": res,
    }


def falsify(
    controller: str = "state_feedback",
    path: str = "sine",
    *,
    gains=None,
    slip_bound_deg: float = 10.0,
    f_max_hz: float = 0.5,
    lateral_offset: float = 0.1,
    heading_error_deg: float = 5.0,
    objective: str = "iae",
    restarts: int = 8,
    steps: int = 50,
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

    Returns:
        a :class:`pfjax.falsification.FalsifierResult` (the worst value, its parameters and status).
    """
    import jax

    from pfjax import controllers as C
    from pfjax import paths
    from pfjax.falsification import falsify as run_falsify
    from pfjax.models.slip import CONVENTIONS, SlipParams
    from pfjax.sim import SimConfig

    e, d = C.resolve(controller)
    entry = paths.entry(path)
    if entry.build is None:
        raise errors.InputError(
            f"path: {path!r} is built only from a study config; expected one of {', '.join(paths.fixed_paths())}",
            "path",
        )
    errors.number("speed", speed, positive=True, unit=" m/s")
    errors.number("L", L, positive=True, unit=" m")
    errors.number("delta_max_deg", delta_max_deg, positive=True, below=90, unit=" deg")
    errors.number("lateral_offset", lateral_offset, nonnegative=True, unit=" m")
    errors.number("heading_error_deg", heading_error_deg, nonnegative=True, below=180, unit=" deg")
    restarts = errors.integer("restarts", restarts, low=1, high=4096)
    steps = errors.integer("steps", steps, low=1, high=100_000)
    params, _ = _gains_of(e, d, gains, speed, L)
    sp = SlipParams(
        v=np.asarray(speed, float),
        L=np.asarray(L, float),
        delta_max=np.asarray(math.radians(delta_max_deg), float),
        convention=np.asarray(CONVENTIONS["source"], np.int32),
    )
    k = jax.random.PRNGKey(errors.seed("key", key)) if isinstance(key, (int, np.integer)) else key
    ic = {
        "d": (-lateral_offset, lateral_offset),
        "theta_e_deg": (-heading_error_deg, heading_error_deg),
        "u": entry.start_u,
    }
    return run_falsify(
        e.controller,
        params,
        entry.build(),
        config=config or SimConfig(record=False),
        slip_bound_deg=slip_bound_deg,
        f_max_hz=f_max_hz,
        ic_bounds=ic,
        objective=objective,
        n_restarts=restarts,
        steps=steps,
        key=k,
        params=sp,
    )
