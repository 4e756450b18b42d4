"""The Monte Carlo study report's headline figure: per controller, success rate with its interval,
slip margin per axis and IAE spread, side by side."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from pfjax.report.figure_style import log_axis, pct_axis

__all__ = ["headline_figure"]


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
    paths = summary.get("paths", [])
    _success_panel(ax[0], summary, colors, y)
    _margin_panel(ax[1], ctrl, colors, y)
    _iae_panel(ax[2], ctrl, colors, y)
    fig.suptitle(
        f"Study '{summary['study']}': {summary.get('n_runs_per_controller_and_path', '?')} runs per "
        f"controller and path ({len(paths)} path{'s' if len(paths) != 1 else ''})"
    )
    return fig


def _success_panel(a, summary: dict, colors: dict[str, str], y: np.ndarray) -> None:
    """Success rate with its 95 % interval per controller, and per path as small markers."""
    ctrl = summary["controllers"]
    names = list(ctrl)
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
    pct_axis(a)
    a.set(xlabel="success rate [%]", title="success rate, 95 % CI" + (" (small: per path)" if len(paths) > 1 else ""))
    a.set_yticks(y, names)
    a.grid(alpha=0.3, axis="x")


def _margin_panel(a, ctrl: dict, colors: dict[str, str], y: np.ndarray) -> None:
    """Slip margin per axis with its ``[lo, hi]`` (hollow marker: censored)."""
    names = list(ctrl)
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


def _iae_panel(a, ctrl: dict, colors: dict[str, str], y: np.ndarray) -> None:
    """IAE quantiles: box p25-p75, whiskers p05-p95, tick the median, diamond the mean."""
    names = list(ctrl)
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
        log_axis(a)
    a.set(xlabel="IAE = ∫|d| dt [m·s]" + (", log scale" if log else ""), title="IAE: p05–p95, p25–p75, median, ◆ mean")
    a.grid(alpha=0.3, axis="x")


# ------------------------------------------------------------------------------- distributions
