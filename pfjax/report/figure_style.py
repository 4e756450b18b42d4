"""The look shared by the Monte Carlo study report's figures: one colour per controller, a frozen
layout, logarithmic and percentage axes, the slip-margin axis titles."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import LogLocator, NullLocator

__all__ = ["AXIS_TITLE", "controller_colors", "freeze_layout", "log_axis", "pct_axis"]

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


def log_axis(ax, axis="x"):
    """Log scale with plain tick labels at 1, 2, 5 x 10^k."""
    ax.set_xscale("log") if axis == "x" else ax.set_yscale("log")
    a = ax.xaxis if axis == "x" else ax.yaxis
    lo, hi = ax.get_xlim() if axis == "x" else ax.get_ylim()
    decades = np.log10(hi / lo) if lo > 0 and hi > lo else 1.0
    subs = (1.0, 2.0, 5.0) if decades <= 2.2 else (1.0, 3.0) if decades <= 3.5 else (1.0,)
    a.set_major_locator(LogLocator(base=10, subs=subs))
    a.set_major_formatter(lambda v, _: f"{v:g}")
    a.set_minor_locator(NullLocator())


def pct_axis(ax, axis="x"):
    (ax.xaxis if axis == "x" else ax.yaxis).set_major_formatter(
        lambda v, _: f"{100 * v:.10g}" if -1e-9 <= v <= 1 + 1e-9 else ""
    )


# ------------------------------------------------------------------------------- headline
