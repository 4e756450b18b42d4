"""The tuning study: GA vs gradient tuners over seeds and problems, ablation, Table 3 check, robust designs.

Part 1 runs, for every problem in ``compare.problems`` (controller, scenario set, cost) and every
seed, the GA (the source's settings), the multi-start gradient tuner (``pfjax tune --method
gradient``, settings in ``[multistart]``) and plain projected adam (``gradient-plain``,
``[gradient]``); on the first problem also ``ga+gradient``, and on every problem of
``compare.ablate_problems`` the ablation variants of ``compare.ablation`` (the multi-start tuner
with one ingredient changed). Part 1b repeats ``pfjax tune --method gradient``'s default settings
(5 ms step) for the first ``cli_seeds`` seeds against the GA on the same seeds. Parts 2 and 3
(:mod:`pfjax.tuning.study_parts`): K tuned on one scenario and on a training sample, the LMI designs,
and every controller on one held-out Monte Carlo set.

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
from pfjax.tuning.study_config import TuningStudy, problem_list


def make_study_problem(cfg: dict, name: str):
    """``controller:scenario`` -> Problem. ``heldout-cvar``: CVaR of IAE over the held-out study's
    distribution, ``compare.cvar_runs`` runs per path with run indices disjoint from the held-out runs."""
    from pfjax.sim import SimConfig
    from pfjax.tuning.cost import CostSpec
    from pfjax.tuning.problem import make_problem

    controller, _, scenario = name.partition(":")
    if scenario == "heldout-cvar":
        cost = CostSpec(aggregate="cvar", level=cfg["compare"]["cvar_level"])
        return make_problem(
            controller, cfg["heldout"], cost=cost, n_runs=cfg["compare"]["cvar_runs"], run_offset=1 << 20
        )
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


def methods(cfg: dict, name: str, first: bool) -> dict[str, dict]:
    """Label -> :func:`pfjax.tuning.problem.tune` keywords of every method run on problem ``name``."""
    from pfjax.tuning.multistart import MultistartOptions

    ms = MultistartOptions(**cfg["multistart"])
    out: dict[str, dict] = {
        "ga": dict(method="ga"),
        "gradient": dict(method="gradient", multistart=ms),
        "gradient-plain": dict(
            method="gradient-plain",
            steps=cfg["gradient"]["steps"],
            n_starts=cfg["gradient"]["starts"],
            learning_rate=cfg["gradient"]["lr"],
        ),
    }
    if first:
        out["ga+gradient"] = dict(method="ga+gradient")
    if cfg["compare"]["ablate"] and name in problem_list(cfg["compare"]["ablate_problems"]):
        for k, v in cfg["compare"]["ablation"].items():
            out[f"gradient:{k}"] = dict(method="gradient", multistart=ms._replace(**v))
    return out


def compare(cfg: dict, progress: bool):
    """Every method on every problem and seed (module docstring); returns (histories, runs, problems)."""
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import tune

    opts = GAOptions(population_size=cfg["ga"]["population"], generations=cfg["ga"]["generations"])
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
    """The held-out Monte Carlo study at the study's sizes, step and horizon."""
    from pfjax.montecarlo.config import load_study

    spec, _ = load_study(
        Path(cfg["heldout"]),
        [
            f"n_runs={cfg['robust']['heldout_runs']}",
            f"margin.n_per_amplitude={cfg['robust']['margin_runs']}",
            f"sim.horizon={cfg['sim']['horizon']}",
            f"sim.dt={cfg['sim']['dt']}",
        ],
    )
    return spec


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
    from pfjax.tables import write_parquet
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
        "heldout": {
            "study": cfg["heldout"],
            "seed": spec.seed,
            "n_per_path": cfg["robust"]["heldout_runs"],
            "margin_runs": cfg["robust"]["margin_runs"],
            "config_sha256": config_hash(json.loads(spec.model_dump_json())),
            "table": table,
        },
        "targets": targets,
    }
    summary["wall_s"] = time.time() - t0
    out.mkdir(parents=True, exist_ok=True)
    meta = parquet_metadata(cfg, None, config_sha256=summary["config_sha256"])
    tables = {"tuning_runs": hist, "heldout": df, "margin": sweep}
    for name, frame in tables.items():
        write_parquet(frame, out / f"{name}.parquet", meta)
    figures(hist, problem_list(cfg["compare"]["problems"])[0], out)
    (out / "summary.json").write_text(dumps(summary) + "\n")
    document.write(report(summary, tables), out)
    return summary


__all__ = ["compare", "heldout_spec", "make_study_problem", "methods", "run"]
