#!/usr/bin/env python
"""Kinematic vs dynamic: does the robustness verdict of the kinematic slip studies survive a vehicle
whose slip comes from tyre forces (CommonRoad's single-track model, :mod:`pfjax.sim.dynamic`)?

    python studies/kinematic_vs_dynamic.py [--config studies/kinematic_vs_dynamic.toml] [--set key=value ...]
                                           [--out DIR] [--quick]

Arms, all on the same runs (run ``i`` of a path starts from the same pose in every arm: common random
numbers, so differences between arms are paired): the dynamic arm (robot parameter set, friction
``mu`` uniform on ``[mu_low, mu_high]``) and kinematic arms with constant slip uniform on ``+-A`` per
axle for each ``A`` of ``slip_ranges_deg``, and the dynamic vehicle on a high-friction surface
(``mu_grip``: the same model with little slip). Writes to ``results/kinematic_vs_dynamic/`` (or
``--out``): ``runs.parquet`` (one row per arm, path, controller and run), ``summary.json`` and
``report.md``:

* the slip the dynamic model produces (largest and time-mean |beta_r|, |beta_f| per run) by friction
  bin and by path, against the declared range of the default study (+-10 deg);
* per controller: success rate with its 95 % Clopper-Pearson interval in each arm, the paired
  difference dynamic - kinematic(+-10 deg) with its 95 % interval, and whether the verdict survives
  (both arms on the same side of the 95 % success line, judged by the intervals);
* the equivalent kinematic slip range: the ``A`` whose success rate is closest to the dynamic arm's;
* throughput: the dynamic and kinematic simulators' cost per rollout-step on the same batch, float32
  and float64 (the ratio is the model's cost in the one loop).
"""

from __future__ import annotations

import argparse
import copy
import itertools
import math
import sys
import tempfile
import time
from pathlib import Path

import jax

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache

pfjax.cache.enable()

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from pfjax.config import ConfigError, load, parse_override, read_toml  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.metrics.robustness import clopper_pearson  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.provenance import config_hash, machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_TOML = Path(__file__).with_suffix(".toml")
QUICK = ["study.n_runs=16", "study.chunk_size=16", "study.sim.horizon=4.0", "study.sim.steady_window=2.0", "study.success.from_s=2.0",
         "slip_ranges_deg=[10.0, 0.0]", "bench_runs=32", "bench_repeats=1"]  # fmt: skip
#: A verdict's line: a controller is robust in an arm if its success rate is at least this.
ROBUST = 0.95


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(DEFAULT_TOML))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out")
    ap.add_argument("--quick", action="store_true", help="a small sample and short runs (for tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("kinematic_vs_dynamic", lambda: run(args))


def load_config(args) -> dict:
    """Defaults <- --config <- --set; ConfigError naming the key (the arms' study configs are
    validated by pfjax's study schema when they run)."""
    defaults = read_toml(DEFAULT_TOML)
    defaults["slip_ranges_deg"] = []  # any length
    cfg = load(defaults, args.config)
    for text in (QUICK if args.quick else []) + args.set:
        if "slip_ranges_deg" in parse_override(text):
            cfg["slip_ranges_deg"] = []
        cfg = load(cfg, None, [text])
    if not 0 < cfg["mu_low"] < cfg["mu_high"] <= 10:
        raise ConfigError(f"mu_low, mu_high: need 0 < mu_low < mu_high <= 10, got {cfg['mu_low']}, {cfg['mu_high']}")
    ranges = cfg["slip_ranges_deg"]
    if not ranges or not all(isinstance(a, (int, float)) and 0 <= a < 90 for a in ranges):
        raise ConfigError(f"slip_ranges_deg: expected a non-empty list of angles in [0, 90) deg, got {ranges!r}")
    if not 0 < cfg["mu_grip"] <= 10:
        raise ConfigError(f"mu_grip: expected a friction coefficient in (0, 10], got {cfg['mu_grip']!r}")
    for k in ("bench_runs", "bench_repeats"):
        if not (isinstance(cfg[k], int) and cfg[k] >= 1):
            raise ConfigError(f"{k}: expected an integer >= 1, got {cfg[k]!r}")
    return cfg


def arms(cfg: dict) -> dict[str, dict]:
    """Arm name -> its study config (pfjax's study schema)."""
    base = {**copy.deepcopy(cfg["study"]), "name": cfg["name"]}
    out = {}
    dyn = copy.deepcopy(base)
    dyn["vehicle"] = {**dyn.get("vehicle", {}), "model": "st"}
    dyn["vehicle"]["mu"] = {"dist": "uniform", "low": cfg["mu_low"], "high": cfg["mu_high"]}
    out["dynamic"] = dyn
    grip = copy.deepcopy(dyn)  # the same vehicle on a high-friction surface: little slip
    grip["vehicle"]["mu"] = cfg["mu_grip"]
    out[f"dynamic_mu{cfg['mu_grip']:g}"] = grip
    for a in cfg["slip_ranges_deg"]:
        kin = copy.deepcopy(base)
        slip = {"dist": "uniform", "low": -a, "high": a} if a > 0 else 0.0
        kin["slip"] = {"kind": "constant", "beta_r_deg": slip, "beta_f_deg": slip}
        out[f"kinematic_{a:g}deg"] = kin
    return out


def run(args) -> int:
    cfg = load_config(args)
    check_name("name", cfg["name"])
    out = Path(args.out) if args.out else ROOT / "results" / cfg["name"]
    with OutputDir(
        out, command="kinematic-vs-dynamic", config_sha256=config_hash(cfg), overwrite=args.overwrite
    ) as output:
        t0 = time.time()
        frames, wall = [], {}
        with tempfile.TemporaryDirectory() as tmp:
            for name, spec in arms(cfg).items():
                t = time.time()
                res = pfjax.run_study(spec, Path(tmp) / name, report=False, progress=False)
                wall[name] = time.time() - t
                frames.append(res.runs.assign(arm=name))
                print(f"{name}: {len(res.runs)} runs, {wall[name]:.1f} s", file=sys.stderr)
        runs = pd.concat(frames, ignore_index=True)
        bench = throughput(cfg)
        summary = summarise(cfg, runs)
        summary.update(
            study=cfg["name"],
            config=cfg,
            config_sha256=config_hash(cfg),
            pfjax_version=pfjax.__version__,
            machine=machine(),
            throughput=bench,
            wall_s={"arms": wall, "total": time.time() - t0},
        )
        runs.to_parquet(output.staging / "runs.parquet", index=False)
        (output.staging / "summary.json").write_text(dumps(summary) + "\n")
        (output.staging / "report.md").write_text(report(summary))
        output.commit()
    print(report(summary))
    return 0


def _rate(success: np.ndarray) -> dict:
    k, n = int(np.sum(success)), len(success)
    lo, hi = clopper_pearson(k, n)
    return {"rate": k / n, "ci95": [lo, hi], "k": k, "n": n}


def _paired(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean of the paired differences ``a - b`` (success indicators) with its 95 % normal interval."""
    d = a.astype(float) - b.astype(float)
    se = float(np.std(d, ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.nan
    m = float(np.mean(d))
    return {"diff": m, "ci95": [m - 1.96 * se, m + 1.96 * se], "n": len(d)}


def _side(r: dict) -> str:
    """``robust`` (interval above the line), ``fragile`` (below) or ``undecided`` (straddles it)."""
    lo, hi = r["ci95"]
    return "robust" if lo >= ROBUST else "fragile" if hi < ROBUST else "undecided"


SLIP_COLS = ["max_abs_beta_r_deg", "max_abs_beta_f_deg", "mean_abs_beta_r_deg", "mean_abs_beta_f_deg"]


def summarise(cfg: dict, runs: pd.DataFrame) -> dict:
    dyn = runs[runs.arm == "dynamic"]
    q = lambda s: {"q50": float(s.quantile(0.5)), "q95": float(s.quantile(0.95)), "max": float(s.max())}
    bins = np.linspace(cfg["mu_low"], cfg["mu_high"], 8)
    by_mu = []
    for lo, hi in itertools.pairwise(bins):
        part = dyn[(dyn.mu >= lo) & (dyn.mu <= hi)]
        by_mu.append({"mu": [float(lo), float(hi)], "n": len(part), **{c: q(part[c]) for c in SLIP_COLS}})
    by_path = [{"path": p, "n": len(part), **{c: q(part[c]) for c in SLIP_COLS}} for p, part in dyn.groupby("path")]
    declared = max(cfg["slip_ranges_deg"])
    slip = {
        "by_mu": by_mu,
        "by_path": by_path,
        "all": {c: q(dyn[c]) for c in SLIP_COLS},
        "declared_range_deg": declared,
        "fraction_max_beyond_declared": {
            c: float(np.mean(dyn[c] > declared)) for c in ("max_abs_beta_r_deg", "max_abs_beta_f_deg")
        },
    }
    key = ["path", "controller", "run"]
    ref = f"kinematic_{declared:g}deg"
    controllers = {}
    for name in dict.fromkeys(runs.controller):
        mine = runs[runs.controller == name]
        rates = {arm: _rate(mine[mine.arm == arm].success.to_numpy()) for arm in dict.fromkeys(runs.arm)}
        d = dyn[dyn.controller == name].set_index(key).sort_index()
        k = runs[(runs.arm == ref) & (runs.controller == name)].set_index(key).sort_index()
        paired = _paired(d.success.to_numpy(), k.success.to_numpy())
        kin_arms = {a: r for a, r in rates.items() if a.startswith("kinematic")}
        equivalent = min(kin_arms, key=lambda a: abs(kin_arms[a]["rate"] - rates["dynamic"]["rate"]))
        by_path = {
            arm: {p: _rate(part.success.to_numpy()) for p, part in mine[mine.arm == arm].groupby("path")}
            for arm in ("dynamic", ref)
        }
        dm = d.reset_index()
        edges = np.linspace(cfg["mu_low"], cfg["mu_high"], 4)
        by_mu = [
            {"mu": [float(lo), float(hi)], **_rate(dm[(dm.mu >= lo) & (dm.mu <= hi)].success.to_numpy())}
            for lo, hi in itertools.pairwise(edges)
        ]
        controllers[name] = {
            "success": rates,
            "success_by_path": by_path,
            "success_by_mu_dynamic": by_mu,
            "paired_dynamic_minus_kinematic": paired,
            "verdict_kinematic": _side(rates[ref]),
            "verdict_dynamic": _side(rates["dynamic"]),
            "verdict_survives": _side(rates[ref]) == _side(rates["dynamic"]),
            "equivalent_kinematic_arm": equivalent,
            "equivalent_gap": abs(kin_arms[equivalent]["rate"] - rates["dynamic"]["rate"]),
            "failure_status_dynamic": {str(s): int(v) for s, v in d.status.value_counts().items()},
            "late_max_abs_d_mm": {
                arm: 1000 * float(mine[mine.arm == arm].late_max_abs_d.quantile(0.95)) for arm in rates
            },
        }
    return {"slip": slip, "controllers": controllers, "reference_arm": ref, "robust_line": ROBUST}


def throughput(cfg: dict) -> dict:
    """Wall time per rollout-step of the dynamic and the kinematic simulators on the same batch
    (``bench_runs`` runs of the study's horizon and step on the sine path, Stanley, metrics only;
    best of ``bench_repeats`` interleaved calls after a compiling call), float32 and float64."""
    sim = cfg["study"].get("sim", {})
    horizon, dt = float(sim.get("horizon", 20.0)), float(sim.get("dt", 0.005))
    steps = round(horizon / dt)
    n = cfg["bench_runs"]
    out = {"runs": n, "steps": steps, "controller": "stanley", "path": "sine"}
    for dtype in ("float32", "float64"):
        with jax.enable_x64(dtype == "float64"):
            calls = {}
            for model in ("kinematic", "st"):
                kw = {"model": "st", "mu": 0.65} if model == "st" else {"beta_r_deg": 5.0, "beta_f_deg": 5.0}
                runs = pfjax.scenarios("sine", n=n, lateral_offset=pfjax.uniform(-0.5, 0.5), key=0, **kw)
                calls[model] = lambda runs=runs: pfjax.simulate(runs, "stanley", config={"horizon": horizon, "dt": dt})
                calls[model]()  # compiles
            best = dict.fromkeys(calls, math.inf)
            for _ in range(cfg["bench_repeats"]):  # interleaved, so both see the same load on a shared machine
                for model, call in calls.items():
                    t = time.perf_counter()
                    call()
                    best[model] = min(best[model], time.perf_counter() - t)
            row = {m: {"wall_s": b, "ns_per_rollout_step": 1e9 * b / (n * steps)} for m, b in best.items()}
            row["ratio_st_over_kinematic"] = best["st"] / best["kinematic"]
            out[dtype] = row
    return out


def _pct(r: dict) -> str:
    return f"{100 * r['rate']:.1f} % [{100 * r['ci95'][0]:.1f}, {100 * r['ci95'][1]:.1f}]"


def report(s: dict) -> str:
    cfg = s["config"]
    ref = s["reference_arm"]
    lines = [
        f"# Kinematic vs dynamic ({cfg['name']})",
        "",
        f"{cfg['study']['n_runs']} runs per controller and path on {', '.join(p['kind'] for p in cfg['study']['paths'])}; "
        f"dynamic arm: CommonRoad ST, robot parameter set, mu uniform on [{cfg['mu_low']:g}, {cfg['mu_high']:g}]; "
        f"kinematic arms: constant slip uniform on +-A per axle, A in {cfg['slip_ranges_deg']} deg. "
        f"Machine: {s['machine']}; wall {s['wall_s']['total']:.0f} s (shared machine: timings are noisy).",
        "",
        "## Slip the dynamic model produces (deg)",
        "",
        "| mu | runs | max abs beta_r q50 / q95 / max | max abs beta_f q50 / q95 / max | mean abs beta_f q50 / q95 |",
        "|---|---|---|---|---|",
    ]
    f = lambda d: f"{d['q50']:.2f} / {d['q95']:.2f} / {d['max']:.2f}"
    for b in s["slip"]["by_mu"]:
        lines.append(
            f"| {b['mu'][0]:.2f}-{b['mu'][1]:.2f} | {b['n']} | {f(b['max_abs_beta_r_deg'])} | {f(b['max_abs_beta_f_deg'])} | "
            f"{b['mean_abs_beta_f_deg']['q50']:.2f} / {b['mean_abs_beta_f_deg']['q95']:.2f} |"
        )
    lines += [
        "",
        "| path | runs | max abs beta_r q50 / q95 / max | max abs beta_f q50 / q95 / max |",
        "|---|---|---|---|",
    ]
    for b in s["slip"]["by_path"]:
        lines.append(f"| {b['path']} | {b['n']} | {f(b['max_abs_beta_r_deg'])} | {f(b['max_abs_beta_f_deg'])} |")
    fr = s["slip"]["fraction_max_beyond_declared"]
    lines += [
        "",
        f"Runs whose largest slip exceeds the declared +-{s['slip']['declared_range_deg']:g} deg: rear "
        f"{100 * fr['max_abs_beta_r_deg']:.1f} %, front {100 * fr['max_abs_beta_f_deg']:.1f} %.",
        "",
        "## Success rates (95 % Clopper-Pearson intervals) and verdicts",
        "",
        f"Verdict: robust if the interval lies above {100 * s['robust_line']:.0f} %, fragile if below, "
        f"undecided if it straddles; paired difference: dynamic - {ref}, same runs (95 % normal interval).",
        "",
        f"| controller | dynamic | {ref} | paired difference | verdict kinematic -> dynamic | survives | equivalent kinematic arm |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, c in s["controllers"].items():
        p = c["paired_dynamic_minus_kinematic"]
        lines.append(
            f"| {name} | {_pct(c['success']['dynamic'])} | {_pct(c['success'][ref])} | "
            f"{100 * p['diff']:+.1f} pp [{100 * p['ci95'][0]:+.1f}, {100 * p['ci95'][1]:+.1f}] | "
            f"{c['verdict_kinematic']} -> {c['verdict_dynamic']} | {'yes' if c['verdict_survives'] else 'no'} | "
            f"{c['equivalent_kinematic_arm']} (gap {100 * c['equivalent_gap']:.1f} pp) |"
        )
    grip = f"dynamic_mu{cfg['mu_grip']:g}"
    lines += [
        "",
        f"On a high-friction surface (mu = {cfg['mu_grip']:g}, arm {grip}: the same vehicle with little slip):",
        "",
        "| controller | " + grip + " |",
        "|---|---|",
    ]
    for name, c in s["controllers"].items():
        lines.append(f"| {name} | {_pct(c['success'][grip])} |")
    paths_ = list(next(iter(s["controllers"].values()))["success_by_path"]["dynamic"])
    lines += ["", "Success by path (dynamic / " + ref + "):", "", "| controller | " + " | ".join(paths_) + " |"]
    lines.append("|---|" + "---|" * len(paths_))
    for name, c in s["controllers"].items():
        bp = c["success_by_path"]
        cells = [f"{100 * bp['dynamic'][p]['rate']:.1f} / {100 * bp[ref][p]['rate']:.1f} %" for p in paths_]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    mus = next(iter(s["controllers"].values()))["success_by_mu_dynamic"]
    lines += ["", "Success in the dynamic arm by friction:", ""]
    lines.append("| controller | " + " | ".join(f"mu {b['mu'][0]:.2f}-{b['mu'][1]:.2f}" for b in mus) + " |")
    lines.append("|---|" + "---|" * len(mus))
    for name, c in s["controllers"].items():
        lines.append(f"| {name} | " + " | ".join(_pct(b) for b in c["success_by_mu_dynamic"]) + " |")
    arms_ = [a for a in next(iter(s["controllers"].values()))["success"] if a.startswith("kinematic")]
    lines += ["", "Success by kinematic slip range:", "", "| controller | " + " | ".join(arms_) + " |"]
    lines.append("|---|" + "---|" * len(arms_))
    for name, c in s["controllers"].items():
        lines.append(f"| {name} | " + " | ".join(_pct(c["success"][a]) for a in arms_) + " |")
    lines += [
        "",
        "95th percentile of the late max |d| (mm):",
        "",
        "| controller | " + " | ".join(["dynamic", *arms_]) + " |",
    ]
    lines.append("|---|" + "---|" * (len(arms_) + 1))
    for name, c in s["controllers"].items():
        lines.append(
            f"| {name} | " + " | ".join(f"{c['late_max_abs_d_mm'][a]:.1f}" for a in ["dynamic", *arms_]) + " |"
        )
    b = s["throughput"]
    lines += [
        "",
        f"## Throughput ({b['runs']} runs x {b['steps']} steps, {b['controller']} on {b['path']}, best of "
        f"{cfg['bench_repeats']})",
        "",
        "| precision | kinematic ns/rollout-step | dynamic ns/rollout-step | ratio |",
        "|---|---|---|---|",
    ]
    for dtype in ("float32", "float64"):
        r = b[dtype]
        lines.append(
            f"| {dtype} | {r['kinematic']['ns_per_rollout_step']:.0f} | {r['st']['ns_per_rollout_step']:.0f} | "
            f"{r['ratio_st_over_kinematic']:.2f} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
