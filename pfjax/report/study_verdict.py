"""The Monte Carlo study report's verdict: controllers ranked by success rate, and the best one
compared with each other one *paired*.

Every controller ran the same scenarios (common random numbers), so for two controllers A and B
the runs where exactly one of them succeeds decide the comparison. With ``b`` runs where A succeeds
and B fails and ``c`` the reverse, the difference in success rate is ``D = (b - c) / n``, with
Tango's 95 % score interval for paired proportions (:func:`pfjax.metrics.robustness.paired_interval`,
which keeps a width when the two controllers' outcomes are identical, where the Wald interval has none),
and the exact McNemar test of "equally robust" is the two-sided binomial test of ``b`` successes
in ``b + c`` trials at ``p = 1/2``. That distribution is symmetric, so its p-value is twice the
smaller tail, ``min(1, 2 P(X <= min(b, c)))`` with ``X ~ Bin(b + c, 1/2)`` (``scipy.stats.binomtest``'s
to 1e-10 relative, tested; computed with ``scipy.special``, which imports about 0.5 s faster
than ``scipy.stats``).
"""

from __future__ import annotations

import math

import pandas as pd
from scipy import special

from pfjax.metrics.robustness import paired_interval
from pfjax.report.document import Cell
from pfjax.report.study_format import DASH, cell, fmt_ci, fmt_margin, fmt_num, fmt_p, fmt_pct, fmt_times, missing

__all__ = ["paired", "verdict"]


def paired(runs: pd.DataFrame, a: str, b: str) -> dict:
    """Paired comparison of controllers ``a`` and ``b`` over the scenarios both ran (module docstring)."""
    sa = runs.loc[runs.controller == a, ["path", "run", "success"]]
    sb = runs.loc[runs.controller == b, ["path", "run", "success"]]
    m = sa.merge(sb, on=["path", "run"], suffixes=("_a", "_b"))
    x, y = m["success_a"].to_numpy(bool), m["success_b"].to_numpy(bool)
    n, only_a, only_b = len(m), int((x & ~y).sum()), int((~x & y).sum())
    p = min(1.0, 2.0 * float(special.bdtr(min(only_a, only_b), only_a + only_b, 0.5))) if only_a + only_b else 1.0
    diff = (only_a - only_b) / n if n else math.nan
    return {"n": n, "only_a": only_a, "only_b": only_b, "diff": diff, "ci": paired_interval(only_a, only_b, n), "p": p}


def verdict(summary: dict, runs: pd.DataFrame) -> tuple[str, list[str], list[list]]:
    """Controllers ranked by success rate (then its lower bound, then mean IAE), and how the best
    compares with each other one: sentences and a table."""
    ctrl = summary["controllers"]
    neg = lambda v: None if missing(v) else -v
    key = lambda n: (neg(ctrl[n]["success_rate"]), neg(ctrl[n]["success_ci95"][0]), ctrl[n]["iae_mean"])
    ranked = sorted(ctrl, key=lambda n: tuple(math.inf if missing(v) else v for v in key(n)))
    best = ranked[0]
    cb = ctrl[best]
    lines: list[str] = []
    rows: list[list[Cell]] = []
    if len(ranked) == 1:
        return (
            best,
            [f"Only one controller, {best}: success {fmt_pct(cb['success_rate'])} {fmt_ci(cb['success_ci95'])}."],
            rows,
        )
    for other in ranked[1:]:
        co = ctrl[other]
        pr = paired(runs, best, other)
        sig = pr["p"] < 0.05
        f_best, f_other = 1 - cb["success_rate"], 1 - co["success_rate"]
        ratio = (
            f"{other} fails {fmt_times(f_other / f_best)} as often"
            if f_best > 0
            else (
                f"{best} never failed, {other} did in {fmt_pct(f_other)} of runs" if f_other > 0 else "neither failed"
            )
        )
        mb, mo = cb.get("slip_margin", {}).get("joint"), co.get("slip_margin", {}).get("joint")
        margin = f" Joint slip margin: {best} {fmt_margin(mb)}, {other} {fmt_margin(mo)}." if mb and mo else ""
        lines.append(
            f"{best} succeeds in {fmt_pct(cb['success_rate'])} of runs {fmt_ci(cb['success_ci95'])}, {other} in "
            f"{fmt_pct(co['success_rate'])} {fmt_ci(co['success_ci95'])}: {100 * pr['diff']:.2f} percentage points "
            f"{'more' if sig else 'apart, not a significant difference'} (paired 95 % CI [{100 * pr['ci'][0]:.2f}, "
            f"{100 * pr['ci'][1]:.2f}]; {ratio}). On the same {pr['n']} scenarios, {best} succeeded where {other} failed "
            f"{pr['only_a']} times and the reverse happened {pr['only_b']} times (exact McNemar p {'= ' if pr['p'] >= 1e-16 else ''}"
            f"{fmt_p(pr['p'])}).{margin}"
        )
        rows.append(
            [
                cell(other),
                cell(f"{-100 * pr['diff']:+.2f} pp"),
                cell(f"[{-100 * pr['ci'][1]:+.2f}, {-100 * pr['ci'][0]:+.2f}] pp"),
                cell(f"{pr['only_a']} / {pr['only_b']}"),
                cell(fmt_p(pr["p"]), cls="good" if sig else ""),
                cell(
                    DASH
                    if missing(co["iae_mean"]) or missing(cb["iae_mean"]) or not cb["iae_mean"]
                    else fmt_num(co["iae_mean"] / cb["iae_mean"]) + "×"
                ),
            ]
        )
    return best, lines, rows
