"""The parking study's batched parts: the assumptions sweep over cases A-D, the GA and grid searches
of the garage schedule, the start-pose map and the robustness Monte Carlo. Each part takes the
validated config, a :class:`pfjax.parking.study_config.ParkingStudy`."""

from __future__ import annotations

import time

import jax
import numpy as np
import pandas as pd

from pfjax.parking import figures as F
from pfjax.parking.assumptions import case_sweep, sweep_summary
from pfjax.parking.defaults import GARAGE_XS
from pfjax.parking.montecarlo import Scatter, monte_carlo, summarise
from pfjax.parking.schedules import GARAGE_START
from pfjax.parking.simulate import STATUS_NAMES, run_params
from pfjax.parking.study_config import ParkingStudy
from pfjax.parking.study_runs import setup
from pfjax.parking.switch_search import evaluate, garage_base, search_ga, search_grid, start_map
from pfjax.report.figures import save
from pfjax.reproduce.parking import GA_SOLUTIONS
from pfjax.tuning.ga import GAOptions


def part_assumptions(cfg: ParkingStudy, pmap):
    """Cases A-D under every combination of the open assumptions (pfjax.parking.assumptions)."""
    control, _, pc, _ = setup(cfg)
    a = cfg.assumptions
    grid = {
        "front": a.fronts,
        "zone": a.zones,
        "scan_period": a.scan_periods,
        "decision_delay": a.decision_delays,
        "lag": a.lags,
        "pause": a.pauses,
    }
    c = cfg.controller
    df = case_sweep(
        pmap,
        grid,
        control_kw={"k1": c.k1, "k2": c.k2, "speed": c.speed},
        cfg=pc,
        chunk=cfg.sim.chunk,
        progress=True,
    )
    return df, sweep_summary(df)


def search_base(cfg: ParkingStudy):
    """The garage run the search and the start map vary: the study's controller, reach a_f and
    scanner period (:func:`pfjax.parking.switch_search.garage_base`)."""
    control, front, _, _ = setup(cfg)
    return garage_base(front=front, scan_period=cfg.sim.scan_period, control=control)


def part_search(cfg: ParkingStudy, fig_dir, gmap, key):
    """The grid, ``search.ga_seeds`` GA runs and the source's GA solutions (:data:`GA_SOLUTIONS`),
    all with the search's fitness and cut-off: ``(best GA run, GA runs, grid best, grid table,
    source solutions)``, each with its fitness ratio to the grid's best (null where none scores)."""
    _, _, _, pc = setup(cfg)
    se = cfg.search
    base = search_base(cfg)
    t0 = time.perf_counter()
    grid = search_grid(gmap, n=se.grid_n, base=base, weight=se.weight, cfg=pc, progress=True, chunk=cfg.sim.chunk)
    grid["wall_s"] = time.perf_counter() - t0
    table = grid.pop("table")
    f = table["fitness"]

    def ratio(fitness: float) -> float | None:  # to the grid's best; null where no grid point scores
        return float(fitness) / grid["fitness"] if grid["fitness"] > 0 else None

    runs = []
    for i in range(se.ga_seeds):  # independent GA runs: the source reports several good solutions
        t0 = time.perf_counter()
        r = search_ga(
            gmap,
            key=jax.random.fold_in(key, i),
            base=base,
            weight=se.weight,
            cfg=pc,
            progress=True,
            options=GAOptions(population_size=se.population, generations=se.generations),
        )
        r.update(
            seed_index=i,
            wall_s=time.perf_counter() - t0,
            grid_fraction_better=float(np.mean(f > r["fitness"])),
            fitness_ratio_to_grid_best=ratio(r["fitness"]),
        )
        runs.append(r)
    ga = max(runs, key=lambda r: r["fitness"])
    save(F.search_figure(ga, table, se.grid_n, se.weight), fig_dir, "search")
    for d in (*runs, grid):
        d["status"] = STATUS_NAMES[int(d["status"])]
    df = pd.DataFrame({k: v for k, v in table.items()})
    df["status"] = [STATUS_NAMES[int(s)] for s in df["status"]]
    df["converged_fraction"] = None
    sources = evaluate(
        gmap, base, *(list(v) for v in zip(*GA_SOLUTIONS)), cfg=pc, weight=se.weight, chunk=cfg.sim.chunk
    )
    solutions = [
        {
            "xs": float(sources["xs"][i]),
            "alpha1": float(sources["alpha1"][i]),
            "alpha2": float(sources["alpha2"][i]),
            "status": STATUS_NAMES[int(sources["status"][i])],
            "time_s": float(sources["time_s"][i]),
            "switches": int(sources["switches"][i]),
            "fitness": float(sources["fitness"][i]),
            "fitness_ratio_to_grid_best": ratio(sources["fitness"][i]),
        }
        for i in range(len(GA_SOLUTIONS))
    ]
    return ga, runs, grid, df, solutions


def part_start_map(cfg: ParkingStudy, fig_dir, gmap):
    _, _, _, pc = setup(cfg)
    sm = cfg.start_map
    rows = start_map(
        gmap,
        sm.x0,
        sm.theta0_deg,
        n=sm.grid_n,
        weight=cfg.search.weight,
        cfg=pc,
        progress=True,
        chunk=cfg.sim.chunk,
        base=search_base(cfg),
    )
    for r in rows:
        r["status"] = STATUS_NAMES[int(r["status"])] if isinstance(r["status"], int) else r["status"]
    save(
        F.start_map_figure([{**r, "status": 0 if r["status"] == "converged" else 1} for r in rows]),
        fig_dir,
        "start_map",
    )
    return rows


def part_montecarlo(cfg: ParkingStudy, fig_dir, gmap, ga, grid, key):
    """Fixed schedule vs the GA's best vs the grid's best, on the same sampled runs."""
    control, front, pc, _ = setup(cfg)
    m = cfg.montecarlo
    sc = Scatter(
        **{
            k: getattr(m, k)
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
    scan = cfg.sim.scan_period
    schedules: list[tuple[str, float, tuple[float, ...]]] = [(f"fixed: α=1, X_s={GARAGE_XS:g}", GARAGE_XS, (1.0,))]
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
            n=m.n_runs,
            scatter=sc,
            cfg=pc,
            progress=True,
            label=lab,
            chunk=cfg.sim.chunk,
        )
        for lab, xs, sched in schedules
    ]
    df = pd.concat(dfs, ignore_index=True)
    save(F.monte_carlo_figure(df), fig_dir, "montecarlo")
    return df, {lab: summarise(g) for lab, g in df.groupby("schedule", sort=False)}
