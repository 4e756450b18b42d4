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

:func:`run` writes ``summary.json``, ``tuning_runs.parquet`` (cost history of every tuning run),
``heldout.parquet`` (one row per held-out run and controller), ``margin.parquet`` (the slip-margin
sweep's successes ``k`` of ``n`` runs per controller, axis and amplitude), ``figures/*.png|svg`` and
``report.md`` / ``report.html`` (:mod:`pfjax.tuning.study_report`).
"""

from __future__ import annotations

import json
import platform
import time
from pathlib import Path

import jax
import numpy as np
import pandas as pd

from pfjax.numerics.random import seed_key
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
    return {
        "problem": problem_name,
        "method": method,
        "seed": seed,
        "cost": float(r.cost),
        "n_rollouts": int(r.n_rollouts),
        "n_forward_passes": int(r.n_forward_passes),
        "wall_s": float(r.wall_s),
        "compile_s": float(r.compile_s),
        "gains": pr.tunable.named(r.theta),
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


def heldout_summary(cfg: dict, spec, table: list) -> dict:
    """The summary's ``heldout`` section: the held-out study, its paths and margin sweeps, ``table``."""
    from pfjax.provenance import config_hash
    from pfjax.tuning.study_config import MARGIN_AXIS

    return {
        "study": cfg["heldout"],
        "seed": spec.seed,
        "n_per_path": cfg["robust"]["heldout_runs"],
        "paths": [p.label for p in spec.paths],
        "margin_runs": cfg["robust"]["margin_runs"],
        "margin_axis": MARGIN_AXIS,
        "margin_axes": list(spec.margin.axes),
        "config_sha256": config_hash(json.loads(spec.model_dump_json())),
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
    for r in table:
        r["gains"] = ", ".join(f"{k}={np.round(v, 4).tolist()}" for k, v in controllers[r["controller"]][2].items())
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
    from pfjax import __version__
    from pfjax.jsonio import dumps
    from pfjax.provenance import config_hash, parquet_metadata
    from pfjax.report import document
    from pfjax.tuning.study_report import figures, report

    t0 = time.time()
    cfg = config.model_dump(mode="json")
    spec = heldout_spec(cfg)
    hist, parts, table, targets, df, sweep = _parts(cfg, spec, progress)
    summary = {
        "study": "tuning_ga_vs_gradient",
        "pfjax_version": __version__,
        "config": cfg,
        "config_sha256": config_hash(cfg),
        "seed": list(range(cfg["seeds"])),
        "machine": f"{platform.machine()}, {jax.device_count()} {jax.default_backend()} device(s), "
        f"jax {jax.__version__}",
        **parts,
        "heldout": heldout_summary(cfg, spec, table),
        "targets": targets,
    }
    summary["wall_s"] = time.time() - t0
    out.mkdir(parents=True, exist_ok=True)
    meta = parquet_metadata(cfg, None, config_sha256=summary["config_sha256"])
    tables = {"tuning_runs": hist, "heldout": df, "margin": sweep}
    write_tables(tables, out, meta)
    figures(hist, problem_list(cfg["compare"]["problems"])[0], out)
    (out / "summary.json").write_text(dumps(summary) + "\n")
    document.write(report(summary, tables), out)
    return summary


__all__ = [
    "COLUMNS",
    "compare",
    "heldout_spec",
    "heldout_summary",
    "make_study_problem",
    "methods",
    "run",
    "write_tables",
]
