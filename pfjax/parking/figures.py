"""Figures of parking runs like the source's (matplotlib; the caller picks the backend).

Trajectories with the robot's rectangle at the start, at every switch and at the end (source
Figs. 4-8, 13-17), state and input histories, the GA history and grid slices, the start-pose map
and Monte Carlo distributions. Save with :func:`pfjax.report.figures.save` (PNG + SVG).
"""

from __future__ import annotations

import math

import numpy as np

from pfjax.parking.defaults import WEIGHT
from pfjax.parking.geometry import rectangle_corners
from pfjax.parking.model import yaw_rate_command

SWITCH_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b")


def _obstacles(ax, polygons: dict, xlim, ylim):
    from matplotlib.patches import Polygon

    for poly in polygons.values():
        ax.add_patch(Polygon(np.asarray(poly), closed=True, facecolor="#bbbbbb", edgecolor="#555555", lw=0.8, zorder=0))
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")


def _rect(ax, pose, shape, color, lw=1.0, ls="-"):
    import jax.numpy as jnp
    from matplotlib.patches import Polygon

    c = np.asarray(rectangle_corners(jnp.asarray(pose, float), shape))
    ax.add_patch(Polygon(c, closed=True, fill=False, edgecolor=color, lw=lw, ls=ls, zorder=3))
    x, y, th = pose
    ax.plot([x, x + 0.08 * math.cos(th)], [y, y + 0.08 * math.sin(th)], color=color, lw=lw, zorder=3)


def trajectory_axes(ax, polygons, traj, result, shape, title, xlim=(-1.6, 0.9), ylim=(-0.8, 1.0)):
    """One run on its map: path, rectangle at start, each switch and the end."""
    _obstacles(ax, polygons, xlim, ylim)
    run = np.asarray(traj.running)
    st = np.asarray(traj.state)[run]
    ax.plot(st[:, 0], st[:, 1], color="k", lw=1.2, zorder=2)
    _rect(ax, st[0, :3], shape, "#1f77b4", ls="--")
    n = min(int(result.n_switches), len(np.asarray(result.log_t)))
    for i in range(n):
        _rect(ax, np.asarray(result.log_pose)[i], shape, SWITCH_COLORS[(i + 1) % len(SWITCH_COLORS)])
        p = np.asarray(result.log_pose)[i]
        ax.annotate(str(i + 1), (p[0], p[1]), fontsize=7, color="#333333", zorder=4)
    _rect(ax, np.asarray(result.final), shape, "#000000", lw=1.5)
    ax.plot(0, 0, marker="+", color="m", ms=10, zorder=5)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def add_trajectory_legend(fig, ncol: int = 6):
    """A figure-level legend, below the panels, for what :func:`trajectory_axes` draws (it covers no
    panel; call ``fig.tight_layout(rect=(0, 0.07, 1, 1))`` or similar to leave it room)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [
        Line2D([], [], color="k", lw=1.2, label="path of the axle midpoint"),
        Patch(fill=False, edgecolor="#1f77b4", ls="--", label="rectangle at the start"),
        Patch(fill=False, edgecolor=SWITCH_COLORS[1], label="rectangle at switch n (numbered)"),
        Patch(fill=False, edgecolor="#000000", lw=1.5, label="rectangle at the end"),
        Line2D([], [], color="m", marker="+", ms=10, ls="none", label="target (0, 0)"),
        Patch(facecolor="#bbbbbb", edgecolor="#555555", label="obstacle"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=ncol, fontsize=8, frameon=False)


def histories_figure(traj, result, control, title):
    """x, y, θ and the inputs v₁, v₂ against time (source Figs. 5-8 bottom)."""
    import matplotlib.pyplot as plt

    run = np.asarray(traj.running)
    t = np.asarray(traj.t)[run]
    st = np.asarray(traj.state)[run]
    d = np.asarray(traj.direction)[run]
    a = np.asarray(traj.alpha)[run]
    v1 = d * float(control.speed)
    v2 = np.asarray(yaw_rate_command(st[:, 2], st[:, 1], v1, a, float(control.k1), float(control.k2)))
    fig, axs = plt.subplots(2, 1, figsize=(8.4, 5.2), sharex=True)
    axs[0].plot(t, st[:, 0], label="x [m]")
    axs[0].plot(t, st[:, 1], label="y [m]")
    axs[0].plot(t, st[:, 2], label="θ [rad]")
    axs[1].plot(t, v1 * 10, label="10·v₁ [m/s]")
    axs[1].plot(t, v2, label="v₂ [rad/s]")
    axs[1].step(t, a / 10, where="post", label="α / 10", color="#999999", lw=0.8)
    for ax in axs:
        for ts in np.asarray(result.log_t)[: int(result.n_switches)]:
            ax.axvline(ts, color="#cccccc", lw=0.6, zorder=0)
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the axes: covers no curve
        ax.grid(alpha=0.3)
    axs[0].set_ylabel("state (units in legend)")
    axs[1].set_ylabel("input, gain (units in legend)")
    axs[1].set_xlabel("t [s]")
    axs[0].set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def search_figure(ga: dict, grid_table: dict, n: int, weight: float = WEIGHT):
    """GA best/mean fitness per generation, and the grid's best fitness over α₂ for each (X_s, α₁)
    (``weight``: w of J = 1/(t_e + w e), s/m)."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(10, 4))
    axs[0].plot(ga["history_best_fitness"], label="GA best")
    axs[0].plot(ga["history_mean_fitness"], label="GA population mean")
    axs[0].axhline(grid_table["fitness"].max(), color="k", ls="--", lw=0.8, label=f"grid {n}³ best")
    axs[0].set_xlabel("generation")
    axs[0].set_ylabel(f"J = 1/(t_e + {weight:g} e) [1/s]")
    axs[0].legend(fontsize=8)
    axs[0].grid(alpha=0.3)
    F = grid_table["fitness"].reshape(n, n, n).max(axis=2)
    xs, a1 = np.unique(grid_table["xs"]), np.unique(grid_table["alpha1"])
    im = axs[1].pcolormesh(
        a1, xs, np.where(F > 0, 1.0 / np.maximum(F, 1e-12), np.nan), shading="nearest", cmap="viridis_r"
    )
    fig.colorbar(im, ax=axs[1], label="best 1/J over α₂ [s]")
    i = int(np.argmax(grid_table["fitness"]))
    axs[1].plot(grid_table["alpha1"][i], grid_table["xs"][i], "wo", mec="k", ms=8, label="grid best")
    axs[1].plot(ga["alpha1"], ga["xs"], "r*", ms=12, label="GA best")
    axs[1].set_xlabel("α₁")
    axs[1].set_ylabel("X_s [m]")
    axs[1].set_title("grid: best over α₂ (blank: every α₂ fails)", fontsize=9)
    axs[1].legend(fontsize=8)
    fig.tight_layout()
    return fig


def start_map_figure(rows: list[dict]):
    """Best parking time and best (X_s, α₁, α₂) over start poses (x₀, θ₀)."""
    import matplotlib.pyplot as plt

    x0 = np.unique([r["x0"] for r in rows])
    th = np.unique([r["theta0_deg"] for r in rows])
    grid = {k: np.full((len(th), len(x0)), np.nan) for k in ("time_s", "xs", "alpha1", "alpha2")}
    for r in rows:
        i, j = int(np.searchsorted(th, r["theta0_deg"])), int(np.searchsorted(x0, r["x0"]))
        used = {
            "time_s": r["status"] == 0,
            "xs": r["switches"] >= 1,
            "alpha1": r["switches"] >= 1,
            "alpha2": r["switches"] >= 2,
        }
        for k in grid:
            grid[k][i, j] = r[k] if used[k] else np.nan  # blank: failed, or too few switches to use the parameter
    fig, axs = plt.subplots(1, 4, figsize=(15, 3.6))
    for ax, (k, label) in zip(
        axs, [("time_s", "best parking time [s]"), ("xs", "best X_s [m]"), ("alpha1", "best α₁"), ("alpha2", "best α₂")]
    ):
        im = ax.pcolormesh(x0, th, grid[k], shading="nearest", cmap="viridis")
        if np.isfinite(grid[k]).any():  # an all-blank panel gets no (empty) colour scale
            fig.colorbar(im, ax=ax)
        ax.set_title(
            label + (" (blank: unused or no run parks)" if k != "time_s" else " (blank: no run parks)"), fontsize=9
        )
        ax.set_facecolor("#eeeeee")
        ax.set_xlabel("x₀ [m]")
        ax.set_ylabel("θ₀ [deg]")
    fig.tight_layout()
    return fig


def monte_carlo_figure(df):
    """Parking-time ECDF (failures at +∞) and status counts per schedule."""
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11.5, 3.8))
    for label, g in df.groupby("schedule", sort=False):
        t = np.sort(np.where(g["converged"], g["time_s"], np.inf))
        axs[0].step(t, np.arange(1, len(t) + 1) / len(t), where="post", label=label)
    axs[0].set_xlabel("parking time [s] (failed runs never arrive)")
    axs[0].set_ylabel("fraction of runs parked")
    axs[0].grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    counts = df.groupby(["schedule", "status"], sort=False).size().unstack(fill_value=0)
    counts.plot.bar(ax=axs[1], rot=0)
    # the schedule's name only ("GA best"): its parameters are in the left panel's legend
    axs[1].set_xticklabels([str(s).split(":")[0] for s in counts.index])
    axs[1].set_xlabel("schedule (parameters: left legend)")
    axs[1].set_ylabel("runs")
    axs[1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))  # beside the bars: covers none
    fig.tight_layout()
    return fig
