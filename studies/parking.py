#!/usr/bin/env python
"""Parking by switching travel direction and gain (docs/reproductions/parking.md): every case of its §4,
the a_f calibration, the garage X_s tries, the GA and grid searches, the start-pose map and a
robustness Monte Carlo.

    python studies/parking.py [--config studies/parking.toml] [--set key=value ...] [--out DIR] [--quick]

Writes to ``results/parking/`` (or ``--out``): ``summary.json`` (config, SHA-256, seed, version),
``cases.parquet``, ``assumptions.parquet`` (cases A-D under every combination of the open assumptions),
``grid.parquet``, ``start_map.parquet``,
``montecarlo.parquet``, ``figures/*.png|svg`` and ``report.md``. Outputs are assembled in a temporary
directory and moved into place when complete; a bad key or value stops with one line, exit 2.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import jax
import matplotlib

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache

jax.config.update("jax_enable_x64", True)
pfjax.cache.enable()
matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from tqdm import tqdm  # noqa: E402

from pfjax.config import ConfigError, load  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.parking import figures as F  # noqa: E402
from pfjax.parking.assumptions import ZONES, case_sweep, sweep_summary  # noqa: E402
from pfjax.parking.calibrate import calibrate_front  # noqa: E402
from pfjax.parking.maps import GARAGE, PARALLEL, to_obstacle_map  # noqa: E402
from pfjax.parking.model import control_params  # noqa: E402
from pfjax.parking.montecarlo import Scatter, monte_carlo, summarise  # noqa: E402
from pfjax.parking.schedules import CASES, GARAGE_START  # noqa: E402
from pfjax.parking.simulate import (  # noqa: E402
    STATUS_NAMES,
    ParkingConfig,
    n_periods_for,
    run_jit,
    run_params,
    run_recorded_jit,
    simulated_first_switch,
)
from pfjax.parking.summary import run_summary  # noqa: E402
from pfjax.parking.switch_search import search_ga, search_grid, start_map  # noqa: E402
from pfjax.provenance import (  # noqa: E402
    config_hash,
    parquet_metadata,
)
from pfjax.provenance import stamp as provenance_stamp  # noqa: E402
from pfjax.report.figures import save  # noqa: E402
from pfjax.reproduce.parking import GA_SOLUTIONS  # noqa: E402
from pfjax.reproduce.parking import verdicts as parking_verdicts  # noqa: E402
from pfjax.tables import write_parquet  # noqa: E402
from pfjax.tuning.ga import GAOptions  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULTS = {
    "name": "parking",
    "seed": 0,
    "controller": {"k1": 32.0, "k2": 8.0, "speed": 0.05},
    "sim": {
        "scan_period": 0.1,
        "t_max": 200.0,
        "tol": 0.02,
        "n_sub": 2,
        "front": 0.0,
        "chunk": 1024,
        "stuck_switches": 4,
        "stuck_travel": 0.1,
    },
    # the open assumptions of docs/reproductions/parking.md §3, swept over the four cases (pfjax.parking.assumptions)
    "assumptions": {
        "fronts": [0.10, 0.125, 0.15, 0.175, 0.20, 0.225, 0.25],
        "zones": ["middle", "axle", "whole"],
        "scan_periods": [0.05, 0.1, 0.2],
        "decision_delays": [False, True],
        "lags": [False, True],
        "pauses": [0.0, 1.0],
    },
    "garage": {"xs_values": [-0.9, -1.2, -1.8]},
    "experiment": {"pause": 1.0},  # s standing at each reversal in the source's experiments
    "search": {"weight": 100.0, "population": 20, "generations": 100, "grid_n": 32, "ga_seeds": 3, "max_switches": 10},
    "start_map": {"x0": [-1.5, -1.3, -1.1, -0.9, -0.7], "theta0_deg": [-80.0, -40.0, 0.0, 40.0, 80.0], "grid_n": 10},
    "montecarlo": {
        "n_runs": 1000,
        "pos_scatter": 0.05,
        "theta_scatter_deg": 5.0,
        "scan_lo": 0.05,
        "scan_hi": 0.2,
        "speed_lo": 0.04,
        "speed_hi": 0.06,
        "lag_probability": 0.5,
    },
}
QUICK = {
    "sim": {"chunk": 32},
    "search": {"population": 4, "generations": 2, "grid_n": 3, "ga_seeds": 2},
    "start_map": {"grid_n": 2},
    "montecarlo": {"n_runs": 16},
}


def validate(cfg: dict) -> None:
    c, s = cfg["controller"], cfg["sim"]
    for key, v in [
        ("controller.k1", c["k1"]),
        ("controller.k2", c["k2"]),
        ("controller.speed", c["speed"]),
        ("sim.scan_period", s["scan_period"]),
        ("sim.t_max", s["t_max"]),
        ("sim.tol", s["tol"]),
    ]:
        if v <= 0:
            raise ConfigError(f"{key}: must be > 0, got {v}")
    if not 0 <= s["front"] < 0.54:
        raise ConfigError(f"sim.front: must be in [0, 0.54) (0 = calibrated), got {s['front']}")
    if s["chunk"] < 1:
        raise ConfigError(f"sim.chunk: must be >= 1, got {s['chunk']}")
    if s["n_sub"] < 1:
        raise ConfigError(f"sim.n_sub: must be >= 1, got {s['n_sub']}")
    if s["stuck_switches"] < 1 or s["stuck_travel"] < 0:
        raise ConfigError("sim.stuck_switches: must be >= 1, and sim.stuck_travel >= 0")
    if cfg["search"]["max_switches"] < 1:
        raise ConfigError(f"search.max_switches: must be >= 1, got {cfg['search']['max_switches']}")
    if cfg["experiment"]["pause"] < 0:
        raise ConfigError(f"experiment.pause: must be >= 0 s, got {cfg['experiment']['pause']}")
    if s["t_max"] / s["scan_period"] > 20000:
        raise ConfigError(
            f"sim.scan_period: t_max / scan_period must be <= 20000, got {s['t_max'] / s['scan_period']:g}"
        )
    a = cfg["assumptions"]
    for i, f in enumerate(a["fronts"]):
        if not 0 < f < 0.54:
            raise ConfigError(f"assumptions.fronts[{i}]: must be in (0, 0.54), got {f}")
    for i, f in enumerate(a["scan_periods"]):
        if not 0 < f <= 1:
            raise ConfigError(f"assumptions.scan_periods[{i}]: must be in (0, 1], got {f}")
    for i, z in enumerate(a["zones"]):
        if z not in ZONES:
            raise ConfigError(f"assumptions.zones[{i}]: expected one of {', '.join(ZONES)}, got {z!r}")
    for key in ("decision_delays", "lags"):
        if not a[key] or not all(isinstance(v, bool) for v in a[key]):
            raise ConfigError(f"assumptions.{key}: expected a non-empty list of booleans, got {a[key]!r}")
    if not a["pauses"] or not all(isinstance(v, (int, float)) and v >= 0 for v in a["pauses"]):
        raise ConfigError(f"assumptions.pauses: expected a non-empty list of times >= 0 s, got {a['pauses']!r}")
    se = cfg["search"]
    if (
        se["population"] < 2
        or se["generations"] < 1
        or se["ga_seeds"] < 1
        or not 2 <= se["grid_n"] <= 64
        or se["weight"] < 0
    ):
        raise ConfigError(f"search: need population >= 2, generations >= 1, 2 <= grid_n <= 64, weight >= 0, got {se}")
    for i, th in enumerate(cfg["start_map"]["theta0_deg"]):
        if abs(th) >= 90:
            raise ConfigError(f"start_map.theta0_deg[{i}]: magnitude must be < 90, got {th}")
    m = cfg["montecarlo"]
    if (
        m["n_runs"] < 1
        or not 0 < m["scan_lo"] <= m["scan_hi"]
        or not 0 < m["speed_lo"] <= m["speed_hi"]
        or not 0 <= m["lag_probability"] <= 1
        or m["pos_scatter"] < 0
        or m["theta_scatter_deg"] < 0
    ):
        raise ConfigError(f"montecarlo: invalid ranges {m}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default=str(ROOT / "studies" / "parking.toml"))
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out")
    ap.add_argument("--quick", action="store_true", help="small sizes (tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("parking", lambda: run(args))


def run(args) -> int:
    cfg = load(DEFAULTS, args.config, args.set)
    if args.quick:
        for sec, vals in QUICK.items():
            cfg[sec].update(vals)
        cfg["start_map"]["x0"], cfg["start_map"]["theta0_deg"] = [-1.3, -0.9], [-80.0, 40.0]
        cfg["assumptions"].update(
            fronts=[0.15, 0.2], scan_periods=[0.1], decision_delays=[False], lags=[False], pauses=[0.0]
        )
    validate(cfg)
    check_name("name", cfg["name"])
    out = Path(args.out) if args.out else ROOT / "results" / cfg["name"]
    with OutputDir(
        out,
        command="parking-study",
        config_sha256=config_hash(cfg),
        overwrite=args.overwrite,
        extra={"seed": cfg["seed"]},
    ) as output:
        summary = run_study(cfg, output.staging, quick=args.quick)
        out = output.commit()
    print(f"wrote {out} in {summary['wall_s']:.1f} s")
    return 0


# ----------------------------------------------------------------------------------- parts


def setup(cfg):
    """``(control, front, config of single runs, config of the search)``: single runs, cases, maps
    and the Monte Carlo run until they converge, get stuck or time out; the search also fails a
    candidate at its (max_switches + 1)-th switch (the source's search cut-off)."""
    c, s = cfg["controller"], cfg["sim"]
    control = control_params(k1=c["k1"], k2=c["k2"], speed=c["speed"])
    front = s["front"] if s["front"] > 0 else None
    pc = ParkingConfig(
        t_max=s["t_max"],
        tol=s["tol"],
        n_sub=s["n_sub"],
        stuck_switches=s["stuck_switches"],
        stuck_travel=s["stuck_travel"],
    )
    search = ParkingConfig(
        t_max=s["t_max"],
        tol=s["tol"],
        n_sub=s["n_sub"],
        max_switches=cfg["search"]["max_switches"],
        stuck_switches=None,
    )
    return control, front, pc, search


def one(cfg, x0, direction, schedule, *, xs=None, omap, front=None, scan=None):
    control, f0, pc, _ = setup(cfg)
    scan = scan or cfg["sim"]["scan_period"]
    p = run_params(x0, direction, schedule, xs=xs, front=front or f0, scan_period=scan, control=control)
    r, tr = run_recorded_jit(p, omap, pc, n_periods_for(pc, scan))
    return p, r, tr


def part_cases(cfg, fig_dir, pmap, gmap):
    rows, runs = [], {}
    for name, c in CASES.items():
        p, r, tr = one(cfg, c["x0"], c["direction"], c["schedule"], omap=pmap)
        runs[name] = (p, r, tr)
        rows.append(
            {
                "case": name,
                "map": "parallel",
                "start": str(c["x0"]),
                "direction": "forward" if c["direction"] > 0 else "backward",
                "schedule": ",".join(f"{a:g}" for a in c["schedule"]),
                "xs": math.nan,
                **_flat(run_summary(r)),
            }
        )
    for xs in cfg["garage"]["xs_values"]:
        p, r, tr = one(cfg, GARAGE_START, 1, (1.0,), xs=xs, omap=gmap)
        runs[f"garage X_s={xs:g}"] = (p, r, tr)
        rows.append(
            {
                "case": f"garage X_s={xs:g}",
                "map": "garage",
                "start": str(GARAGE_START),
                "direction": "forward",
                "schedule": "1",
                "xs": xs,
                **_flat(run_summary(r)),
            }
        )
    fig, axs = plt.subplots(2, 2, figsize=(11, 8))
    for ax, name in zip(axs.ravel(), "ABCD"):
        p, r, tr = runs[name]
        F.trajectory_axes(
            ax,
            PARALLEL,
            tr,
            r,
            p.shape,
            f"case {name}: {STATUS_NAMES[int(r.status)]}, {int(r.n_switches)} switches, {float(r.time):.1f} s",
            xlim=(-1.0, 1.0),
            ylim=(-0.45, 1.0),
        )
    fig.tight_layout()
    save(fig, fig_dir, "cases_parallel")
    g = [k for k in runs if k.startswith("garage")]
    fig, axs = plt.subplots(1, len(g), figsize=(5 * len(g), 4.6), squeeze=False)
    for ax, name in zip(axs[0], g):
        p, r, tr = runs[name]
        F.trajectory_axes(
            ax,
            GARAGE,
            tr,
            r,
            p.shape,
            f"{name}: {STATUS_NAMES[int(r.status)]}, {int(r.n_switches)} sw., {float(r.time):.1f} s",
            xlim=(-2.2, 0.6),
            ylim=(-1.0, 1.0),
        )
    fig.tight_layout()
    save(fig, fig_dir, "garage_xs")
    for name in ("D", g[0]):
        p, r, tr = runs[name]
        save(
            F.histories_figure(tr, r, p.control, f"{name}: states and inputs"),
            fig_dir,
            "histories_" + name.replace(" ", "_").replace("=", "").replace(".", "p"),
        )
    return rows, runs


def _flat(s: dict) -> dict:
    return {
        "status": s["status"],
        "converged": s["converged"],
        "time_s": s["time_s"],
        "switches": s["switches"],
        "final_x": s["final"]["x"],
        "final_y": s["final"]["y"],
        "final_theta_deg": s["final"]["theta_deg"],
        "error": s["error"],
        "distance_m": s["distance_m"],
        "switch_times_s": ",".join(f"{e['t']:.1f}" for e in s["switch_log"]),
    }


def part_assumptions(cfg, pmap):
    """Cases A-D under every combination of the open assumptions (pfjax.parking.assumptions)."""
    control, _, pc, _ = setup(cfg)
    a = cfg["assumptions"]
    grid = {
        "front": a["fronts"],
        "zone": a["zones"],
        "scan_period": a["scan_periods"],
        "decision_delay": a["decision_delays"],
        "lag": a["lags"],
        "pause": a["pauses"],
    }
    c = cfg["controller"]
    df = case_sweep(
        pmap,
        grid,
        control_kw={"k1": c["k1"], "k2": c["k2"], "speed": c["speed"]},
        cfg=pc,
        chunk=cfg["sim"]["chunk"],
        progress=True,
    )
    return df, sweep_summary(df)


def part_outcomes(cfg, pmap, gmap) -> dict:
    """Every scenario whose outcome the source reports (docs/reproductions/parking.md §4), at pfjax's defaults, and the
    experiments' with a stop at each reversal (``experiment.pause``)."""
    control, front, pc, _ = setup(cfg)
    scan, pause = cfg["sim"]["scan_period"], cfg["experiment"]["pause"]
    runs = {}
    for name, c in CASES.items():
        runs[name] = (
            pmap,
            run_params(c["x0"], c["direction"], c["schedule"], front=front, scan_period=scan, control=control),
        )
    c = CASES["D"]
    runs["D+pause"] = (
        pmap,
        run_params(c["x0"], c["direction"], c["schedule"], front=front, scan_period=scan, control=control, pause=pause),
    )
    for xs in (-0.9, -1.2, -1.8):
        for suffix, ps in (("", 0.0), ("+pause", pause)):
            runs[f"garage {xs:g}{suffix}"] = (
                gmap,
                run_params(GARAGE_START, 1, (1.0,), xs=xs, front=front, scan_period=scan, control=control, pause=ps),
            )
    for xs, a1, a2 in GA_SOLUTIONS:
        for suffix, ps in (("", 0.0), ("+pause", pause)):
            runs[f"GA solution ({xs:g}, {a1:g}, {a2:g}){suffix}"] = (
                gmap,
                run_params(
                    GARAGE_START, 1, (1.0, a1, a2), xs=xs, front=front, scan_period=scan, control=control, pause=ps
                ),
            )
    out = {}
    for name, (omap, p) in runs.items():
        r = run_jit(p, omap, pc)
        out[name] = {"status": STATUS_NAMES[int(r.status)], "switches": int(r.n_switches), "time_s": float(r.time)}
    return out


def part_search(cfg, fig_dir, gmap, key):
    control, front, _, pc = setup(cfg)
    se = cfg["search"]
    base = run_params(
        GARAGE_START, 1, (1.0,), xs=-1.0, front=front, scan_period=cfg["sim"]["scan_period"], control=control
    )
    t0 = time.perf_counter()
    grid = search_grid(
        gmap, n=se["grid_n"], base=base, weight=se["weight"], cfg=pc, progress=True, chunk=cfg["sim"]["chunk"]
    )
    grid["wall_s"] = time.perf_counter() - t0
    table = grid.pop("table")
    f = table["fitness"]
    runs = []
    for i in range(se["ga_seeds"]):  # independent GA runs: the source reports several good solutions
        t0 = time.perf_counter()
        r = search_ga(
            gmap,
            key=jax.random.fold_in(key, i),
            base=base,
            weight=se["weight"],
            cfg=pc,
            progress=True,
            options=GAOptions(population_size=se["population"], generations=se["generations"]),
        )
        r.update(
            seed_index=i,
            wall_s=time.perf_counter() - t0,
            grid_fraction_better=float(np.mean(f > r["fitness"])),
            fitness_ratio_to_grid_best=r["fitness"] / grid["fitness"],
        )
        runs.append(r)
    ga = max(runs, key=lambda r: r["fitness"])
    save(F.search_figure(ga, table, se["grid_n"]), fig_dir, "search")
    for d in (*runs, grid):
        d["status"] = STATUS_NAMES[int(d["status"])]
    df = pd.DataFrame({k: v for k, v in table.items()})
    df["status"] = [STATUS_NAMES[int(s)] for s in df["status"]]
    df["converged_fraction"] = None
    return ga, runs, grid, df


def part_start_map(cfg, fig_dir, gmap):
    _, _, _, pc = setup(cfg)
    sm = cfg["start_map"]
    rows = start_map(
        gmap,
        sm["x0"],
        sm["theta0_deg"],
        n=sm["grid_n"],
        weight=cfg["search"]["weight"],
        cfg=pc,
        progress=True,
        chunk=cfg["sim"]["chunk"],
    )
    for r in rows:
        r["status"] = STATUS_NAMES[int(r["status"])] if isinstance(r["status"], int) else r["status"]
    save(
        F.start_map_figure([{**r, "status": 0 if r["status"] == "converged" else 1} for r in rows]),
        fig_dir,
        "start_map",
    )
    return rows


def part_montecarlo(cfg, fig_dir, gmap, ga, grid, key):
    """Fixed schedule vs the GA's best vs the grid's best, on the same sampled runs."""
    control, front, pc, _ = setup(cfg)
    m = cfg["montecarlo"]
    sc = Scatter(
        **{
            k: m[k]
            for k in (
                "pos_scatter",
                "theta_scatter_deg",
                "scan_lo",
                "scan_hi",
                "speed_lo",
                "speed_hi",
                "lag_probability",
            )
        }
    )
    scan = cfg["sim"]["scan_period"]
    schedules = [("fixed: α=1, X_s=-0.9", -0.9, (1.0,))]
    for lab, d in (("GA best", ga), ("grid best", grid)):
        schedules.append(
            (
                f"{lab}: X_s={d['xs']:.3f}, α₁={d['alpha1']:.3f}, α₂={d['alpha2']:.3f}",
                d["xs"],
                (1.0, d["alpha1"], d["alpha2"]),
            )
        )
    dfs = [
        monte_carlo(
            gmap,
            run_params(GARAGE_START, 1, sched, xs=xs, front=front, scan_period=scan, control=control),
            key=key,
            n=m["n_runs"],
            scatter=sc,
            cfg=pc,
            progress=True,
            label=lab,
            chunk=cfg["sim"]["chunk"],
        )
        for lab, xs, sched in schedules
    ]
    df = pd.concat(dfs, ignore_index=True)
    save(F.monte_carlo_figure(df), fig_dir, "montecarlo")
    return df, {lab: summarise(g) for lab, g in df.groupby("schedule", sort=False)}


def run_study(cfg: dict, out: Path, quick=False) -> dict:
    t_start = time.perf_counter()
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True)
    pmap, gmap = to_obstacle_map(list(PARALLEL.values())), to_obstacle_map(list(GARAGE.values()))
    key = jax.random.PRNGKey(cfg["seed"])
    k_ga, k_mc = jax.random.split(key)
    steps = tqdm(total=6, desc="parking study", unit="part")
    timings = {}

    def tick(name, t0):
        timings[name] = time.perf_counter() - t0
        steps.update(1)

    t0 = time.perf_counter()
    cal = calibrate_front()
    cal["simulated_first_switch"] = simulated_first_switch(cal["a_f"])
    tick("calibration", t0)
    t0 = time.perf_counter()
    case_rows, _ = part_cases(cfg, fig_dir, pmap, gmap)
    tick("cases", t0)
    t0 = time.perf_counter()
    outcomes = part_outcomes(cfg, pmap, gmap)
    sens, sweep = part_assumptions(cfg, pmap)
    tick("assumptions", t0)
    t0 = time.perf_counter()
    ga, ga_runs, grid, grid_df = part_search(cfg, fig_dir, gmap, k_ga)
    tick("search", t0)
    t0 = time.perf_counter()
    smap = part_start_map(cfg, fig_dir, gmap)
    tick("start_map", t0)
    t0 = time.perf_counter()
    mc_df, mc = part_montecarlo(cfg, fig_dir, gmap, ga, grid, k_mc)
    tick("montecarlo", t0)
    steps.close()

    cases = pd.DataFrame(case_rows)
    stamp = provenance_stamp(cfg, cfg["seed"])
    meta = parquet_metadata(cfg, cfg["seed"])
    for name, df in (
        ("cases", cases),
        ("assumptions", sens),
        ("grid", grid_df.drop(columns=["converged_fraction"])),
        ("start_map", pd.DataFrame(smap)),
        ("montecarlo", mc_df),
    ):
        write_parquet(df, out / f"{name}.parquet", meta)
    summary = {
        "study": cfg["name"],
        **stamp,
        "quick": quick,
        "config": cfg,
        "calibration": cal,
        "cases": case_rows,
        "assumptions": sweep,
        "source_outcomes": outcomes,
        "search": {"ga": ga, "ga_runs": ga_runs, "grid": grid},
        "start_map": smap,
        "montecarlo": mc,
        "timings_s": timings,
        "wall_s": time.perf_counter() - t_start,
    }
    rows = parking_verdicts(outcomes, cal, sweep, {"runs": ga_runs})
    summary["verdicts"] = [v._asdict() for v in rows]
    (out / "summary.json").write_text(dumps(summary) + "\n")
    from pfjax.parking.report import write_report

    write_report(out, summary, sens)
    return summary


if __name__ == "__main__":
    sys.exit(main())
