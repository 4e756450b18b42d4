"""Figure of a study's worst-case search: per controller, the falsifier's worst run and the search curves."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from pfjax.tables import COLUMNS


def objective_unit(objective: str) -> str:
    """The unit of a worst-case objective (a metric of :data:`pfjax.tables.COLUMNS`) as a figure
    writes it: ``m·s`` for IAE, ``m²·s`` for ISE."""
    unit = COLUMNS[objective][0] if objective in COLUMNS else ""
    return unit.replace("^2", "²").replace(" ", "·")


def worst_case_figure(trajs: dict, summary: dict, colors: dict[str, str]) -> Figure | None:
    """One row per controller: (a) the worst run's rear-axle path against the reference path,
    (b) its slip profile (rear, front), (c) its lateral error, (d) the worst objective found against
    the rollouts spent, falsifier (gradient ascent) versus random search."""
    names = [n for n in trajs if "worst_case" in summary["controllers"].get(n, {})]
    if not names:
        return None
    fig = Figure(figsize=(16, 3.3 * len(names)), layout="constrained")
    ax = np.atleast_2d(fig.subplots(len(names), 4))
    for row, name in zip(ax, names):
        tr, wc, c = trajs[name], summary["controllers"][name]["worst_case"], colors.get(name, "C0")
        unit = objective_unit(wc["objective"])
        a = row[0]
        inside = (tr["path_x"] > tr["x"].min() - 1) & (tr["path_x"] < tr["x"].max() + 1)
        a.plot(np.where(inside, tr["path_x"], np.nan), tr["path_y"], color="0.6", lw=3, alpha=0.5, label="path")
        a.plot(tr["x"], tr["y"], color=c, lw=1.5, label="worst run")
        a.plot(tr["x"][0], tr["y"][0], "ko", ms=4)
        near = (
            (tr["path_x"] > tr["x"].min() - 1)
            & (tr["path_x"] < tr["x"].max() + 1)
            & (tr["path_y"] > tr["y"].min() - 1)
            & (tr["path_y"] < tr["y"].max() + 1)
        )
        a.plot(tr["path_x"][near], tr["path_y"][near], color="none")  # autoscale to the run, not the whole path
        a.set(
            xlabel="x [m]",
            ylabel="y [m]",
            title=f"{name}: worst {wc['objective']} = {wc['falsifier']:.3g} {unit} ({wc['falsifier_status']})",
        )
        a.set_aspect("equal", adjustable="datalim")
        a.autoscale(enable=True, tight=False)
        a.legend(fontsize=7)
        a = row[1]
        a.plot(tr["t"], np.degrees(tr["beta_r"]), color=c, label="β_r")
        a.plot(tr["t"], np.degrees(tr["beta_f"]), color=c, ls="--", label="β_f")
        a.set(xlabel="t [s]", ylabel="slip [deg]", title="worst slip profile")
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
        a = row[2]
        a.plot(tr["t"], 100 * tr["d"], color=c)
        a.axhline(0, color="0.7", lw=0.6)
        a.set(xlabel="t [s]", ylabel="d [cm]", title="lateral error of the worst run")
        a.grid(alpha=0.3)
        a = row[3]
        a.plot(wc["history_rollouts"], wc["history"], color=c, lw=2, label="falsifier (gradient ascent)")
        a.plot(wc["history_random_rollouts"], wc["history_random"], color="0.4", ls="--", label="random search")
        a.set(
            xlabel="rollouts simulated",
            ylabel=f"worst {wc['objective']} found [{unit}]",
            title=f"search: ratio {wc['ratio']:.2f}×",
        )
        a.legend(fontsize=7)
        a.grid(alpha=0.3)
    return fig
