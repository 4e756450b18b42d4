"""Figures of a Monte Carlo study report (run table and summary in, ``Figure`` out; never under jit).

Every builder aggregates first (quantiles, histograms, ECDFs on a fixed grid, 2D bins) and plots
the aggregate, so a figure costs the same for 100 runs as for 100,000 and its SVG stays small.
Each controller keeps one colour throughout (:func:`controller_colors`, the colours of
:func:`pfjax.controllers.style` of its type). Figures are ``matplotlib.figure.Figure``
objects, independent of the pyplot backend; :func:`pfjax.report.figures.save` writes them.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from pfjax.report.figure_style import AXIS_TITLE, controller_colors, freeze_layout, log_axis, pct_axis
from pfjax.report.headline_figure import headline_figure
from pfjax.report.study_format import fmt_margin

__all__ = [
    "AXIS_TITLE",
    "PREDICTION_GRID",
    "controller_colors",
    "distribution_figure",
    "fmt_margin",
    "freeze_layout",
    "headline_figure",
    "margin_figure",
    "slip_map_figure",
    "success_by_param_figure",
]


def _grid(values: np.ndarray, log: bool, n: int):
    v = values[np.isfinite(values)]
    if log:
        v = v[v > 0]
    if v.size == 0:
        return None
    lo, hi = np.quantile(v, [0.001, 1.0]) if log else (v.min(), v.max())
    if not hi > lo:
        lo, hi = (lo / 2, lo * 2) if log and lo > 0 else (lo - 0.5, hi + 0.5)
    return np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)


def _wants_log(values: np.ndarray) -> bool:
    v = values[np.isfinite(values) & (values > 0)]
    if v.size < 2:
        return False
    q01, q99 = np.quantile(v, [0.01, 0.99])
    return q99 > 30 * q01


def distribution_figure(
    runs: pd.DataFrame,
    metric: str,
    colors: dict[str, str],
    paths: list[str],
    *,
    scale: float = 1.0,
    unit: str = "",
    label: str | None = None,
    band: float | None = None,
    bins: int | None = None,
) -> Figure:
    """Histogram (top) and ECDF (bottom) of one metric, controllers overlaid, one column per path.

    Only runs that ran to the end (status ok) enter the histograms and the ECDF's steps: a failed
    run's metrics stop at its failure (a run that diverges at once has IAE 0), so it would look
    like the best run. Every run counts in the denominators instead: a failed run (or a
    non-finite value) counts as beyond the right edge, and the ECDF stops short of 1 by the
    failed fraction (given in the legend). Histograms show the fraction of a controller's runs
    per bin (the end bins collect the clipped tails); the x axis is logarithmic when the 1-99 %
    range of the values of all paths pooled spans more than a factor 30 (one scale for every path
    of the figure, so the panels compare). ECDFs are evaluated on a 400-point grid
    (``searchsorted`` on the sorted values). ``band`` (metric units) draws the success band, named
    in the ECDF legend.
    """
    label = label or metric
    if bins is None:  # ~1.5 sqrt(n) per controller and path, 10 to 60
        n_max = int(runs.groupby(["path", "controller"]).size().max()) if len(runs) else 1
        bins = int(np.clip(1.5 * np.sqrt(n_max), 10, 60))
    ncol = max(1, len(paths))
    fig = Figure(figsize=(4.3 * ncol + 0.8, 6.2), layout="constrained")
    ax = np.asarray(fig.subplots(2, ncol, squeeze=False, sharex="col"))
    pooled = runs[runs.path.isin(paths) & (runs["status"] == "ok")][metric].to_numpy(dtype=float) * scale
    log = _wants_log(pooled)  # one scale for the whole figure
    for j, p in enumerate(paths):
        sub = runs[runs.path == p]
        healthy = (sub["status"] == "ok").to_numpy()
        allv = sub[metric].to_numpy(dtype=float)[healthy] * scale
        edges = _grid(allv, log, bins + 1)
        grid = _grid(allv, log, 400)
        h, e = ax[0, j], ax[1, j]
        for name, g in sub.groupby("controller", sort=False):
            v = g[metric].to_numpy(dtype=float) * scale
            ok = (g["status"] == "ok").to_numpy()
            fin = v[ok & np.isfinite(v)]
            n_fail, n_bad = int((~ok).sum()), int((ok & ~np.isfinite(v)).sum())
            lab = name + (f" ({n_fail} failed: +∞)" if n_fail else "") + (f", {n_bad} non-finite" if n_bad else "")
            if edges is not None and fin.size:
                counts, _ = np.histogram(np.clip(fin, edges[0], edges[-1]), edges)
                h.stairs(counts / v.size, edges, color=colors[name], lw=1.6, label=lab)
                h.stairs(counts / v.size, edges, color=colors[name], alpha=0.12, fill=True)
                e.plot(
                    grid,
                    np.searchsorted(np.sort(fin), grid, side="right") / v.size,
                    color=colors[name],
                    lw=1.8,
                    label=lab,
                )
            else:
                e.plot([], [], color=colors[name], lw=1.8, label=lab + " (no run reached the end)")
        for a in (h, e):
            if log:
                log_axis(a)
            if band is not None:
                a.axvline(band, color="k", ls="--", lw=1, label=f"success band: {band:g} {unit}" if a is e else None)
            a.grid(alpha=0.3)
        h.set(title=f"path '{p}'", ylabel="fraction of runs per bin" if j == 0 else None)
        e.set(
            xlabel=f"{label} [{unit}]" + (", log scale" if log else ""),
            ylabel="ECDF: P(X ≤ x)" if j == 0 else None,
            ylim=(0, 1.02),
        )
        e.legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Distribution of {label} per controller (top: histogram, bottom: empirical CDF)")
    return fig


# ------------------------------------------------------------------------------- margin curves


def margin_figure(summary: dict, colors: dict[str, str]) -> Figure | None:
    """Success rate against slip amplitude, one panel per axis (rear, front, joint), from the
    sweep's per-amplitude tables: line and markers the rate ``k/n``, band the 95 %
    Clopper-Pearson interval, dashed the ``1 - eps`` line, triangle each controller's margin.
    None when the study has no sweep."""
    ctrl = summary["controllers"]
    axes = [x for x in ("rear", "front", "joint") if any(x in c.get("slip_margin", {}) for c in ctrl.values())]
    if not axes:
        return None
    fig = Figure(figsize=(4.6 * len(axes) + 0.6, 4.3), layout="constrained")
    ax = np.atleast_1d(fig.subplots(1, len(axes), sharey=True))
    eps = None
    n_per = None
    for a, x in zip(ax, axes):
        for name, c in ctrl.items():
            m = c.get("slip_margin", {}).get(x)
            if m is None:
                continue
            eps, n_per = m["eps"], m["table"][0]["n"]
            t = pd.DataFrame(m["table"])
            col = colors[name]
            span = max(float(t["amplitude"].max() - t["amplitude"].min()), 1.0)
            t["amplitude"] += (list(ctrl).index(name) - (len(ctrl) - 1) / 2) * 0.006 * span  # dodge overlapping curves
            a.fill_between(t["amplitude"], t["lo"], t["hi"], color=col, alpha=0.15, lw=0)
            a.plot(t["amplitude"], t["rate"], "o-", color=col, lw=1.8, ms=4, label=f"{name}: margin {fmt_margin(m)}")
            a.plot([m["margin"]], [1 - m["eps"]], "v", color=col, ms=9, mec="k", mew=0.6, zorder=5)
        if eps is not None:
            a.axhline(1 - eps, color="k", ls="--", lw=1)
            a.annotate(
                f"1 − ε = {100 * (1 - eps):g} %",
                (0, 1 - eps),
                xycoords=("axes fraction", "data"),
                xytext=(4, -11),
                textcoords="offset points",
                fontsize=7,
            )
        a.set(title=AXIS_TITLE[x], xlabel="slip amplitude A [deg]", ylim=(-0.02, 1.04))
        pct_axis(a, "y")
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="best")
    ax[0].set_ylabel("success rate [%]")
    fig.suptitle(
        f"Slip margin: success rate vs constant slip amplitude ({n_per} runs per amplitude, all paths pooled; "
        "band: 95 % Clopper-Pearson; ▼ margin)"
    )
    return fig


# ------------------------------------------------------------------------------- slip map


#: Points per axis at which :func:`slip_map_figure` evaluates the linearised prediction.
PREDICTION_GRID = 121


def slip_map_figure(
    runs: pd.DataFrame,
    controllers: list[str],
    *,
    delta_max_deg: float | None = None,
    convention: str = "source",
    note: str = "",
    predicted=None,
) -> Figure | None:
    """Success rate binned over the sampled ``(beta_r_deg, beta_f_deg)``, one panel per controller
    (all paths pooled): ``rate = successes / runs`` per cell of an ``n_b x n_b`` grid,
    ``n_b = clip(sqrt(n / 25), 4, 24)`` with ``n`` the runs per controller (about 25 runs per
    cell); white cells hold no run. Dashed: where a straight-line equilibrium stops existing,
    ``|beta_r +- beta_f| = delta_max`` (source / Lenain convention, nominal ``delta_max``).
    ``predicted``: optional ``{controller: fn(xs_deg, ys_deg) -> bool grid (len(xs), len(ys))}``, the
    linearised prediction of success, drawn as a solid contour next to the simulated rates.
    None when neither slip angle varies."""
    if not {"beta_r_deg", "beta_f_deg"} <= set(runs.columns):
        return None
    br, bf = runs["beta_r_deg"].to_numpy(float), runs["beta_f_deg"].to_numpy(float)
    ok = np.isfinite(br) & np.isfinite(bf)
    if not ok.any() or (np.ptp(br[ok]) == 0 and np.ptp(bf[ok]) == 0):
        return None
    n_per = max(1, ok.sum() // max(1, len(controllers)))
    nb = int(np.clip(np.sqrt(n_per / 25), 4, 24))

    def edges(v):
        lo, hi = v.min(), v.max()
        if hi == lo:
            lo, hi = lo - 0.5, hi + 0.5
        return np.linspace(lo, hi, nb + 1)

    ex, ey = edges(br[ok]), edges(bf[ok])
    ncol = len(controllers)
    fig = Figure(figsize=(4.2 * ncol + 1.2, 4.2), layout="constrained")
    ax = np.atleast_1d(fig.subplots(1, ncol, sharey=True))
    mesh = None
    for a, name in zip(ax, controllers):
        g = runs[(runs.controller == name).to_numpy() & ok]
        x, y, s = g["beta_r_deg"].to_numpy(float), g["beta_f_deg"].to_numpy(float), g["success"].to_numpy(float)
        cnt, _, _ = np.histogram2d(x, y, [ex, ey])
        hit, _, _ = np.histogram2d(x, y, [ex, ey], weights=s)
        rate = np.ma.masked_where(cnt == 0, hit / np.maximum(cnt, 1))
        mesh = a.pcolormesh(ex, ey, rate.T, cmap="RdYlGn", vmin=0, vmax=1, edgecolors="face", lw=0)
        if delta_max_deg is not None:
            b = np.array([ex[0], ex[-1]])
            from pfjax.models.slip import CONVENTIONS, FRONT_SLIP_SIGN  # figure_set has imported them

            sign = FRONT_SLIP_SIGN[CONVENTIONS[convention]]  # |delta*| = delta_max: its steering's limit
            for s_ in (-1, 1):
                a.plot(b, sign * (s_ * delta_max_deg - b), "--", color="0.25", lw=1)
        if predicted and name in predicted:
            xs, ys = np.linspace(ex[0], ex[-1], PREDICTION_GRID), np.linspace(ey[0], ey[-1], PREDICTION_GRID)
            grid = np.asarray(predicted[name](xs, ys), dtype=float)
            if 0 < grid.mean() < 1:
                a.contour(xs, ys, grid.T, levels=[0.5], colors="k", linewidths=1.4)
            a.text(
                0.02,
                0.02,
                "— linearised: success predicted inside"
                if 0 < grid.mean() < 1
                else f"linearised: success predicted {'everywhere' if grid.mean() == 1 else 'nowhere'}",
                transform=a.transAxes,
                fontsize=7,
                va="bottom",
                bbox=dict(fc="white", alpha=0.7, lw=0),
            )
        a.set(
            xlim=(ex[0], ex[-1]),
            ylim=(ey[0], ey[-1]),
            xlabel=f"β_r{note} [deg]",
            title=f"{name}: {100 * s.mean():.1f} % overall" if s.size else name,
        )
    ax[0].set_ylabel(f"β_f{note} [deg]")
    if mesh is not None:
        fig.colorbar(mesh, ax=list(ax), label="success rate (from simulation)", shrink=0.9)
    fig.suptitle(
        f"Robustness map from simulation: success rate over sampled slip ({nb}×{nb} bins, "
        f"~{n_per / nb**2:.0f} runs per bin, all paths pooled)"
    )
    return fig


# ------------------------------------------------------------------------------- success per parameter

PARAM_LABEL = {
    "speed": "speed v [m/s]",
    "L": "wheelbase L [m]",
    "delta_max_deg": "δ_max [deg]",
    "beta_r_deg": "β_r [deg]",
    "beta_f_deg": "β_f [deg]",
    "step_time_s": "step time [s]",
    "step_r_deg": "rear step [deg]",
    "step_f_deg": "front step [deg]",
    "amp_r_deg": "rear amplitude [deg]",
    "amp_f_deg": "front amplitude [deg]",
    "freq_hz": "slip frequency [Hz]",
    "ou_sigma_deg": "OU std [deg]",
    "ou_tau_s": "OU time constant [s]",
    "start_along_m": "start along the path [m]",
    "lateral_offset": "initial lateral offset [m]",
    "heading_error_deg": "initial heading error [deg]",
    "radius": "circle radius [m]",
}


def success_by_param_figure(summary: dict, colors: dict[str, str], ncols: int = 4) -> Figure | None:
    """Success rate per bin of every varied sampled parameter (``success_by_param`` of the summary:
    equal-count bins, or one per value), one panel per parameter, controllers side by side with
    their 95 % Clopper-Pearson intervals. None when no parameter varies."""
    ctrl = summary["controllers"]
    params = list(dict.fromkeys(p for c in ctrl.values() for p in c.get("success_by_param", {})))
    if not params:
        return None
    ncols = min(ncols, len(params))
    nrows = -(-len(params) // ncols)
    fig = Figure(figsize=(3.7 * ncols + 0.4, 2.9 * nrows + 0.6), layout="constrained")
    ax = np.asarray(fig.subplots(nrows, ncols, squeeze=False, sharey=True)).ravel()
    for a, p in zip(ax, params):
        for i, (name, c) in enumerate(ctrl.items()):
            bins = c.get("success_by_param", {}).get(p)
            if not bins:
                continue
            t = pd.DataFrame(bins)
            lo = np.array([ci[0] for ci in t["success_ci95"]], float)
            hi = np.array([ci[1] for ci in t["success_ci95"]], float)
            x = 0.5 * (t["lo"] + t["hi"]).to_numpy(float)
            span = max(float(t["hi"].max() - t["lo"].min()), 1e-12)
            x = x + (i - (len(ctrl) - 1) / 2) * 0.012 * span  # side by side
            r = t["success_rate"].to_numpy(float)
            a.errorbar(x, r, yerr=[r - lo, hi - r], fmt="o-", ms=3.5, lw=1.2, capsize=2, color=colors[name], label=name)
        a.set(xlabel=PARAM_LABEL.get(p, p), ylim=(-0.03, 1.03))
        pct_axis(a, "y")
        a.grid(alpha=0.3)
    for a in ax[len(params) :]:
        a.set_visible(False)
    for r in range(nrows):
        ax[r * ncols].set_ylabel("success rate [%]")
    ax[0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Success rate per bin of each varied parameter (equal-count bins, all paths pooled; bars: 95 % CI)")
    return fig
