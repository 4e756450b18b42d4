"""Numbers and texts of the Monte Carlo study report, formatted: percentages, intervals,
p-values, millimetres, distributions in words; a missing or non-finite value shows as an em dash."""

from __future__ import annotations

import math

from pfjax.report.document import Cell

__all__ = [
    "DASH",
    "cell",
    "fmt_ci",
    "fmt_dist",
    "fmt_gains",
    "fmt_margin",
    "fmt_mm",
    "fmt_num",
    "fmt_p",
    "fmt_pct",
    "fmt_times",
    "missing",
]

DASH = "—"


def missing(x) -> bool:
    return x is None or (isinstance(x, float) and not math.isfinite(x))


def fmt_pct(x, digits: int = 2) -> str:
    """A probability as a percentage: ``0.725 -> "72.50 %"``."""
    return DASH if missing(x) else f"{100 * x:.{digits}f} %"


def fmt_ci(ci, digits: int = 2) -> str:
    """A probability interval in percent: ``[0.561, 0.854] -> "[56.11, 85.40] %"``."""
    lo, hi = ci
    return DASH if missing(lo) or missing(hi) else f"[{100 * lo:.{digits}f}, {100 * hi:.{digits}f}] %"


def fmt_num(x, sig: int = 3) -> str:
    return DASH if missing(x) else f"{x:.{sig}g}"


def fmt_mm(x_m) -> str:
    """Metres shown in millimetres: ``0.0955 -> "95.5"``."""
    return DASH if missing(x_m) else f"{1000 * x_m:.1f}"


def fmt_dist(d) -> str:
    """A config distribution (dict from ``Dist.model_dump``) or a plain value, in words."""
    if not isinstance(d, dict) or "dist" not in d:
        return str(d)
    k = d["dist"]
    if k == "constant":
        return f"{d['value']:g} (fixed)"
    if k == "uniform":
        return f"uniform on [{d['low']:g}, {d['high']:g}]"
    if k == "normal":
        return f"normal, mean {d['mean']:g}, std {d['std']:g}"
    if k == "truncnormal":
        return f"normal, mean {d['mean']:g}, std {d['std']:g}, truncated to [{d['low']:g}, {d['high']:g}]"
    return "one of {" + ", ".join(f"{v:g}" for v in d["values"]) + "} (equally likely)"


def fmt_gains(gains, empty: str = DASH) -> str:
    """Scalar gains by name (:func:`pfjax.controllers.flat_gains`, what outputs record):
    ``{"k_d": -2.7381, "k_theta": -2.0772} -> "k_d = -2.738, k_theta = -2.077"``; ``empty`` for none."""
    return ", ".join(f"{k} = {v:.4g}" for k, v in gains.items()) or empty


def fmt_p(p: float) -> str:
    """A p-value: two significant digits, ``< 1e-16`` below double precision's resolution of 1 - p
    (a smaller number printed there would carry no information)."""
    if missing(p):
        return DASH
    return "< 1e-16" if p < 1e-16 else (f"{p:.1e}" if p < 1e-3 else f"{p:.2g}")


def fmt_times(x: float) -> str:
    """A ratio as "4,150×" or "2.35×" (never in exponent notation)."""
    return f"{x:,.0f}×" if x >= 100 else f"{x:.3g}×"


def cell(text, *, cls: str = "", swatch: str | None = None) -> Cell:
    """A report table cell (:class:`pfjax.report.document.Cell`)."""
    return Cell(text, cls, swatch)


def fmt_margin(m: dict | None) -> str:
    """A slip margin with its interval: ``"5° [2.5, 7.5]"``, ``"≥ 20° [20, 20]"`` when censored,
    ``"10° [none, 10]"`` when the conservative reading already fails at the smallest amplitude
    (:func:`pfjax.metrics.margins.slip_margin`'s ``fails_at_smallest_lo``)."""
    if not m:
        return "—"
    if m.get("fails_at_smallest"):
        return f"none: fails at {m['table'][0]['amplitude']:g}°"
    lo = "none" if m.get("fails_at_smallest_lo") else f"{m['margin_lo']:g}"
    return f"{'≥ ' if m['censored'] else ''}{m['margin']:g}° [{lo}, {m['margin_hi']:g}]"
