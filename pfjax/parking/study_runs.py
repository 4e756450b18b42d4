"""The parking study's single runs: the set-up shared by every part, the source's cases A-D and
the garage tries with their figures, and every scenario whose outcome the source reports
(docs/reproductions/parking.md §4). Each part takes the validated config, a
:class:`pfjax.parking.study_config.ParkingStudy`."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np

from pfjax.parking import figures as F
from pfjax.parking.api import DIRECTION_NAMES
from pfjax.parking.defaults import GARAGE_TRIES
from pfjax.parking.maps import GARAGE, PARALLEL
from pfjax.parking.model import control_params
from pfjax.parking.schedules import CASES, GARAGE_START
from pfjax.parking.simulate import (
    STATUS_NAMES,
    ParkingConfig,
    n_periods_for,
    run_jit,
    run_params,
    run_recorded_jit,
)
from pfjax.parking.study_config import ParkingStudy
from pfjax.parking.summary import run_summary
from pfjax.report.figures import save
from pfjax.reproduce.parking import GA_SOLUTIONS


def setup(cfg: ParkingStudy):
    """``(control, front, config of single runs, config of the search)``: single runs, cases, maps
    and the Monte Carlo run until they converge, get stuck or time out; the search also fails a
    candidate at its (max_switches + 1)-th switch (the source's search cut-off)."""
    c, s = cfg.controller, cfg.sim
    control = control_params(k1=c.k1, k2=c.k2, speed=c.speed)
    front = s.front if s.front > 0 else None
    pc = ParkingConfig(
        t_max=s.t_max,
        tol=s.tol,
        n_sub=s.n_sub,
        stuck_switches=s.stuck_switches,
        stuck_travel=s.stuck_travel,
    )
    search = ParkingConfig(
        t_max=s.t_max,
        tol=s.tol,
        n_sub=s.n_sub,
        max_switches=cfg.search.max_switches,
        stuck_switches=None,
    )
    return control, front, pc, search


def one(cfg: ParkingStudy, x0, direction, schedule, *, xs=None, omap, front=None, scan=None):
    control, f0, pc, _ = setup(cfg)
    scan = scan or cfg.sim.scan_period
    p = run_params(x0, direction, schedule, xs=xs, front=front or f0, scan_period=scan, control=control)
    r, tr = run_recorded_jit(p, omap, pc, n_periods_for(pc, scan))
    return p, r, tr


#: figure layout per map: (rows, columns or None for one row, figure size per panel, x limits, y limits)
_LAYOUT = {
    "cases_parallel": ((2, 2), (5.5, 4.0), (-1.0, 1.0), (-0.45, 1.0)),
    "garage_xs": (None, (5.0, 3.6), (-2.2, 0.6), (-1.0, 1.0)),
}


def _trajectory_figure(runs, names, shapes, fig_dir, figure, label, switches):
    """One panel per run ``names`` (trajectory over the map ``shapes``), titled with the outcome."""
    grid, (w, h), xlim, ylim = _LAYOUT[figure]
    xlim, ylim = _covering([runs[name] for name in names], xlim, ylim)
    nr, nc = grid or (1, len(names))
    fig, axs = plt.subplots(nr, nc, figsize=(w * nc, h * nr + 0.5), squeeze=False)
    for ax, name in zip(axs.ravel(), names):
        p, r, tr = runs[name]
        title = f"{label.format(name=name)}: {STATUS_NAMES[int(r.status)]}, {int(r.n_switches)} {switches}, "
        F.trajectory_axes(ax, shapes, tr, r, p.shape, title + f"{float(r.time):.1f} s", xlim=xlim, ylim=ylim)
    F.add_trajectory_legend(fig, ncol=3 if nc < 3 else 6)
    fig.tight_layout(rect=(0, 0.9 / (h * nr + 0.5), 1, 1))
    save(fig, fig_dir, figure)


def _covering(runs, xlim, ylim):
    """The layout's limits (m), widened so that every run's recorded path and its rectangle (the
    farthest corner's distance from the axle around each point) are in view: a config's X_s or a_f
    far from the source's would otherwise leave the panel."""
    lo, hi = np.array([xlim[0], ylim[0]], float), np.array([xlim[1], ylim[1]], float)
    for p, _, tr in runs:
        pts = np.asarray(tr.state)[np.asarray(tr.running)][:, :2]
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        if len(pts):
            f, length, width = (float(v) for v in (p.shape.front, p.shape.length, p.shape.width))
            reach = math.hypot(max(f, length - f), 0.5 * width)
            lo, hi = np.minimum(lo, pts.min(axis=0) - reach), np.maximum(hi, pts.max(axis=0) + reach)
    return (float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1]))


def part_cases(cfg: ParkingStudy, fig_dir, pmap, gmap):
    rows, runs = [], {}
    for name, c in CASES.items():
        p, r, tr = one(cfg, c["x0"], c["direction"], c["schedule"], omap=pmap)
        runs[name] = (p, r, tr)
        rows.append(
            {
                "case": name,
                "map": "parallel",
                "start": str(c["x0"]),
                "direction": DIRECTION_NAMES[c["direction"]],
                "schedule": ",".join(f"{a:g}" for a in c["schedule"]),
                "xs": math.nan,
                **flat_summary(run_summary(r)),
            }
        )
    for xs in cfg.garage.xs_values:
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
                **flat_summary(run_summary(r)),
            }
        )
    _trajectory_figure(runs, list("ABCD"), PARALLEL, fig_dir, "cases_parallel", "case {name}", "switches")
    g = [k for k in runs if k.startswith("garage")]
    _trajectory_figure(runs, g, GARAGE, fig_dir, "garage_xs", "{name}", "sw.")
    for name in ("D", g[0]):
        p, r, tr = runs[name]
        save(
            F.histories_figure(tr, r, p.control, f"{name}: states and inputs"),
            fig_dir,
            "histories_" + name.replace(" ", "_").replace("=", "").replace(".", "p"),
        )
    return rows, runs


def flat_summary(s: dict) -> dict:
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


def part_outcomes(cfg: ParkingStudy, pmap, gmap) -> dict:
    """Every scenario whose outcome the source reports (docs/reproductions/parking.md §4), at pfjax's defaults, and the
    experiments' with a stop at each reversal (``experiment.pause``)."""
    control, front, pc, _ = setup(cfg)
    scan, pause = cfg.sim.scan_period, cfg.experiment.pause
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
    for xs in GARAGE_TRIES:
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
