"""The Monte Carlo study report's run tables: run status, worst sampled runs, failure drivers,
worst cases found, rare failures and the float32-vs-float64 check, as rows of
:class:`pfjax.report.document.Cell` built from the summary and the run table (nothing recomputed
beyond counting rows)."""

from __future__ import annotations

import pandas as pd

from pfjax.metrics.robustness import worst_first
from pfjax.report.study_format import DASH, cell, fmt_ci, fmt_margin, fmt_mm, fmt_num, fmt_p, fmt_pct
from pfjax.sim.status import STATUS_NAMES

__all__ = [
    "drivers",
    "headline_rows",
    "per_path_rows",
    "precision_rows",
    "rare_event_rows",
    "status_table",
    "worst_case_rows",
    "worst_runs",
]


def headline_rows(summary: dict, colors: dict, axes: list[str]) -> list[list]:
    rows = []
    for n, c in summary["controllers"].items():
        rows.append(
            [
                cell(n, swatch=colors[n]),
                cell(f"{c['k']} / {c['n']}"),
                cell(fmt_pct(c["success_rate"])),
                cell(fmt_ci(c["success_ci95"])),
                cell(fmt_num(c["iae_mean"])),
                cell(fmt_num(c["iae_p95"])),
                cell(fmt_mm(c["steady_abs_d_p95"])),
            ]
            + [cell(fmt_margin(c.get("slip_margin", {}).get(x))) for x in axes]
        )
    return rows


def per_path_rows(summary: dict, colors: dict) -> list[list]:
    rows = []
    for n, c in summary["controllers"].items():
        for p, b in c["per_path"].items():
            st = ", ".join(f"{k} {v}" for k, v in b["status_counts"].items())
            rows.append(
                [
                    cell(n, swatch=colors[n]),
                    cell(p),
                    cell(f"{b['k']} / {b['n']}"),
                    cell(fmt_pct(b["success_rate"])),
                    cell(fmt_ci(b["success_ci95"])),
                    cell(fmt_num(b["iae_mean"])),
                    cell(fmt_num(b["iae_p95"])),
                    cell(fmt_mm(b["steady_abs_d_p95"])),
                    cell(st, cls="bad" if set(b["status_counts"]) - {"ok"} else ""),
                ]
            )
    return rows


def status_table(runs: pd.DataFrame, colors: dict) -> tuple[list[str], list[list]]:
    """Per controller and path (and the controller's total): successes, runs that ran to the end but
    missed the band, and the count of every status code (:mod:`pfjax.sim.status`)."""
    names = list(STATUS_NAMES.values())
    head = ["controller", "path", "runs", "success", "ok but outside the band"] + [f"status {s}" for s in names]
    rows = []

    def row(n, path, g, total=False):
        ok = (g["status"] == "ok").to_numpy()
        succ = g["success"].to_numpy(bool)
        counts = g["status"].value_counts()
        r = [
            cell(n, swatch=colors[n]),
            cell(path, cls="total" if total else ""),
            cell(str(len(g))),
            cell(str(int(succ.sum())), cls="good"),
            cell(str(int((ok & ~succ).sum())), cls="warn" if (ok & ~succ).any() else ""),
        ]
        return r + [
            cell(str(int(counts.get(s, 0))), cls="bad" if s != "ok" and counts.get(s, 0) else "") for s in names
        ]

    for n, g in runs.groupby("controller", sort=False):
        by_path = list(g.groupby("path", sort=False))
        rows += [row(n, p, gp) for p, gp in by_path]
        if len(by_path) > 1:
            rows.append(row(n, "all paths", g, total=True))
    return head, rows


def precision_rows(summary: dict, colors: dict) -> list[list]:
    """The float32-vs-float64 check (:func:`pfjax.montecarlo.checks.float64_check`), one row per controller."""
    chk = summary.get("float64_check") or {}
    rows = []
    for n, c in (chk.get("controllers") or {}).items():
        mism = ", ".join(
            f"{m['path']} run {m['run']}: {m['float32']} vs {m['float64']}" for m in c["status_mismatches"][:3]
        )
        rows.append(
            [
                cell(n, swatch=colors.get(n, "#888")),
                cell(str(c["n"])),
                cell(fmt_num(c["max_abs_diff_iae"], 3)),
                cell(fmt_num(c["max_rel_diff_iae"], 3)),
                cell(fmt_num(c["max_abs_diff_late_max_abs_d"], 3)),
                cell(fmt_pct(c["status_agreement"]), cls="" if c["status_agreement"] == 1 else "warn"),
                cell(fmt_pct(c["success_agreement"]), cls="" if c["success_agreement"] == 1 else "warn"),
                cell(mism or DASH),
            ]
        )
    return rows


def worst_runs(runs: pd.DataFrame, params: list[str], n_show: int = 5) -> dict[str, list[list]]:
    """Per controller, the worst sampled runs (:func:`pfjax.metrics.robustness.worst_first`): failures
    first (earliest failure first), then the largest late max |d|."""
    out = {}
    for name, g in runs.groupby("controller", sort=False):
        g = worst_first(g).head(n_show)
        out[name] = [
            [
                cell(r.path),
                cell(str(r.run)),
                cell(r.status, cls="bad" if r.status != "ok" else ""),
                cell(fmt_num(r.fail_time)),
                cell(fmt_mm(r.late_max_abs_d)),
                cell(fmt_num(r.iae)),
                cell("yes" if r.success else "no", cls="good" if r.success else "warn"),
            ]
            + [cell(fmt_num(getattr(r, p))) for p in params]
            for r in g.itertuples(index=False)
        ]
    return out


def drivers(summary: dict) -> dict[str, list[list]]:
    out = {}
    for n, c in summary["controllers"].items():
        out[n] = [
            [
                cell(d["parameter"]),
                cell(fmt_num(d["rho_failure"], 2)),
                cell(fmt_p(d["p_failure"])),
                cell(fmt_num(d["rho_metric"], 2)),
                cell(fmt_p(d["p_metric"])),
                cell(fmt_num(d["effect_size"], 2)),
            ]
            for d in c.get("failure_drivers", [])
        ]
    return out


def worst_case_rows(summary: dict, colors: dict) -> list:
    rows = []
    for n, c in summary["controllers"].items():
        wc = c.get("worst_case")
        if wc:
            rows.append(
                [
                    cell(n, swatch=colors[n]),
                    cell(wc["path"]),
                    cell(wc["objective"]),
                    cell(f"{wc['falsifier']:.4g} ({wc['falsifier_status']})"),
                    cell(f"{wc['random']:.4g} ({wc['random_status']})"),
                    cell(f"{wc['ratio']:.2f}×"),
                    cell(str(wc["n_rollouts"])),
                    cell(
                        f"d₀ = {wc['worst_ic']['d0']:+.3f} m, θₑ₀ = {wc['worst_ic']['theta_e0_deg']:+.1f}°, "
                        f"peak |β_r|, |β_f| = {wc['worst_slip_peak_deg'][0]:.1f}°, {wc['worst_slip_peak_deg'][1]:.1f}°"
                    ),
                ]
            )
    return rows


#: Failure points (the importance-sampling proposal's modes) shown per controller.
RARE_POINTS = 3


def _failure_point_text(q: dict) -> str:
    """``"sine, 44 %: beta_r_deg = -4 (-3.1σ), beta_f_deg = 4 (+3.2σ)"``: a failure point's path,
    weight and the inputs that drive it (``drivers``: far from their medians, in config units)."""
    drv = q.get("drivers") or []
    what = ", ".join(f"{d['key'].split('.')[-1]} = {d['value']:.3g} ({d['u']:+.1f}σ)" for d in drv) or "near nominal"
    return f"{q.get('path', '')}, {100 * q['weight']:.0f} %: {what}"


def rare_event_rows(summary: dict, colors: dict) -> list:
    """Per controller: the rare-event estimate beside the plain failure rate of the study's runs, and
    the failure modes the estimate found (:mod:`pfjax.rare.importance`), with what drives each (``[rare_event]``,
    :mod:`pfjax.rare`)."""
    rows = []
    for n, c in summary["controllers"].items():
        if "p_fail" not in c:
            continue
        lo, hi = c["p_fail_ci95"]
        plain, plain_ci = c.get("plain_fail"), c.get("plain_fail_ci95")  # the same event as p_fail
        points = c["rare_event"].get("failure_points") or []
        top = "; ".join(_failure_point_text(q) for q in points[:RARE_POINTS]) if points else "—"
        rel = "—" if c["rel_error"] is None else f"{100 * c['rel_error']:.1f} %"
        warn = c["rare_event"].get("warning")
        rows.append(
            [
                cell(n, swatch=colors[n]),
                cell(f"{c['p_fail']:.3g} [{lo:.3g}, {hi:.3g}]" + (f" (warning: {warn})" if warn else "")),
                cell(rel),
                cell(f"{c['n_rollouts']} ({c['method']})"),
                cell("—" if plain is None else f"{plain:.3g} [{plain_ci[0]:.3g}, {plain_ci[1]:.3g}]"),
                cell(top),
            ]
        )
    return rows
