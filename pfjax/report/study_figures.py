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
from matplotlib.ticker import LogLocator, NullLocator

_SPARE = [
    "#ff7f0e",
    "#e377c2",
    "#bcbd22",
    "#7f7f7f",
    "#393b79",
    "#637939",
    "#8c6d31",
    "#843c39",
    "#7b4173",
    "#aec7e8",
    "#ffbb78",
    "#98df8a",
    "#ff9896",
    "#c5b0d5",
    "#c49c94",
    "#f7b6d2",
    "#dbdb8d",
    "#9edae5",
]

AXIS_TITLE = {
    "rear": "rear axle only (β_r = ±A)",
    "front": "front axle only (β_f = ±A)",
    "joint": "both axles (β_r = ±A, β_f = ±A)",
}


def fmt_margin(m: dict | None) -> str:
    """A slip margin with its interval: ``"5° [2.5, 7.5]"``, ``"≥ 20° [20, 20]"`` when censored."""
    if not m:
        return "—"
    if m.get("fails_at_smallest"):
        return f"none: fails at {m['table'][0]['amplitude']:g}°"
    return f"{'≥ ' if m['censored'] else ''}{m['margin']:g}° [{m['margin_lo']:g}, {m['margin_hi']:g}]"


def controller_colors(controllers: list[dict]) -> dict[str, str]:
    """One colour per controller: its type's colour (:func:`pfjax.controllers.style`), a spare one if
    already taken.

    Args:
        controllers: the study config's controller entries (``name``, ``type``).
    """
    from pfjax.controllers import style

    used, out = set(), {}
    spare = list(_SPARE)
    for i, c in enumerate(controllers):
        col = style(c.get("type", "")).get("color")
        if col is None or col in used:
            col = next((s for s in spare if s not in used), spare[i % len(spare)])
        used.add(col)
        out[c["name"]] = col
    return out


def freeze_layout(fig: Figure) -> Figure:
    """Run the figure's constrained layout once and keep it, so that saving the figure twice (PNG
    and SVG) does not lay it out twice (about a third of the drawing time)."""
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")
    return fig


def _log_axis(ax, axis="x"):
    """Log scale with plain tick labels at 1, 2, 5 x 10^k."""
    ax.set_xscale("log") if axis == "x" else ax.set_yscale("log")
    a = ax.xaxis if axis == "x" else ax.yaxis
    lo, hi = ax.get_xlim() if axis == "x" else ax.get_ylim()
    decades = np.log10(hi / lo) if lo > 0 and hi > lo else 1.0
    subs = (1.0, 2.0, 5.0) if decades <= 2.2 else (1.0, 3.0) if decades <= 3.5 else (1.0,)
    a.set_major_locator(LogLocator(base=10, subs=subs))
    a.set_major_formatter(lambda v, _: f"{v:g}")
    a.set_minor_locator(NullLocator())


def _fmt_pct_axis(ax, axis="x"):
    (ax.xaxis if axis == "x" else ax.yaxis).set_major_formatter(
        lambda v, _: f"{100 * v:.10g}" if -1e-9 <= v <= 1 + 1e-9 else ""
    )


# ------------------------------------------------------------------------------- headline


def headline_figure(summary: dict, colors: dict[str, str]) -> Figure:
    """Three panels sharing one row per controller: success rate with its 95 % Clopper-Pearson
    interval (pooled, and per path as small markers), slip margin per axis with ``[lo, hi]``
    (an arrow when censored: the margin is at least the largest amplitude tested), and the IAE
    quantiles (box p25-p75, whiskers p05-p95, tick the median, diamond the mean)."""
    ctrl = summary["controllers"]
    names = list(ctrl)
    y = np.arange(len(names))[::-1].astype(float)
    fig = Figure(figsize=(14, 1.5 + 0.8 * len(names)), layout="constrained")
    ax = fig.subplots(1, 3, sharey=True, gridspec_kw={"width_ratios": [1.15, 1.0, 1.0]})

    a = ax[0]
    paths = summary.get("paths", [])
    lows = []
    for yi, n in zip(y, names):
        c = ctrl[n]
        lo, hi = c["success_ci95"]
        r = c["success_rate"]
        lows.append(lo)
        a.errorbar([r], [yi], xerr=[[r - lo], [hi - r]], fmt="o", ms=8, color=colors[n], capsize=4, lw=2)
        for j, p in enumerate(paths if len(paths) > 1 else []):
            pp = c["per_path"].get(p)
            if pp:
                yy = yi - 0.12 - 0.24 * j / max(1, len(paths) - 1)
                plo, phi = pp["success_ci95"]
                lows.append(plo)
                a.errorbar(
                    [pp["success_rate"]],
                    [yy],
                    xerr=[[pp["success_rate"] - plo], [phi - pp["success_rate"]]],
                    fmt="s",
                    ms=3.5,
                    color=colors[n],
                    alpha=0.55,
                    lw=0.8,
                    capsize=0,
                )
                right = pp["success_rate"] > 0.85  # near 100 %: label on the left, inside the panel
                a.annotate(
                    p,
                    (plo if right else pp["success_rate"], yy),
                    xytext=(-4 if right else 4, 0),
                    textcoords="offset points",
                    fontsize=6,
                    va="center",
                    ha="right" if right else "left",
                    color="0.35",
                )
        a.annotate(f"{100 * r:.2f} %", (r, yi), xytext=(0, 7), textcoords="offset points", ha="center", fontsize=8.5)
    left = max(0.0, min(lows) - 0.05 * max(1e-3, 1 - min(lows)) - 0.01) if lows else 0.0
    a.set_xlim(left, 1.0 + (0.1 if len(paths) > 1 else 0.03) * (1.0 - left))
    _fmt_pct_axis(a)
    a.set(xlabel="success rate [%]", title="success rate, 95 % CI" + (" (small: per path)" if len(paths) > 1 else ""))
    a.set_yticks(y, names)
    a.grid(alpha=0.3, axis="x")

    a = ax[1]
    axes = [x for x in ("rear", "front", "joint") if any(x in ctrl[n].get("slip_margin", {}) for n in names)]
    if axes:
        markers = {"rear": "o", "front": "s", "joint": "D"}
        top, eps = 1.0, None
        for yi, n in zip(y, names):
            for j, x in enumerate(axes):
                m = ctrl[n].get("slip_margin", {}).get(x)
                if m is None:
                    continue
                eps = m["eps"]
                yy = yi + 0.28 - 0.56 * (j + 0.5) / len(axes)
                a.errorbar(
                    [m["margin"]],
                    [yy],
                    xerr=[[m["margin"] - m["margin_lo"]], [m["margin_hi"] - m["margin"]]],
                    fmt=markers[x],
                    ms=6,
                    color=colors[n],
                    capsize=3,
                    lw=1.5,
                    mfc="white" if m["censored"] else colors[n],
                )
                label = (
                    f"{x}: fails at {m['table'][0]['amplitude']:g}°"
                    if m.get("fails_at_smallest")
                    else f"{x} {'≥ ' if m['censored'] else ''}{m['margin']:g}°"
                )
                a.annotate(
                    label, (m["margin_hi"], yy), xytext=(6, 0), textcoords="offset points", fontsize=7, va="center"
                )
                top = max(top, m["margin_hi"])
        a.set_xlim(-0.03 * top - 0.3, 1.3 * top + 1)
        a.set_title("slip margin [lo, hi]" + (f", success ≥ {100 * (1 - eps):g} %" if eps else ""))
    else:
        a.text(
            0.5, 0.5, "no slip-margin sweep in this study", ha="center", va="center", transform=a.transAxes, color="0.4"
        )
        a.set_title("slip margin")
    a.set(xlabel="largest safe slip amplitude A [deg]")
    a.grid(alpha=0.3, axis="x")

    a = ax[2]
    spread = []
    for yi, n in zip(y, names):
        q = ctrl[n]["quantiles"]["iae"]
        if not q.get("n_finite"):
            continue
        spread += [q["q05"], q["q95"]]
        c = colors[n]
        a.plot([q["q05"], q["q95"]], [yi, yi], color=c, lw=1.2)
        a.fill_betweenx([yi - 0.18, yi + 0.18], q["q25"], q["q75"], color=c, alpha=0.45, lw=0)
        a.plot([q["q50"]] * 2, [yi - 0.22, yi + 0.22], color=c, lw=2.2)
        a.plot([q["mean"]], [yi], "D", color="k", ms=4)
    log = bool(spread) and min(spread) > 0 and max(spread) > 10 * min(spread)
    if log:
        _log_axis(a)
    a.set(xlabel="IAE = ∫|d| dt [m·s]" + (", log scale" if log else ""), title="IAE: p05–p95, p25–p75, median, ◆ mean")
    a.grid(alpha=0.3, axis="x")
    fig.suptitle(
        f"Study '{summary['study']}': {summary.get('n_runs_per_controller_and_path', '?')} runs per "
        f"controller and path ({len(paths)} path{'s' if len(paths) != 1 else ''})"
    )
    return fig


# ------------------------------------------------------------------------------- distributions


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
                _log_axis(a)
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
        _fmt_pct_axis(a, "y")
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
            sign = 1 if convention == "source" else -1
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
        _fmt_pct_axis(a, "y")
        a.grid(alpha=0.3)
    for a in ax[len(params) :]:
        a.set_visible(False)
    for r in range(nrows):
        ax[r * ncols].set_ylabel("success rate [%]")
    ax[0].legend(fontsize=7, loc="lower left")
    fig.suptitle("Success rate per bin of each varied parameter (equal-count bins, all paths pooled; bars: 95 % CI)")
    return fig
