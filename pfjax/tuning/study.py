"""The tuning study: GA vs gradient tuners over seeds and problems, ablation, Table 3 check, robust designs.

Part 1 runs, for every problem in ``compare.problems`` (controller, scenario set, cost) and every
seed, the GA (``[ga]``), the multi-start gradient tuner (``pfjax tune --method gradient``,
settings in ``[multistart]``) and plain projected adam (``gradient-plain``, ``[gradient]``); on the
first problem also ``ga+gradient``, and on every problem of ``compare.ablate_problems`` the
ablation variants of ``compare.ablation`` (the multi-start tuner with one ingredient changed).
Part 1b runs ``pfjax tune --method gradient`` and ``--method ga`` on the command line's problem (5
ms step, 20 s) with the ``[ga]`` and ``[multistart]`` settings for the first ``cli_seeds`` seeds:
the command line's defaults when those are the published sizes (the report lists any setting that
differs). Parts 2 and 3 (:mod:`pfjax.tuning.study_parts`): K tuned on one scenario and on a
training sample, the LMI designs, and every controller on one held-out Monte Carlo set. ``[sim]``
sets the step and horizon of the paper-* problems, of the training sets and of the held-out set.

:func:`run` writes ``summary.json`` (every number's unit in its ``units`` map, :func:`summary_units`),
``tuning_runs.parquet`` (cost history of every tuning run),
``heldout.parquet`` (one row per held-out run and controller), ``margin.parquet`` (the slip-margin
sweep's successes ``k`` of ``n`` runs per controller, axis and amplitude), ``figures/*.png|svg`` and
``report.md`` / ``report.html`` (:mod:`pfjax.tuning.study_report`).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pfjax.montecarlo.summary import UNITS as MONTE_CARLO_UNITS
from pfjax.numerics.random import seed_key
from pfjax.provenance import STAMP_UNITS
from pfjax.tables import H2_CHANNELS, HINF_CHANNELS
from pfjax.tuning.study_config import TuningStudy, ga_options, heldout_study, methods, problem_list

#: The units of ``tuning_runs.parquet``'s columns (:func:`pfjax.tables.write_parquet`): every
#: problem's cost is an IAE (paper-*: the mean over its runs; heldout-cvar: the CVaR), in m s.
COLUMNS: dict[str, tuple[str, str]] = {
    "problem": ("", "CONTROLLER:SCENARIO of compare.problems"),
    "method": ("", "tuning method (gradient:<variant>: an ablation variant)"),
    "seed": ("", "PRNG seed of the run"),
    "iteration": ("", "GA generation or gradient step (0: the first evaluations)"),
    "best_cost": ("m s", "best cost so far: IAE over the problem's runs (mean or CVaR), a failed run +100"),
    "rollouts": ("", "rollouts simulated so far"),
    "wall_s": ("s", "wall time so far, compilation excluded"),
}

#: A tuning cost (:mod:`pfjax.tuning.cost`), as :data:`COLUMNS`'s ``best_cost``.
_COST = f"{COLUMNS['best_cost'][0]} (IAE over the problem's runs: mean, heldout-cvar the CVaR; a failed run +100)"
_PASSES = "forward-pass equivalents (a value-only rollout 1, one with its gradient 1 + D forward mode, 4 reverse)"

#: ``summary.json``'s units by field name (a field has one meaning wherever it occurs; "1":
#: dimensionless; a block's key names the unit of every number under it), written as
#: ``summary["units"]``; the held-out table's as in ``pfjax study``'s summary
#: (:data:`pfjax.montecarlo.summary.UNITS`).
SUMMARY_UNITS: dict[str, object] = {
    **STAMP_UNITS,
    "wall_s": "s (wall clock: the whole study; of a tuning run, compilation excluded)",
    "compile_s": "s (ahead-of-time compilation, not in wall_s)",
    # part 1: the tuning runs, the Table 3 check and the local checks
    **dict.fromkeys(("cost", "descent_cost", "median", "min", "max", "ga_median", "ga_best"), _COST),
    **dict.fromkeys(("ga_costs", "gradient_costs"), _COST),
    "n_rollouts": MONTE_CARLO_UNITS["n_rollouts"],
    **dict.fromkeys(("rollouts", "ga_rollouts"), f"{MONTE_CARLO_UNITS['n_rollouts']} of one tuning run"),
    **dict.fromkeys(("n_forward_passes", "forward_passes"), _PASSES),
    "n_nonfinite_grad": "gradient components (not finite, replaced by 0)",
    "gradient": f"{COLUMNS['best_cost'][0]} per gain unit (table3: d cost / d gain, in the order of the tuned "
    "gains kp_d, ki_d, kp_theta, ki_theta); "
    "elsewhere the gradient tuner's block, its numbers by their own keys",
    "projected_gradient_norm": f"{COLUMNS['best_cost'][0]} per box width (gains normalised to the tuning box)",
    **dict.fromkeys(
        ("eigenvalues", "check_eigenvalues"),
        f"{COLUMNS['best_cost'][0]} per box width^2 (the cost's Hessian on the free coordinates)",
    ),
    **dict.fromkeys(
        ("probe_decrease", "check_probe_decrease"), "1 (largest (J - J_probe) / |J| over the probes; <= 0: none lower)"
    ),
    "active": "1 (per gain: -1 on the lower bound, +1 on the upper bound, 0 free)",
    "descent_steps": "adam steps",
    "descent_lr": "normalised box units (adam step)",
    "relative_decrease": "1 (1 - descent_cost / cost)",
    # part 2: K, the LMI designs
    "K": "rad/m, rad/rad (delta = K [d, theta_e]); integral designs rad/m, rad/rad, rad/(m s) (K [d, theta_e, int d])",
    "train_cost": f"{COLUMNS['best_cost'][0]} (mean IAE over the paper line's or the training set's runs, a failed run +100)",
    "rollouts_per_eval": "rollouts per cost evaluation",
    "gamma_inf": f"H-infinity bound {HINF_CHANNELS}",
    "hinf_norm": f"H-infinity norm {HINF_CHANNELS}, the largest over the design's plants",
    "gamma_2": f"H2 bound {H2_CHANNELS}",
    "h2_norm": f"H2 norm {H2_CHANNELS}, the largest over the design's plants",
    "closed_loop_poles": "1/s ([real, imaginary] per pole)",
    "max_vertex_pole_real": "1/s (largest real part of a closed-loop pole over the design's plants)",
    "alpha": "1 (weight of gamma_inf^2)",
    "beta": "1 (weight of gamma_2^2)",
    "steer_bound": "rad (largest |K x| on the invariant ellipsoid)",
    # part 3: the held-out evaluation
    "n_per_path": "runs (held-out runs per path and controller)",
    "margin_runs": "runs (per slip amplitude, path and controller in the margin sweep)",
    **{k: MONTE_CARLO_UNITS[k] for k in ("success_rate", "success_ci95", "iae_mean", "iae_p95", "slip_margin_deg")},
    "steady_abs_d_p95_mm": "mm (95th percentile of steady_abs_d over runs with status ok)",
    "n": "runs in heldout.table (a controller's held-out runs); seeds in targets.by_problem (tuning runs)",
    # the targets
    "wins_needed": "seeds (a tuner must win)",
    "wins": "seeds (with a cost at most the GA's median)",
    **dict.fromkeys(("rollout_fraction", "forward_pass_fraction"), "1 (ratio to the GA's)"),
    **dict.fromkeys(("wall_s_median", "ga_wall_s_median"), "s (median over seeds, compilation excluded)"),
    **dict.fromkeys(("dt", "horizon"), "s"),
    "changed": "the setting's unit (pfjax.tuning.study_config: a count, or normalised box units)",
    "gradient_over_ga_best": "1 (cost / ga_best - 1)",
    "integral_steady_abs_d_m": "m (largest steady_abs_d of the integral design under three constant slips)",
}


def summary_units(cfg: dict, types=()) -> dict:
    """:data:`SUMMARY_UNITS` with the gains' units by controller (:func:`pfjax.controllers.gain_units`;
    a gain's name has other units in other controllers): ``gains`` for each controller of
    ``compare.problems`` (a problem's name before ``:``), the Table 3 check's ``pi`` and ``types``
    (the held-out rows' ``type``), ``descent_gains`` for the ``pi`` (the Table 3 check's descent)."""
    from pfjax import controllers as C

    problems = (p.partition(":")[0] for p in problem_list(cfg["compare"]["problems"]))
    names = dict.fromkeys(["pi", *problems, *types])
    by = {n: C.gain_units(C.entry(n)) for n in names}
    return {**SUMMARY_UNITS, "gains": by, "descent_gains": {"pi": by["pi"]}}


def make_study_problem(cfg: dict, name: str):
    """``controller:scenario`` -> Problem at ``[sim]``'s step and horizon. ``heldout-cvar``: CVaR of
    IAE over the held-out study's distribution, ``compare.cvar_runs`` runs per path with run indices
    disjoint from the held-out runs (:func:`pfjax.tuning.study_parts.training_problem`)."""
    from pfjax.sim import SimConfig
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.problem import make_problem
    from pfjax.tuning.study_parts import training_problem

    controller, _, scenario = name.partition(":")
    if scenario == "heldout-cvar":
        cost = CostSpec(aggregate="cvar", level=cfg["compare"]["cvar_level"])
        return training_problem(cfg, controller, cfg["compare"]["cvar_runs"], cost)
    sim = SimConfig(dt=cfg["sim"]["dt"], horizon=cfg["sim"]["horizon"], record=False)
    return make_problem(controller, scenario, config=sim)


def _run_row(problem_name, method, seed, r, pr) -> dict:
    from pfjax.tuning.problem import reported_gains

    return {
        "problem": problem_name,
        "method": method,
        "seed": seed,
        "cost": float(r.cost),
        "n_rollouts": int(r.n_rollouts),
        "n_forward_passes": int(r.n_forward_passes),
        "wall_s": float(r.wall_s),
        "compile_s": float(r.compile_s),
        "gains": reported_gains(problem_name.partition(":")[0], pr, r.theta),
        "n_nonfinite_grad": int(r.n_nonfinite_grad),
    }


def _history_rows(problem_name, method, seed, r) -> list[dict]:
    return [
        {
            "problem": problem_name,
            "method": method,
            "seed": seed,
            "iteration": it,
            "best_cost": c,
            "rollouts": int(n),
            "wall_s": t,
        }
        for it, (c, n, t) in enumerate(zip(r.history, r.history_rollouts, r.history_wall_s))
    ]


def compare(cfg: dict, progress: bool):
    """Every method on every problem and seed (module docstring); returns (histories, runs, problems)."""
    from pfjax.tuning.problem import tune

    opts = ga_options(cfg)
    rows, runs, problems = [], [], {}
    for i, name in enumerate(problem_list(cfg["compare"]["problems"])):
        pr = problems[name] = make_study_problem(cfg, name)
        for label, kw in methods(cfg, name, i == 0).items():
            for seed in range(cfg["seeds"]):
                # shared_programs=False: the seeds reuse one program per batch shape (chain count, GA
                # population and children), compiled once
                r = tune(pr, key=seed_key(seed), ga_options=opts, shared_programs=False, progress=progress, **kw)
                runs.append(_run_row(name, label, seed, r, pr))
                rows += _history_rows(name, label, seed, r)
            c = [x["cost"] for x in runs if x["problem"] == name and x["method"] == label]
            print(
                f"  {name} {label}: median cost {np.median(c):.5f} (min {min(c):.5f}, max {max(c):.5f}) over "
                f"{len(c)} seeds, {runs[-1]['n_rollouts']} rollouts per seed",
                flush=True,
            )
    return pd.DataFrame(rows), runs, problems


def heldout_spec(cfg: dict):
    """The held-out Monte Carlo study at the study's sizes, step and horizon
    (:func:`pfjax.tuning.study_config.heldout_study`)."""
    return heldout_study(cfg)


def heldout_hash(spec) -> str:
    """The config hash of the held-out study as the tuning study loads it (its file, at the study's
    sizes)."""
    from pfjax.provenance import config_hash

    return config_hash(json.loads(spec.model_dump_json()))


def study_hash(cfg: dict, spec=None) -> str:
    """The tuning study's config hash: of its config and of the held-out study it reads
    (``spec``, else loaded from ``cfg["heldout"]``), whose file can change under the same path."""
    from pfjax.provenance import config_hash

    return config_hash({**cfg, "heldout_config_sha256": heldout_hash(spec if spec is not None else heldout_spec(cfg))})


def heldout_summary(cfg: dict, spec, table: list) -> dict:
    """The summary's ``heldout`` section: the held-out study, its paths and margin sweeps, ``table``."""
    from pfjax.tuning.study_config import MARGIN_AXIS

    return {
        "study": cfg["heldout"],
        "seed": spec.seed,
        "n_per_path": cfg["robust"]["heldout_runs"],
        "paths": [p.label for p in spec.paths],
        "margin_runs": cfg["robust"]["margin_runs"],
        "margin_axis": MARGIN_AXIS,
        "margin_axes": list(spec.margin.axes),
        "config_sha256": heldout_hash(spec),
        "table": table,
    }


def write_tables(tables: dict, out: Path, meta: dict) -> None:
    """``<name>.parquet`` of every frame in ``tables`` into ``out``, each column with its unit
    (:data:`COLUMNS`, then :data:`pfjax.tables.COLUMNS`) and ``meta``."""
    from pfjax.tables import write_parquet

    for name, frame in tables.items():
        write_parquet(frame, out / f"{name}.parquet", meta, units=COLUMNS)


def _parts(cfg: dict, spec, progress: bool):
    """Every part of the study: (histories, summary without provenance, held-out frame, margin sweep)."""
    from pfjax.tuning import study_parts as P

    print("part 1: GA vs gradient tuners", flush=True)
    hist, tuning_runs, problems = compare(cfg, progress)
    main = problem_list(cfg["compare"]["problems"])[0]
    by_problem = P.targets_by_problem(cfg, tuning_runs)
    print("part 1b: the command line's defaults", flush=True)
    cli = P.cli_check(cfg, progress)
    local_checks = P.checks(tuning_runs, problems, main)
    t3 = P.table3(cfg, problems["pi:paper-line"], progress)
    print("part 2: K, single vs robust gradient tuning; LMI designs", flush=True)
    ks = P.tune_K(cfg, spec, progress)
    des = P.designs(cfg)
    controllers = P.heldout_controllers(tuning_runs, ks, des)
    print("part 3: held-out evaluation", flush=True)
    df, sweep, table = P.heldout(cfg, spec, controllers, progress)
    for r in table:  # every gain by scalar name, as pfjax tune --check takes it, and whose they are
        r["gains"], r["type"] = dict(controllers[r["controller"]][2]), controllers[r["controller"]][0].name
    verdicts, comparisons = P.robust_vs_source(table)
    targets = {
        "wins_needed": P.wins_needed(cfg["seeds"]),
        "by_problem": by_problem,
        "cli": cli,
        "robust_vs_source": "; ".join(verdicts),
        "robust_vs_source_detail": comparisons,
        "integral_steady_abs_d_m": P.integral_steady(cfg),
    }
    parts = {"tuning_runs": tuning_runs, "table3": t3, "checks": local_checks, "K_tuning": ks, "designs": des}
    return hist, parts, table, targets, df, sweep


def run(config: TuningStudy, out: Path, progress: bool) -> dict:
    """Run the study at ``config`` and write its outputs into ``out``; returns the summary."""
    from pfjax.jsonio import dumps
    from pfjax.provenance import parquet_metadata, stamp
    from pfjax.report import document
    from pfjax.tuning.study_report import figures, report

    t0 = time.time()
    cfg = config.model_dump(mode="json")
    spec = heldout_spec(cfg)
    hist, parts, table, targets, df, sweep = _parts(cfg, spec, progress)
    summary = {
        "study": "tuning_ga_vs_gradient",
        **stamp(cfg),
        "config_sha256": study_hash(cfg, spec),  # the held-out study's file too
        "seed": list(range(cfg["seeds"])),  # the tuners' seeds 0, 1, ...
        "config": cfg,
        **parts,
        "heldout": heldout_summary(cfg, spec, table),
        "targets": targets,
        "units": summary_units(cfg, [r["type"] for r in table]),
    }
    summary["wall_s"] = time.time() - t0
    out.mkdir(parents=True, exist_ok=True)
    meta = parquet_metadata(cfg, summary["seed"], config_sha256=summary["config_sha256"])  # the tuners' seeds
    tables = {"tuning_runs": hist, "heldout": df, "margin": sweep}
    write_tables(tables, out, meta)
    figures(hist, problem_list(cfg["compare"]["problems"])[0], out)
    (out / "summary.json").write_text(dumps(summary) + "\n")
    document.write(report(summary, tables), out)
    return summary


__all__ = [
    "COLUMNS",
    "SUMMARY_UNITS",
    "compare",
    "heldout_spec",
    "heldout_summary",
    "make_study_problem",
    "methods",
    "run",
    "summary_units",
    "write_tables",
]
