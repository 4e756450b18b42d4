"""The rare-event estimators verified and measured (docs/rare-events.md, *Measured*): against a
failure probability known independently, against plain Monte Carlo, their interval coverage, and
the certification study ``studies/rare_events.toml``; :func:`run` writes ``verification.json``.

Parts of the result (each estimate as :func:`estimate` keeps it: ``p_fail``, ``ci95``, ``rel_error``,
``n_rollouts``, ``method``, ``status``, ``warning``, ``strata``, ``failure_points``, ``wall_s``):

* ``known``: state feedback :data:`K` on a straight line under constant Gaussian slip of standard
  deviation ``s`` (:data:`KNOWN_STD`) from zero initial error (:func:`known_case`): the reference
  is :func:`pfjax.rare.reference.line_offset_failure_probability`, at ``p`` about 1e-4, 1e-6 and
  1e-8, by importance sampling and subset simulation to 10 %; plain Monte Carlo (``mc_known``
  runs) at 1e-4. Each estimate's ``holds_reference``: its 95 % interval holds the reference.
* ``starts``: importance sampling at ``p`` about 1e-6 on the known case from the falsifier's
  failure points (``falsifier``), from failure points of a widened law (``explore``) and from
  ``N(0, I)`` (``none``), seeds ``0 ... start_seeds - 1`` (:func:`starts_comparison`).
* ``coverage``: independent repeats at ``p`` about 1e-4 on the known case, seeds
  :data:`COVERAGE_SEED` + ``i``: the share of 95 % intervals holding the reference
  (:func:`coverage`); for subset simulation also its runs' spread (:func:`run_spread`).
* ``study``: every controller of the study by importance sampling and subset simulation, for its
  own failure (``path``) and for leaving the :data:`BAND` (``band``), there also by plain Monte
  Carlo with ``mc_study`` runs (:func:`study`).
* ``sine_check``: ``pi-table3`` on the sine alone by plain Monte Carlo (``mc_sine`` runs),
  importance sampling and subset simulation (:func:`sine_check`).

The sizes (:data:`FULL`, :data:`QUICK`) fix the repeats (``coverage_repeats``,
``subset_repeats``, ``start_seeds``), the starts compared (``starts``), the plain Monte Carlo runs
(``mc_known``, ``mc_study``, ``mc_sine``) and the budgets: the known case's ``[rare_event]``
budget (``known_budget``: ``n_per_level``, ``batch``, ``max_rollouts``) and ``[falsifier]``
settings (``known_falsifier``, empty: the defaults), and overrides of the study's ``[rare_event]``
(``study_budget``, empty: the study's own). The result carries the provenance record
(:func:`pfjax.provenance.stamp`) of :func:`verification_config` and a ``units`` map by field name
(:func:`units`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from pfjax.jsonio import dumps
from pfjax.montecarlo.config import StudySpec, load_study, study_hash
from pfjax.montecarlo.runner import controllers_of
from pfjax.outputs import OutputDir
from pfjax.provenance import STAMP_UNITS, stamp
from pfjax.rare.reference import line_offset_failure_probability
from pfjax.rare.study import check_budget, estimate_study
from pfjax.rare.study import units as estimate_units

#: the known case's state feedback ``[k_d rad/m, k_θ rad/rad]`` (the default state feedback)
K = [-2.7381, -2.0772]
#: slip standard deviations (deg) putting the known case's ``p`` near 1e-4, 1e-6 and 1e-8
KNOWN_STD = {"1e-4": 1.372, "1e-6": 1.091, "1e-8": 0.931}
#: the band (m) of the study's second failure definition, beside its own threshold (leaving the path)
BAND = 0.05
#: the seed of the first coverage repeat (repeat ``i``: ``COVERAGE_SEED + i``)
COVERAGE_SEED = 1000
#: ``rare_event.seed`` of the known case's estimates (its default; the study keeps its own)
SEED = 0
#: the sizes of docs/rare-events.md's measurements
FULL: dict = {
    "coverage_repeats": 50,
    "subset_repeats": 50,
    "mc_known": 1_000_000,
    "mc_study": 600_000,
    "start_seeds": 3,
    "starts": ["falsifier", "explore", "none"],
    "mc_sine": 1_000_000,
    "known_budget": {"n_per_level": 2000, "batch": 2000, "max_rollouts": 400_000},
    "known_falsifier": {},
    "study_budget": {},
}
#: small sizes (tests and ``--quick``): every part on budgets of a few thousand rollouts
QUICK: dict = {
    "coverage_repeats": 4,
    "subset_repeats": 2,
    "mc_known": 2_000,
    "mc_study": 300,
    "start_seeds": 1,
    "starts": ["falsifier", "explore", "none"],
    "mc_sine": 300,
    "known_budget": {"n_per_level": 100, "batch": 32, "max_rollouts": 1_000},
    "known_falsifier": {"n_restarts": 2, "steps": 5},
    "study_budget": {"n_per_level": 100, "batch": 32, "max_rollouts": 900},
}

#: The units of the verification's own numbers by field name ("1": dimensionless); an estimate's
#: are :data:`pfjax.rare.study.UNITS`, the stamp's :data:`pfjax.provenance.STAMP_UNITS` (:func:`units`).
UNITS: dict[str, str] = {
    "std_deg": "deg (standard deviation of the constant slip on each axle)",
    "reference": "probability per run (the known case's, pfjax.rare.reference.line_offset_failure_probability)",
    "repeats": "independent estimates",
    "coverage": "1 (share of the repeats' 95 % intervals that hold the reference)",
    "mean_estimate_over_reference": "1 (mean p_fail of the repeats over the reference)",
    "mean_rel_error": "1 (mean rel_error of the repeats)",
    "mean_rollouts": "rollouts (mean n_rollouts of the repeats)",
    "estimates": "probability per run (each repeat's p_fail)",
    "n_runs": "subset-simulation runs (inside the repeats)",
    "observed_cov": "1 (coefficient of variation of the runs' p)",
    "delta_uncorrelated_rms": "1 (root mean square of the runs' delta_uncorrelated)",
    "delta_correlated_rms": "1 (root mean square of the runs' delta_correlated)",
}

Log = Callable[[str], None]


def known_case(std_deg: float, budget: dict, falsifier: dict | None = None) -> dict:
    """The known case's study config (a dict) at slip standard deviation ``std_deg`` (deg), its
    ``[rare_event]`` budget ``budget`` (``n_per_level``, ``batch``, ``max_rollouts``) and, where
    given, its ``[falsifier]`` settings (``n_restarts``, ``steps``: the falsifier's starts)."""
    slip = {"dist": "truncnormal", "mean": 0.0, "std": std_deg, "low": -30.0, "high": 30.0}
    config = {
        "name": "rare-line",
        "n_runs": 1,
        "seed": 0,
        "dtype": "float64",
        "sim": {"horizon": 8.0, "dt": 0.01, "steady_window": 2.0},
        "success": {"band": 0.05, "from_s": 6.0},
        "slip": {"beta_r_deg": slip, "beta_f_deg": slip},
        "margin": {"enabled": False},
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "state-feedback", "type": "state_feedback", "K": K}],
        "rare_event": {"enabled": True, **budget},
    }
    return {**config, "falsifier": falsifier} if falsifier else config


def references() -> dict[str, float]:
    """The known case's failure probability per label of :data:`KNOWN_STD`."""
    return {label: line_offset_failure_probability(K, std) for label, std in KNOWN_STD.items()}


def verification_config(sizes: dict, study_spec: StudySpec) -> dict:
    """Everything the result depends on (JSON-able): the sizes, :data:`K`, :data:`KNOWN_STD`,
    :data:`BAND`, :data:`COVERAGE_SEED`, and the study's name and SHA-256
    (:func:`pfjax.montecarlo.config.study_hash`, without ``study_budget``)."""
    return {
        "sizes": sizes,
        "K": K,
        "known_std_deg": KNOWN_STD,
        "band": BAND,
        "coverage_seed": COVERAGE_SEED,
        "study": {"name": study_spec.name, "config_sha256": study_hash(study_spec)},
    }


def units(known_spec: StudySpec, study_spec: StudySpec) -> dict[str, str]:
    """The result's ``units``: :data:`UNITS`, the stamp's and the estimates' of both studies
    (:func:`pfjax.rare.study.units`: their inputs' config keys; not the study config's threshold,
    whose config this file does not hold)."""
    both = {**estimate_units(known_spec), **estimate_units(study_spec)}
    both.pop("config.rare_event.threshold")
    return {**STAMP_UNITS, **both, **UNITS}


def estimate(config, name: str, *, paths: list | None = None, **rare) -> dict:
    """Controller ``name``'s failure probability in the study ``config`` (a TOML path or a config
    dict), ``rare`` overriding its ``[rare_event]`` settings (``method``, ``seed``,
    ``max_rollouts``, ``threshold``, ...) and ``paths`` its paths, computed as
    :func:`pfjax.rare_event` computes it (:func:`pfjax.rare.study.estimate_study`, after
    :func:`pfjax.rare.study.check_budget`): the estimate's fields and ``wall_s``, the call's wall
    time (s)."""
    t0 = time.time()
    values = {f"rare_event.{k}": v for k, v in rare.items()}
    if paths is not None:
        values["paths"] = paths
    spec = _spec(config, values)
    check_budget(spec)
    r = estimate_study(spec, controllers_of(spec), names=[name], progress=False)[name]
    keep = ("p_fail", "ci95", "rel_error", "n_rollouts", "method", "status", "warning", "strata", "failure_points")
    r = {k: r[k] for k in keep}
    r["wall_s"] = time.time() - t0
    return r


def holds(r: dict, p: float) -> bool:
    """Whether estimate ``r``'s 95 % interval holds ``p``."""
    return r["ci95"][0] <= p <= r["ci95"][1]


def coverage(rs: list[dict], p: float) -> dict:
    """Repeated estimates ``rs`` of reference ``p``: ``repeats``, ``coverage`` (the share whose 95 %
    interval holds ``p``), ``mean_estimate_over_reference``, ``mean_rel_error``, ``mean_rollouts``
    and each repeat's ``estimates`` (``p_fail``), ``ci95``, ``rel_error``, ``n_rollouts`` and
    ``holds_reference``."""
    n = len(rs)
    hits = [holds(r, p) for r in rs]
    return {
        "reference": p,
        "repeats": n,
        "coverage": sum(hits) / n,
        "mean_estimate_over_reference": sum(r["p_fail"] for r in rs) / n / p,
        "mean_rel_error": sum(r["rel_error"] for r in rs) / n,
        "mean_rollouts": sum(r["n_rollouts"] for r in rs) / n,
        "estimates": [r["p_fail"] for r in rs],
        "ci95": [r["ci95"] for r in rs],
        "rel_error": [r["rel_error"] for r in rs],
        "n_rollouts": [r["n_rollouts"] for r in rs],
        "holds_reference": hits,
    }


def run_spread(rs: list[dict]) -> dict:
    """Every independent subset-simulation run inside the repeats ``rs`` (one stratum): the observed
    coefficient of variation of the runs' estimates ``p`` beside the root-mean-square of each run's
    levels-uncorrelated error ``sqrt(Σ δ_j²)`` and of its fully-correlated bound ``Σ δ_j``, with the
    runs' ``p``, ``delta_uncorrelated`` and ``delta_correlated``."""
    runs = [run for r in rs for run in r["strata"][0]["run_estimates"]]
    ps = np.asarray([run["p"] for run in runs])
    lo = np.asarray([run["delta_uncorrelated"] for run in runs])
    hi = np.asarray([run["delta_correlated"] for run in runs])
    return {
        "n_runs": len(runs),
        "observed_cov": float(ps.std(ddof=1) / ps.mean()),
        "delta_uncorrelated_rms": float(np.sqrt(np.mean(np.square(lo)))),
        "delta_correlated_rms": float(np.sqrt(np.mean(np.square(hi)))),
        "p": ps.tolist(),
        "delta_uncorrelated": lo.tolist(),
        "delta_correlated": hi.tolist(),
    }


def known(sizes: dict, refs: dict[str, float], log: Log) -> dict:
    """The known case at each :data:`KNOWN_STD` by importance sampling and subset simulation to
    10 %, and by plain Monte Carlo (``mc_known`` runs) at 1e-4."""
    out = {}
    for label, std in KNOWN_STD.items():
        p, config = refs[label], known_case(std, sizes["known_budget"])
        entry: dict = {"std_deg": std, "reference": p}
        for method in ("is", "subset"):
            entry[method] = r = estimate(config, "state-feedback", method=method, target_rel_error=0.1)
            r["holds_reference"] = holds(r, p)
            log(f"known {label} {method}: {r['p_fail']:.3g} vs {p:.3g} ({r['n_rollouts']} rollouts)")
        if label == "1e-4":
            entry["mc"] = r = estimate(config, "state-feedback", method="mc", max_rollouts=sizes["mc_known"])
            r["holds_reference"] = holds(r, p)
        out[label] = entry
    return out


def starts_comparison(sizes: dict, p: float, log: Log) -> dict:
    """Importance sampling on the known case at 1e-6 (reference ``p``) started from the falsifier's
    failure points, from failure points of a widened law, and from ``N(0, I)``: rollouts to 10 %
    (seeds ``0 ... start_seeds - 1``)."""
    config = known_case(KNOWN_STD["1e-6"], sizes["known_budget"], sizes["known_falsifier"])
    out: dict = {"reference": p}
    for how in sizes["starts"]:
        rs = [estimate(config, "state-feedback", method="is", seed=s, starts=how) for s in range(sizes["start_seeds"])]
        out[how] = {
            "n_rollouts": [r["n_rollouts"] for r in rs],
            "p_fail": [r["p_fail"] for r in rs],
            "rel_error": [r["rel_error"] for r in rs],
            "wall_s": [r["wall_s"] for r in rs],
            "holds_reference": [holds(r, p) for r in rs],
        }
        log(f"starts {how}: {out[how]['n_rollouts']}")
    return out


def repeats(sizes: dict, p: float, log: Log) -> dict:
    """Independent repeats at 1e-4 on the known case (reference ``p``), seeds ``COVERAGE_SEED + i``:
    ``coverage_repeats`` by importance sampling and ``subset_repeats`` by subset simulation
    (:func:`coverage`; subset simulation's also :func:`run_spread` under ``runs``)."""
    config = known_case(KNOWN_STD["1e-4"], sizes["known_budget"])
    out = {}
    for method, n in (("is", sizes["coverage_repeats"]), ("subset", sizes["subset_repeats"])):
        rs = [
            estimate(config, "state-feedback", method=method, seed=COVERAGE_SEED + i, target_rel_error=0.1)
            for i in range(n)
        ]
        out[method] = coverage(rs, p)
        if method == "subset":
            out[method]["runs"] = run_spread(rs)
        log(f"coverage {method}: {sum(out[method]['holds_reference'])}/{n}")
    return out


def _short(estimates: dict) -> dict[str, str]:
    """Each method's ``p_fail`` to three digits (the progress lines)."""
    return {m: f"{r['p_fail']:.3g}" for m, r in estimates.items()}


def _spec(study_config, values: dict | None = None) -> StudySpec:
    """The validated study of ``study_config`` (a TOML path or a config dict), ``values`` (dotted
    keys) overriding."""
    if isinstance(study_config, dict):
        return load_study(data=study_config, values=values)[0]
    return load_study(Path(study_config), values=values)[0]


def _budget(sizes: dict) -> dict:
    """``study_budget``: the study's ``[rare_event]`` settings overridden (``max_rollouts``, ...);
    a method's own ``max_rollouts`` (plain Monte Carlo's) replaces its ``max_rollouts``."""
    return dict(sizes["study_budget"])


def study(study_config, names: list[str], sizes: dict, log: Log) -> dict:
    """Each controller ``names`` of the study (a TOML path or a config dict, as
    :func:`pfjax.rare_event` takes it) by importance sampling and subset
    simulation: leaving the path (``path``) and leaving the :data:`BAND` (``band``), there also by
    plain Monte Carlo with ``mc_study`` runs."""
    budget, out = _budget(sizes), {}
    for name in names:
        path = {m: estimate(study_config, name, method=m, **budget) for m in ("is", "subset")}
        band = {m: estimate(study_config, name, method=m, threshold=BAND, **budget) for m in ("is", "subset")}
        band["mc"] = estimate(
            study_config, name, **{**budget, "method": "mc", "max_rollouts": sizes["mc_study"]}, threshold=BAND
        )
        out[name] = {"path": path, "band": band}
        log(f"{name} {_short(path)} {_short(band)}")
    return out


def sine_check(study_config, sizes: dict, log: Log) -> dict:
    """``pi-table3`` leaving the path on the sine alone by plain Monte Carlo (``mc_sine`` runs),
    importance sampling and subset simulation."""
    budget = _budget(sizes)
    out = {
        m: estimate(study_config, "pi-table3", paths=[{"kind": "sine"}], **{**budget, "method": m, **kw})
        for m, kw in (("mc", {"max_rollouts": sizes["mc_sine"]}), ("is", {}), ("subset", {}))
    }
    log(f"sine check {_short(out)}")
    return out


def run(
    sizes: dict, out: str | Path, study_config: str | Path | dict, *, overwrite: bool = False, log: Log = print
) -> dict:
    """Every part (module docstring) at ``sizes`` for the study ``study_config`` (a TOML path or a
    config dict; ``studies/rare_events.toml`` for docs/rare-events.md, with a ``pi-table3``
    controller and a sine path),
    written to ``out/verification.json`` through :class:`pfjax.outputs.OutputDir` (``overwrite``:
    replace another command's or config's output); a line per part to ``log``. Returns the result:
    the provenance record (:func:`pfjax.provenance.stamp` of :func:`verification_config`, seed
    :data:`SEED`), ``config``, ``units``, ``known``, ``starts``, ``coverage``, ``study``,
    ``sine_check`` and ``wall_s`` (s, in all)."""
    t0 = time.time()
    study_spec = _spec(study_config)
    budget = {f"rare_event.{k}": v for k, v in _budget(sizes).items()}
    names = [c.name for c in _spec(study_config, budget).controllers]
    known_spec = load_study(data=known_case(KNOWN_STD["1e-4"], sizes["known_budget"]))[0]
    config = verification_config(sizes, study_spec)
    result: dict = {**stamp(config, SEED), "config": config, "units": units(known_spec, study_spec)}
    marker = {"seed": SEED}
    with OutputDir(
        out, command="rare-events", config_sha256=result["config_sha256"], overwrite=overwrite, extra=marker
    ) as output:
        refs = references()
        result["known"] = known(sizes, refs, log)
        result["starts"] = starts_comparison(sizes, refs["1e-6"], log)
        result["coverage"] = repeats(sizes, refs["1e-4"], log)
        result["study"] = study(study_config, names, sizes, log)
        result["sine_check"] = sine_check(study_config, sizes, log)
        result["wall_s"] = time.time() - t0
        (output.staging / "verification.json").write_text(dumps(result, indent=1) + "\n")
        output.commit()
    return result
