"""A study controller's failure probability: the study's runs as a limit-state function on the
standard-normal space, estimated per stratum and combined.

For a stratum ``s`` (a path and one value of every ``choice``, :mod:`pfjax.rare.transform`) and
standard-normal points ``u``, the runs are the study's runs with the continuous inputs set to
``T(u)`` (:func:`pfjax.montecarlo.sampling.sample_runs` with ``given``), simulated as the study
simulates them (same settings, precision and gains), and the margin is

$$
g(u) = \\text{threshold} - \\text{metric}(u) \\quad (\\text{metric's unit}),
$$

forced to at most ``-10⁻⁹`` where the run's status is a failure (diverged, non-finite, ...);
positive margins are rounded up to multiples of ``margin_resolution`` (its sign, so the failure
set, unchanged), so runs that converge alike tie, and beside the margin ``g`` returns the
tie-break ``-tie_break metric`` that orders tied runs in subset simulation (the larger the
transient error, the nearer failure; :mod:`pfjax.rare.subset`, *Plateaus*). The
strata combine as ``p = Σ_s w_s p_s`` with ``Var p = Σ_s w_s² Var p_s`` (:func:`combine`); one
stratum keeps its estimator's own interval, several get the lognormal one of
:func:`pfjax.rare.estimate.lognormal_interval`. A stratum whose estimate is 0 or whose relative
error is infinite (no failure seen, a stalled subset run, too few draws) has no variance to add:
the controller's relative error is infinite, and the stratum's weighted interval ``w_s [lo_s,
hi_s]`` is added to the interval of the other strata, so its upper bound stays in the
controller's.

An importance-sampling estimate is checked per stratum (:mod:`pfjax.rare.check`): always for
weights concentrated on one draw, and with ``check = "subset"`` against subset simulation on the
same target and budget. A stratum whose estimate is 0 (no failure seen, by any method) is flagged
``no_failures`` (:func:`no_failures`). The controller's ``status`` is the first stratum's flag
(the checks' first; ``ok`` where none is raised) and its ``warning`` names each flagged stratum's
path.
"""

from __future__ import annotations

import itertools
import math
import time
from functools import partial

import numpy as np

from pfjax.montecarlo.config import StudySpec
from pfjax.numerics.random import seed_key
from pfjax.rare.check import reliability
from pfjax.rare.estimate import RareEstimate, lognormal_interval, monte_carlo
from pfjax.rare.importance import cross_entropy_is, explore, least_rollouts
from pfjax.rare.starts import N_RAY, falsifier_applies, falsifier_points
from pfjax.rare.subset import subset_simulation
from pfjax.rare.transform import Input, Stratum, config_keys, study_inputs, to_physical
from pfjax.tables import COLUMNS

#: The units of :func:`estimate_controller`'s numbers by field name ("1": dimensionless);
#: :func:`units` adds the study's inputs'.
UNITS: dict[str, str] = {
    "p_fail": "probability per run",
    "ci95": "probability (95 % interval of p_fail)",
    "rel_error": "1 (coefficient of variation of p_fail)",
    "p": "probability per run (one subset-simulation run's estimate)",
    **dict.fromkeys(("delta_uncorrelated", "delta_correlated"), "1 (coefficient of variation)"),
    **dict.fromkeys(("n_rollouts", "falsifier_rollouts"), "rollouts (simulated runs)"),
    "wall_s": "s",
    "weight": "1 (a stratum's probability; a failure point's: its share of the proposal times its stratum's)",
    "max_weight_share": "1 (the largest importance weight over their sum)",
    "z": "1 (the two estimates' log difference in standard errors; null: infinite, one estimate 0)",
    "u": "1 (standard deviations of the input's standard-normal coordinate)",
    **dict.fromkeys(("value", "median"), "the unit of the input named by key"),
}


def units(spec: StudySpec) -> dict[str, str]:
    """:data:`UNITS` and each input's and choice's unit by its config key (``slip.beta_r_deg``:
    deg), as the strata's ``values`` and the failure points give them; the failure threshold's
    (``config.rare_event.threshold``, the unit of ``rare_event.metric``: m for ``late_max_abs_d``,
    m·s for ``iae``)."""
    return {
        **UNITS,
        **{key: COLUMNS[name][0] for name, key in config_keys(spec).items() if COLUMNS.get(name, ("", ""))[0]},
        "config.rare_event.threshold": COLUMNS[spec.rare_event.metric][0],
    }


def failure_threshold(rare: dict, band: float) -> float:
    """The rare-event failure threshold, in its metric's unit: ``rare_event.threshold``, else the
    success band (m; the config refuses no threshold for a metric in another unit,
    :class:`~pfjax.montecarlo.analysis_config.RareEventSpec`). ``rare``: the ``[rare_event]`` table
    as a dict (a spec's ``model_dump()``)."""
    return band if rare["threshold"] is None else rare["threshold"]


def margins(status, metric, threshold: float) -> np.ndarray:
    """The limit state's margins of runs (float64): ``threshold - metric``, and a failed run (status
    not ok) fails whatever its metric (NaN for a run failed at t = 0: fmin). A run fails where its
    margin is at most 0 (:func:`limit_state`; the study's ``plain_fail`` counts the same)."""
    margin = threshold - np.asarray(metric, dtype=float)
    return np.where(np.asarray(status) != 0, np.fmin(margin, -1e-9), margin)


def limit_state(
    spec: StudySpec, stratum: Stratum, inputs: list[Input], controller, *, seed: int = 0, stream: int = 0, counter=None
):
    """``g(u)`` of one stratum for one controller (``(ctrl, gains, flat)`` of
    :func:`pfjax.montecarlo.runner.controller_of`); ``counter(n)`` is told of every ``n`` rollouts.

    A batch of ``n`` points is padded to a multiple of 32 runs (one compiled program per padded
    size), with ``u``'s extra coordinate ignored when the study has no continuous input. Call
    ``c`` of ``g`` draws the randomness that is not in ``u`` (:mod:`pfjax.rare.transform`) from
    ``fold_in(fold_in(seed_key(seed), stream), c)``: fresh at every rollout, the same for the same seed and calls."""
    import jax

    from pfjax.montecarlo.chunk_runs import simulate_scenarios
    from pfjax.montecarlo.runner import batch_size, sim_config, with_gains
    from pfjax.montecarlo.sampling import sample_runs

    ctrl, gains, _ = controller
    rare = spec.rare_event
    threshold = failure_threshold(rare.model_dump(), spec.success.band)
    cfg = sim_config(spec)
    calls = itertools.count()
    base = jax.random.fold_in(seed_key(seed), stream)

    def g(u: np.ndarray) -> np.ndarray:
        n = len(u)
        key = jax.random.fold_in(base, next(calls))
        m = batch_size(n)
        x = to_physical(inputs, u) if inputs else {}
        x.update({k: np.full(n, v) for k, v in stratum.values.items()})
        given = {k: np.concatenate([v, np.repeat(v[:1], m - n)]) for k, v in x.items()}
        sampled = sample_runs(spec, stratum.path_index, np.arange(m), key=key, given=given)
        # the study's vehicle model: the slip model's simulator, or the single-track one (model st, std)
        res = simulate_scenarios(with_gains(sampled.scenarios, gains, m), controller=ctrl, config=cfg)
        margin = margins(np.asarray(res.status)[:n], np.asarray(getattr(res.metrics, rare.metric))[:n], threshold)
        if counter is not None:
            counter(n)
        if rare.margin_resolution > 0:
            r = rare.margin_resolution
            margin = np.where(margin > 0, r * np.maximum(np.ceil(margin / r), 1.0), margin)
        if rare.tie_break is None:
            return margin
        return np.stack([margin, -np.asarray(getattr(res.metrics, rare.tie_break), dtype=float)[:n]], axis=1)

    return g


def stratum_seed(seed: int, k: int) -> int:
    """The seed of stratum ``k``'s draws (its estimator's and its falsifier's) in a study whose
    ``rare_event.seed`` is ``seed``: ``seed`` itself for the first stratum, so that a study of one
    stratum draws as the estimator called with ``seed``; for the others a 63-bit seed drawn by
    NumPy's ``SeedSequence((seed, k))``, so that no stratum shares its draws with a stratum of
    another seed (with ``seed + k``, seed 0's second stratum would draw seed 1's first)."""
    if k == 0:
        return seed
    return _derived(seed, k)


def explore_seed(seed: int) -> int:
    """The seed of the explore stage's draws for an estimate seeded ``seed`` (a stratum's,
    :func:`stratum_seed`): a 63-bit seed drawn by ``SeedSequence((seed, EXPLORE))``, so that it
    meets another study's estimator seed only by chance, not by rule (``seed + c`` is the estimator
    seed of the study seeded ``seed + c``)."""
    return _derived(seed, EXPLORE)


#: The second entropy word of the explore stage's :class:`numpy.random.SeedSequence` (a stratum's is
#: its index, below 10⁸ strata).
EXPLORE = 2**32 - 1


def _derived(seed: int, word: int) -> int:
    return int(np.random.SeedSequence((seed, word)).generate_state(1, np.uint64)[0] >> np.uint64(1))


def _starts(g, dim, rare, seed, falsifier) -> tuple[np.ndarray | None, int, dict]:
    """The first proposal's centres by ``rare.starts``: ``(points or None, rollouts, detail)``.

    ``explore``: a margin that is flat far from failure (a loop with integral action converges
    wherever it does not fail) gives the cross-entropy levels nothing to follow, and they can end
    in one part of the failure region only; failure points of a widened law start the fit.
    ``falsifier``: the falsifier's worst run pulled in to the failure boundary
    (:mod:`pfjax.rare.starts`); ``explore`` where the falsifier does not apply or finds no failure.
    ``detail["falsifier_rollouts"]``: the falsifier's gradient rollouts and its rays' rollouts
    (0 where it did not run), part of ``rollouts`` whether or not it found a start."""
    if rare.starts == "none":
        return None, 0, {"starts": "none", "falsifier_rollouts": 0}
    spent, detail = 0, {"falsifier_rollouts": 0}
    if rare.starts == "falsifier":
        from pfjax.rare.starts import pull_in

        found = falsifier()
        if found is not None:
            u_star, used, grads = found
            starts, ray = pull_in(g, u_star, batch=rare.batch)
            spent = used + ray
            detail = {"falsifier_rollouts": spent, "falsifier_gradients": grads, "u_star": u_star.tolist()}
            if len(starts):
                return starts, spent, {"starts": "falsifier", **detail, "start_points": starts.tolist()}
    starts, used = explore(g, dim, n=rare.n_per_level, seed=explore_seed(seed), batch=rare.batch)
    return (starts if len(starts) else None), spent + used, {"starts": "explore", **detail}


def falsifier_rollouts_at_most(spec: StudySpec) -> int:
    """The most rollouts the falsifier's starts spend in one stratum (``starts = "falsifier"``):
    ``n_restarts × steps`` gradient rollouts and ``1 + n_restarts`` rays of :data:`N_RAY`
    (:mod:`pfjax.rare.starts`); 0 where it does not run (other starts, or
    :func:`pfjax.rare.starts.falsifier_applies` false)."""
    if spec.rare_event.starts != "falsifier" or not falsifier_applies(spec, study_inputs(spec)[0]):
        return 0
    f = spec.falsifier
    return f.n_restarts * f.steps + (1 + f.n_restarts) * N_RAY


def rollouts_needed(spec: StudySpec) -> tuple[int, str]:
    """The fewest rollouts per stratum with which ``spec.rare_event.method`` yields an estimate, and
    what they are for: plain Monte Carlo 1; subset simulation ``n_per_level`` (its first level);
    importance sampling the falsifier's rollouts at most (:func:`falsifier_rollouts_at_most`, with
    ``starts = "falsifier"``), ``n_per_level`` for its starts (``explore``, and the fallback of
    ``falsifier``; none for ``none``), ``n_per_level`` for a cross-entropy level and
    ``n_per_level`` draws to estimate from (:func:`pfjax.rare.importance.least_rollouts`)."""
    rare = spec.rare_event
    n = rare.n_per_level
    if rare.method == "mc":
        return 1, "one run"
    if rare.method == "subset":
        return n, f"a first level of n_per_level = {n}"
    least, ce = least_rollouts(n)
    if rare.starts == "none":
        return least, ce
    fals = falsifier_rollouts_at_most(spec)
    if fals:
        f = spec.falsifier
        return fals + n + least, (
            f"{fals} for the falsifier at most ({f.n_restarts} x {f.steps} gradient rollouts and "
            f"{1 + f.n_restarts} rays of {N_RAY}), {n} for the starts where it finds none, {ce}"
        )
    return n + least, f"{n} for the starts, {ce}"


def check_budget(spec: StudySpec) -> None:
    """:class:`~pfjax.errors.InputError` naming ``rare_event.max_rollouts`` when that budget,
    split evenly over the study's strata (:func:`pfjax.rare.transform.study_inputs`), leaves a
    stratum fewer rollouts than its method needs (:func:`rollouts_needed`): refused before anything
    is simulated, not after a stratum has spent them."""
    from pfjax import errors

    rare = spec.rare_event
    strata = len(study_inputs(spec)[1])
    need, what = rollouts_needed(spec)
    if rare.max_rollouts // strata < need:
        raise errors.InputError(
            f"rare_event.max_rollouts: {rare.method} needs at least {need} rollouts per stratum ({what}); the study "
            f"has {strata} strata (paths x choice values), so at least {need * strata} in all, got {rare.max_rollouts}",
            "rare_event.max_rollouts",
        )


def _estimate(g, dim, method, rare, budget, seed, target, falsifier=lambda: None):
    if method == "mc":
        return monte_carlo(g, dim, n=budget, seed=seed, batch=rare.batch)
    if method == "subset":
        n = rare.n_per_level
        return subset_simulation(
            g, dim, n_per_level=n, target_rel_error=target, max_rollouts=max(budget, n), seed=seed, batch=rare.batch
        )
    est = _importance(g, dim, rare, budget, seed, target, falsifier)
    other = _estimate(g, dim, "subset", rare, budget, seed, target) if rare.check == "subset" else None
    return est._replace(detail={**est.detail, "check": reliability(est, other)})


def _importance(g, dim, rare, budget, seed, target, falsifier):
    """Importance sampling of one stratum within ``budget`` (at least :func:`rollouts_needed`, so
    the levels and the estimate have :func:`~pfjax.rare.importance.least_rollouts` left whatever
    the starts spent)."""
    starts, used, how = _starts(g, dim, rare, seed, falsifier)
    est = cross_entropy_is(
        g,
        dim,
        starts=starts,
        n_components=rare.n_components,
        n_per_level=rare.n_per_level,
        n_batch=rare.n_per_level,
        target_rel_error=target,
        max_rollouts=max(budget - used, least_rollouts(rare.n_per_level)[0]),
        seed=seed,
        batch=rare.batch,
    )
    return est._replace(n_rollouts=est.n_rollouts + used, detail={**est.detail, **how})


def drivers(inputs: list[Input], u: np.ndarray, *, least: float = 1.0) -> list[dict]:
    """What drives a failure point ``u`` (``(dim,)``): the inputs at least ``least`` standard
    deviations from their median in ``u`` (the largest first; the farthest one at any rate), each
    ``{"key", "value", "median", "u"}`` (config units; ``u`` in standard deviations of ``u``)."""
    x = to_physical(inputs, np.stack([u, np.zeros_like(u)]))
    order = np.argsort(-np.abs(u), kind="stable")
    keep = [j for j in order if abs(u[j]) >= least] or list(order[:1])
    return [
        {
            "key": inputs[j].key,
            "value": float(x[inputs[j].name][0]),
            "median": float(x[inputs[j].name][1]),
            "u": float(u[j]),
        }
        for j in keep
    ]


def _failure_points(spec: StudySpec, s: Stratum, inputs: list[Input], r: RareEstimate) -> list[dict]:
    """The proposal's modes of one stratum in config units, each with its weight and drivers."""
    modes = r.detail.get("modes")
    if not (modes and inputs and r.p_fail > 0):
        return []
    keys = config_keys(spec)
    means = np.asarray(modes["means"])
    x = to_physical(inputs, means)
    chosen = {keys[k]: v for k, v in s.values.items()}
    return [
        {
            "path": spec.paths[s.path_index].label,
            **chosen,
            **{inp.key: float(x[inp.name][j]) for inp in inputs},
            "weight": s.weight * w,
            "drivers": drivers(inputs, means[j]),
        }
        for j, w in enumerate(modes["weights"])
    ]


def combine(parts: list[tuple[float, RareEstimate]]) -> tuple[float, tuple[float, float], float]:
    """``(p, 95 % interval, relative error)`` of strata ``(weight, estimate)`` (module docstring):
    ``p = Σ w_s p_s``; one stratum keeps its own interval and relative error; otherwise the strata
    with ``p_s > 0`` and a finite relative error give the lognormal interval of their sum, and
    every other stratum adds ``w_s lo_s`` and ``w_s hi_s`` to its ends (the top cut at 1) and makes
    the relative error infinite."""
    if len(parts) == 1:
        w, r = parts[0]
        return w * r.p_fail, (w * r.ci95[0], min(1.0, w * r.ci95[1])), r.rel_error
    p = sum(w * r.p_fail for w, r in parts)
    known = [(w, r) for w, r in parts if r.p_fail > 0 and math.isfinite(r.rel_error)]
    unknown = [(w, r) for w, r in parts if not (r.p_fail > 0 and math.isfinite(r.rel_error))]
    p_known = sum(w * r.p_fail for w, r in known)
    rel = math.sqrt(sum((w * r.p_fail * r.rel_error) ** 2 for w, r in known)) / p_known if known else math.inf
    lo, hi = lognormal_interval(p_known, rel) if known else (0.0, 0.0)
    lo += sum(w * r.ci95[0] for w, r in unknown)
    hi += sum(w * r.ci95[1] for w, r in unknown)
    return p, (lo, min(1.0, hi)), (math.inf if unknown else rel)


def no_failures(r: RareEstimate) -> dict:
    """The flag of a stratum whose estimate is 0 (no failing draw seen): ``status`` ``"no_failures"``
    and a warning giving the rollouts spent and what bounds ``p`` there: plain Monte Carlo's exact
    interval has an upper end; importance sampling and subset simulation, whose proposal or
    levels never reached the failure region, give none (their interval reaches 1)."""
    if r.method == "mc":
        bound = f"p_fail is 0 with a 95 % upper bound of {r.ci95[1]:.3g} (exact binomial)"
    else:
        bound = f"p_fail is 0 and {r.method} gives no bound (its levels never reached the failure region)"
    return {"status": "no_failures", "warning": f"no failure found in {r.n_rollouts} rollouts: {bound}"}


def estimate_controller(spec: StudySpec, name: str, controller, *, progress=None) -> dict:
    """One controller's failure probability under ``spec.rare_event`` (module docstring).

    Returns:
        ``{"p_fail", "ci95", "rel_error", "n_rollouts", "method", "wall_s", "status", "warning",
        "strata", "failure_points"}``: ``ci95`` ``[lo, hi]``, ``wall_s`` s; ``rel_error``
        infinite where a stratum's is (:func:`combine`); ``status`` and
        ``warning`` the checks' verdict (module docstring; each stratum's ``check`` beside it,
        whose second estimate's rollouts are not in ``n_rollouts``; subset simulation's
        ``run_estimates`` per stratum and its ``error``, what its interval rests on:
        :mod:`pfjax.rare.subset`); each stratum's ``falsifier_rollouts`` (rollouts, the
        falsifier's gradient rollouts and its rays', 0 where it did not run; part of the stratum's
        ``n_rollouts`` and of the budget); ``failure_points`` the
        importance-sampling proposal's modes in the inputs' config units (its weight beside each),
        the failure modes it found (:mod:`pfjax.rare.importance`), each with its ``drivers`` (:func:`drivers`;
        ``[]`` for the other methods).
    """
    rare = spec.rare_event
    check_budget(spec)
    inputs, strata = study_inputs(spec)
    dim = max(1, len(inputs))
    budget = rare.max_rollouts // len(strata)
    t0 = time.time()
    parts: list[tuple[Stratum, RareEstimate]] = []
    for k, s in enumerate(strata):
        g = limit_state(spec, s, inputs, controller, seed=rare.seed, stream=k, counter=progress)
        seed = stratum_seed(rare.seed, k)
        fals = partial(falsifier_points, spec, s, inputs, controller, seed=seed)
        parts.append((s, _estimate(g, dim, rare.method, rare, budget, seed, rare.target_rel_error, fals)))
    p, ci, rel = combine([(s.weight, r) for s, r in parts])
    points, keys = [q for s, r in parts for q in _failure_points(spec, s, inputs, r)], config_keys(spec)
    checks = [(spec.paths[s.path_index].label, r.detail["check"]) for s, r in parts if "check" in r.detail]
    flagged = [(label, c) for label, c in checks if c["status"] != "ok"]
    flagged += [(spec.paths[s.path_index].label, no_failures(r)) for s, r in parts if r.p_fail == 0]
    return {
        "p_fail": float(p),
        "ci95": [float(ci[0]), float(ci[1])],
        "rel_error": float(rel),
        "n_rollouts": int(sum(r.n_rollouts for _, r in parts)),
        "method": rare.method,
        "wall_s": time.time() - t0,
        "status": flagged[0][1]["status"] if flagged else "ok",
        "warning": "; ".join(f"{label}: {c['warning']}" for label, c in flagged) or None,
        "strata": [
            {
                "path": spec.paths[s.path_index].label,
                "values": {keys[k]: v for k, v in s.values.items()},
                "weight": s.weight,
                **{k: v for k, v in r._asdict().items() if k != "detail"},
                "falsifier_rollouts": int(r.detail.get("falsifier_rollouts", 0)),
                **{k: r.detail[k] for k in ("check", "run_estimates", "error") if k in r.detail},
            }
            for s, r in parts
        ],
        "failure_points": sorted(points, key=lambda q: -q["weight"]),
    }


def estimate_study(spec: StudySpec, controllers: dict, *, names=None, progress: bool | None = None) -> dict:
    """:func:`estimate_controller` for every controller of ``controllers`` (``{name: (ctrl, gains,
    flat)}``, :func:`pfjax.montecarlo.runner.controllers_of`) named in ``names`` (default all), in
    the study's precision, with one progress bar of rollouts on stderr (``progress``: default when
    stderr is a terminal)."""
    from tqdm import tqdm

    from pfjax.montecarlo.runner import precision

    names = list(controllers) if names is None else list(names)
    out = {}
    total = spec.rare_event.max_rollouts * len(names)
    disable = None if progress is None else not progress
    with precision(spec), tqdm(total=total, desc=f"{spec.name}: rare events", unit="run", disable=disable) as bar:
        for name in names:
            bar.set_postfix_str(name)
            out[name] = estimate_controller(spec, name, controllers[name], progress=bar.update)
    return out
