"""Tuning study: GA vs gradient tuners over seeds and problems, ablation, Table 3 check, robust designs.

    python studies/tuning_ga_vs_gradient.py [--config studies/tuning_ga_vs_gradient.toml] [--set key=value ...]
                                            [--out results/tuning] [--quick]

Part 1 runs, for every problem in ``compare.problems`` (controller, scenario set, cost) and every
seed, the GA (the source's settings), the multi-start gradient tuner (``pfjax tune --method
gradient``, settings in ``[multistart]``) and plain projected adam (``gradient-plain``,
``[gradient]``); on the first problem also ``ga+gradient``, and on every problem of
``compare.ablate_problems`` the ablation variants of ``compare.ablation`` (the multi-start tuner
with one ingredient changed). Part 1b repeats ``pfjax tune --method gradient``'s default settings
(5 ms step) for the first ``cli_seeds`` seeds against the GA on the same seeds.

Writes ``summary.json``, ``tuning_runs.parquet`` (cost history of every tuning run),
``heldout.parquet`` (one row per held-out run and controller), ``margin.parquet`` (the slip-margin
sweep's successes ``k`` of ``n`` runs per controller, axis and amplitude), ``figures/*.png|svg`` and
``report.md`` (``studies/tuning_report.py``; the Table 3 check, K tuning, designs and held-out
evaluation are in ``studies/tuning_parts.py``), assembled beside the output directory and moved into
place at the end (:class:`pfjax.outputs.OutputDir`).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import jax

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache

jax.config.update("jax_enable_x64", True)
pfjax.cache.enable()

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from tuning_parts import (  # noqa: E402  (studies/, beside this script)
    checks,
    cli_check,
    designs,
    heldout,
    heldout_controllers,
    integral_steady,
    robust_vs_source,
    table3,
    tune_K,
)
from tuning_report import figures, problem_list, report, targets_by_problem  # noqa: E402

from pfjax import __version__  # noqa: E402
from pfjax.config import ConfigError, load  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.outputs import OutputDir  # noqa: E402
from pfjax.provenance import (  # noqa: E402
    config_hash,
    parquet_metadata,
)
from pfjax.tables import write_parquet  # noqa: E402
from pfjax.tuning.multistart import MultistartOptions  # noqa: E402

#: The multi-start tuner with one ingredient changed, at about the same budget (``compare.ablation``).
ABLATION = {
    "no_screening": {"n_screen": 0},
    "uniform_screening": {"sampler": "uniform"},
    "latin_hypercube": {"sampler": "lhs"},
    "no_separation": {"separation": 0.0},
    "no_halving": {"rounds": 1, "steps": 35},
    "no_restarts": {"n_restarts": 0},
    "no_polish": {"polish_steps": 0},
    "fewer_gradient_steps": {"steps": 30, "restart_steps": 10, "polish_steps": 16},
    "adam": {"local": "adam", "learning_rate": 0.05},
    "smoothing": {"smoothing": 0.05},
    "single_start": {"n_starts": 1, "rounds": 1, "steps": 280},
}

DEFAULTS = {
    "heldout": "studies/tuning_heldout.toml",
    "seeds": 20,
    "cli_seeds": 5,
    "sim": {"dt": 0.01, "horizon": 20.0},
    "ga": {"population": 50, "generations": 100},
    "gradient": {"steps": 100, "starts": 4, "lr": 0.05, "table3_steps": 60},
    "multistart": dict(MultistartOptions()._asdict()),
    "compare": {
        "problems": "pi:paper-line, pi:paper-all, pi:heldout-cvar, state_feedback:paper-line, integral:paper-line, "
        "stanley:paper-line, pure_pursuit:paper-line, rear_wheel:paper-line",
        "cvar_level": 0.9,
        "cvar_runs": 3,
        "ablate": True,
        "ablate_problems": "pi:paper-line, integral:paper-line",
        "ablation": ABLATION,
    },
    "robust": {
        "train_runs": 6,
        "heldout_runs": 200,
        "margin_runs": 40,
        "v_lo": 0.8,
        "v_hi": 1.2,
        "beta_r_max_deg": 10.0,
    },
}
QUICK = [
    "seeds=2",
    "cli_seeds=0",
    "compare.ablate=false",
    "multistart.n_screen=8",
    "multistart.n_starts=2",
    "multistart.steps=4",
    "multistart.rounds=2",
    "multistart.n_restarts=1",
    "multistart.restart_steps=2",
    "multistart.polish_steps=1",
    "compare.problems='pi:paper-line, state_feedback:paper-line'",
    "compare.ablation.no_halving.steps=4",
    "compare.ablation.single_start.steps=4",
    "ga.population=8",
    "ga.generations=3",
    "gradient.steps=4",
    "gradient.starts=2",
    "gradient.table3_steps=3",
    "robust.train_runs=1",
    "robust.heldout_runs=6",
    "robust.margin_runs=3",
    "sim.horizon=16.0",
]


def _validate(cfg: dict) -> None:
    if cfg["seeds"] < 1:
        raise ConfigError(f"seeds: must be >= 1, got {cfg['seeds']}")
    if not 0 <= cfg["cli_seeds"] <= cfg["seeds"]:
        raise ConfigError(f"cli_seeds: must be in [0, seeds], got {cfg['cli_seeds']}")
    from pfjax import errors

    for name, over in [("multistart", cfg["multistart"])] + [
        (f"compare.ablation.{k}", {**cfg["multistart"], **v}) for k, v in cfg["compare"]["ablation"].items()
    ]:
        try:
            MultistartOptions(**over).check()
        except (TypeError, errors.InputError) as e:
            raise ConfigError(f"{name}: {e}") from None
    if cfg["compare"]["ablate"] and not set(problem_list(cfg, "ablate_problems")) <= set(problem_list(cfg)):
        raise ConfigError("compare.ablate_problems: every problem must be listed in compare.problems")
    if cfg["compare"]["cvar_runs"] < 1:
        raise ConfigError(f"compare.cvar_runs: must be >= 1, got {cfg['compare']['cvar_runs']}")
    if "pi:paper-line" not in problem_list(cfg):
        raise ConfigError("compare.problems: must list pi:paper-line (the held-out part evaluates its answers)")
    for p in problem_list(cfg):
        c, _, sc = p.partition(":")
        from pfjax import controllers as C

        if c not in C.REGISTRY or C.REGISTRY[c].box is None or sc not in ("paper-line", "paper-all", "heldout-cvar"):
            raise ConfigError(
                f"compare.problems: {p!r}, expected CONTROLLER:SCENARIO with a tunable controller and a scenario "
                "paper-line | paper-all | heldout-cvar"
            )
    if not 0 < cfg["sim"]["dt"] <= cfg["sim"]["horizon"]:
        raise ConfigError(
            f"sim.dt/sim.horizon: need 0 < dt <= horizon, got {cfg['sim']['dt']:g}, {cfg['sim']['horizon']:g}"
        )
    if cfg["sim"]["horizon"] <= 15.0:
        raise ConfigError(f"sim.horizon: must be > 15 s (success window from 15 s), got {cfg['sim']['horizon']:g}")
    for k in ("population", "generations"):
        if cfg["ga"][k] < (2 if k == "population" else 1):
            raise ConfigError(f"ga.{k}: too small, got {cfg['ga'][k]}")
    for sec, k in (
        ("gradient", "steps"),
        ("gradient", "starts"),
        ("gradient", "table3_steps"),
        ("robust", "train_runs"),
        ("robust", "heldout_runs"),
        ("robust", "margin_runs"),
    ):
        if cfg[sec][k] < 1:
            raise ConfigError(f"{sec}.{k}: must be >= 1, got {cfg[sec][k]}")
    if not cfg["gradient"]["lr"] > 0:
        raise ConfigError(f"gradient.lr: must be > 0, got {cfg['gradient']['lr']}")
    if not 0 < cfg["robust"]["v_lo"] <= cfg["robust"]["v_hi"]:
        raise ConfigError(
            f"robust.v_lo/v_hi: need 0 < v_lo <= v_hi, got {cfg['robust']['v_lo']}, {cfg['robust']['v_hi']}"
        )
    if not 0 <= cfg["robust"]["beta_r_max_deg"] < 90:
        raise ConfigError(f"robust.beta_r_max_deg: must be in [0, 90), got {cfg['robust']['beta_r_max_deg']}")
    if not Path(cfg["heldout"]).is_file():
        raise ConfigError(f"heldout: file not found: {cfg['heldout']}")


# --- part 1: GA vs gradient tuners, seeds x problems ------------------------------------------------


def _problem(cfg, name):
    """``controller:scenario`` -> (Problem, label). ``heldout-cvar``: CVaR of IAE over the held-out
    study's distribution, ``compare.cvar_runs`` runs per path with run indices disjoint from the
    held-out runs."""
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


def _run_row(problem_name, method, seed, r, pr):
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


def compare(cfg, progress):
    """Every method on every problem and seed (module docstring); returns (histories, runs, problems)."""
    from pfjax.tuning.ga import GAOptions
    from pfjax.tuning.problem import tune

    opts = GAOptions(population_size=cfg["ga"]["population"], generations=cfg["ga"]["generations"])
    ms = MultistartOptions(**cfg["multistart"])
    rows, runs, problems = [], [], {}
    for i, name in enumerate(problem_list(cfg)):
        pr = problems[name] = _problem(cfg, name)
        methods = {
            "ga": dict(method="ga"),
            "gradient": dict(method="gradient", multistart=ms),
            "gradient-plain": dict(
                method="gradient-plain",
                steps=cfg["gradient"]["steps"],
                n_starts=cfg["gradient"]["starts"],
                learning_rate=cfg["gradient"]["lr"],
            ),
        }
        if i == 0:
            methods["ga+gradient"] = dict(method="ga+gradient")
        if cfg["compare"]["ablate"] and name in problem_list(cfg, "ablate_problems"):
            for k, v in cfg["compare"]["ablation"].items():
                methods[f"gradient:{k}"] = dict(method="gradient", multistart=ms._replace(**v))
        for label, kw in methods.items():
            for seed in range(cfg["seeds"]):
                r = tune(pr, key=jax.random.PRNGKey(seed), ga_options=opts, progress=progress, **kw)
                runs.append(_run_row(name, label, seed, r, pr))
                for it, (c, n, t) in enumerate(zip(r.history, r.history_rollouts, r.history_wall_s)):
                    rows.append(
                        {
                            "problem": name,
                            "method": label,
                            "seed": seed,
                            "iteration": it,
                            "best_cost": c,
                            "rollouts": int(n),
                            "wall_s": t,
                        }
                    )
            c = [x["cost"] for x in runs if x["problem"] == name and x["method"] == label]
            print(
                f"  {name} {label}: median cost {np.median(c):.5f} (min {min(c):.5f}, max {max(c):.5f}) over "
                f"{len(c)} seeds, {runs[-1]['n_rollouts']} rollouts per seed",
                flush=True,
            )
    return pd.DataFrame(rows), runs, problems


def run(cfg: dict, out: Path, progress: bool) -> dict:
    from pfjax.montecarlo.config import load_study

    t0 = time.time()
    spec, _ = load_study(
        Path(cfg["heldout"]),
        [
            f"n_runs={cfg['robust']['heldout_runs']}",
            f"margin.n_per_amplitude={cfg['robust']['margin_runs']}",
            f"sim.horizon={cfg['sim']['horizon']}",
            f"sim.dt={cfg['sim']['dt']}",
        ],
    )
    print("part 1: GA vs gradient tuners", flush=True)
    hist, tuning_runs, problems = compare(cfg, progress)
    main = problem_list(cfg)[0]
    by_problem = targets_by_problem(cfg, tuning_runs)
    print("part 1b: the command line's defaults", flush=True)
    cli = cli_check(cfg, progress)
    local_checks = checks(tuning_runs, problems, main)
    t3 = table3(cfg, _problem(cfg, "pi:paper-line"), progress)
    print("part 2: K, single vs robust gradient tuning; LMI designs", flush=True)
    ks = tune_K(cfg, spec, progress)
    des = designs(cfg)
    controllers = heldout_controllers(tuning_runs, ks, des)
    print("part 3: held-out evaluation", flush=True)
    df, sweep, table = heldout(cfg, spec, controllers, progress)
    for r in table:
        r["gains"] = ", ".join(f"{k}={np.round(v, 4).tolist()}" for k, v in controllers[r["controller"]][2].items())
    verdicts, comparisons = robust_vs_source(table)
    targets = {
        "by_problem": by_problem,
        "cli": cli,
        "robust_vs_source": "; ".join(verdicts),
        "robust_vs_source_detail": comparisons,
        "integral_steady_abs_d_m": integral_steady(cfg),
    }
    summary = {
        "study": "tuning_ga_vs_gradient",
        "pfjax_version": __version__,
        "config": cfg,
        "config_sha256": config_hash(cfg),
        "seed": list(range(cfg["seeds"])),
        "machine": f"{platform.machine()}, {jax.device_count()} {jax.default_backend()} device(s), "
        f"jax {jax.__version__}",
        "tuning_runs": tuning_runs,
        "table3": t3,
        "checks": local_checks,
        "K_tuning": ks,
        "designs": des,
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
    for name, frame in (("tuning_runs", hist), ("heldout", df), ("margin", sweep)):
        write_parquet(frame, out / f"{name}.parquet", meta)
    figures(hist, main, out)
    (out / "summary.json").write_text(dumps(summary) + "\n")
    (out / "report.md").write_text(report(summary))
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="studies/tuning_ga_vs_gradient.toml")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out", default=None)
    ap.add_argument("--quick", action="store_true", help="tiny sizes (seconds of simulation; used by the tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("tuning_ga_vs_gradient", lambda: main_checked(args))


def main_checked(args) -> int:
    cfg = load(DEFAULTS, args.config, (QUICK if args.quick else []) + args.set)
    _validate(cfg)
    out = Path(args.out or ("results/tuning_quick" if args.quick else "results/tuning"))
    with OutputDir(
        out,
        command="tuning-study",
        config_sha256=config_hash(cfg),
        overwrite=args.overwrite,
        extra={"seeds": cfg["seeds"]},
    ) as output:
        summary = run(cfg, output.staging, progress=sys.stderr.isatty())
        out = output.commit()
    print(json.dumps({"out": str(out), "wall_s": round(summary["wall_s"], 1), "targets": summary["targets"]}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
