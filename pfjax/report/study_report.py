"""A Monte Carlo study's ``report.html``: one self-contained page a person reads to see which
controller is more robust and by how much.

:func:`write_report` renders ``templates/study.html.j2`` (Jinja2) with the study's summary (see
:mod:`pfjax.montecarlo.summary`), its run table and its slip-margin sweep. Figures
(:mod:`pfjax.report.study_figures`) are written to ``figures/<name>.png`` and ``.svg`` and
embedded in the page as base64 PNG; CSS is inline, so the page needs nothing beside it.

The verdict compares controllers *paired*: every controller ran the same scenarios (common random
numbers), so for two controllers A and B the runs where exactly one of them succeeds decide the
comparison. With ``b`` runs where A succeeds and B fails and ``c`` the reverse, the difference in
success rate is ``D = (b - c) / n``, with the paired (Wald) 95 % interval::

    D +- 1.96 sqrt((b + c) - (b - c)^2 / n) / n

and the exact McNemar test of "equally robust" is the two-sided binomial test of ``b`` successes
in ``b + c`` trials at ``p = 1/2``.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path

import numpy as np
import pandas as pd
from jinja2 import Environment, FileSystemLoader, StrictUndefined
from scipy import stats

from pfjax.controllers import style
from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.sampling import SLIP_COLUMNS, column_names
from pfjax.report.figure_set import _figures
from pfjax.report.study_figures import controller_colors, fmt_margin
from pfjax.sim.status import STATUS_NAMES

TEMPLATES = Path(__file__).resolve().parent / "templates"
DASH = "—"


# ------------------------------------------------------------------------------- formatting


def _bad(x) -> bool:
    return x is None or (isinstance(x, float) and not math.isfinite(x))


def fmt_pct(x, digits: int = 2) -> str:
    """A probability as a percentage: ``0.725 -> "72.50 %"``."""
    return DASH if _bad(x) else f"{100 * x:.{digits}f} %"


def fmt_ci(ci, digits: int = 2) -> str:
    """A probability interval in percent: ``[0.561, 0.854] -> "[56.11, 85.40] %"``."""
    lo, hi = ci
    return DASH if _bad(lo) or _bad(hi) else f"[{100 * lo:.{digits}f}, {100 * hi:.{digits}f}] %"


def fmt_num(x, sig: int = 3) -> str:
    return DASH if _bad(x) else f"{x:.{sig}g}"


def fmt_mm(x_m) -> str:
    """Metres shown in millimetres: ``0.0955 -> "95.5"``."""
    return DASH if _bad(x_m) else f"{1000 * x_m:.1f}"


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


def _path_description(kind: str) -> str:
    """A registered path's one-line description (:data:`pfjax.paths.PATHS`)."""
    from pfjax.paths import PATHS

    return PATHS[kind].description if kind in PATHS else kind


def _cell(text, *, cls: str = "", swatch: str | None = None) -> dict:
    return {"text": text, "cls": cls, "swatch": swatch}


# ------------------------------------------------------------------------------- content


def _setup(cfg: dict, summary: dict) -> dict:
    """The study set-up: what was varied and how, what was held fixed, and the success criterion."""
    veh, slip, ini, noise, sim = cfg["vehicle"], cfg["slip"], cfg["initial"], cfg["noise"], cfg["sim"]
    rate = veh["delta_rate_max_deg"]
    rows = [
        ("speed v [m/s]", veh["speed"]),
        ("wheelbase L [m]", veh["L"]),
        ("steering limit δ_max [deg]", veh["delta_max_deg"]),
        ("steering rate limit [deg/s]", "none" if rate is None or _bad(rate) or rate == "inf" else rate),
        ("slip model", f"{slip['kind']} (convention: {veh['convention']})"),
        ("rear slip β_r [deg]", slip["beta_r_deg"]),
        ("front slip β_f [deg]", slip["beta_f_deg"]),
    ]
    units = {
        "step_time_s": "step time [s]",
        "step_r_deg": "rear step [deg]",
        "step_f_deg": "front step [deg]",
        "amp_r_deg": "rear sinusoid amplitude [deg]",
        "amp_f_deg": "front sinusoid amplitude [deg]",
        "freq_hz": "sinusoid frequency [Hz]",
        "ou_sigma_deg": "OU stationary std [deg]",
        "ou_tau_s": "OU time constant [s]",
    }
    rows += [(units[k], slip[k]) for k in SLIP_COLUMNS[slip["kind"]]]
    if veh.get("model", "kinematic") in ("st", "std"):  # slip from the tyre forces: the ST model's settings instead
        rows = [
            ("speed reference v [m/s]", veh["speed"]),
            ("vehicle model", f"single-track (CommonRoad {veh['model'].upper()}), parameter set {veh['params']}"),
            ("friction μ", "the parameter set's" if veh["mu"] is None else veh["mu"]),
            ("steering actuator time constant [s]", veh["tau_delta_s"]),
            ("speed loop gain [1/s]", veh["k_v"]),
        ]
    if slip["kind"] == "sinusoid":
        rows.append(("sinusoid phase", "uniform on [0, 2π), per axle"))
    if slip["kind"] == "ou":
        rows.append(("OU sampling period [s]", slip["seq_dt"]))
    rows += [
        ("start along the path [m]", ini["start_along_m"]),
        ("initial lateral offset [m]", ini["lateral_offset"]),
        ("initial heading error [deg]", ini["heading_error_deg"]),
        ("measurement noise on d [m]", f"normal, std {noise['sigma_d']:g}" if noise["sigma_d"] else "none"),
        (
            "measurement noise on θ_e [deg]",
            f"normal, std {noise['sigma_theta_e_deg']:g}" if noise["sigma_theta_e_deg"] else "none",
        ),
    ]
    uncertain = [
        {"name": n, "dist": fmt_dist(d), "varies": isinstance(d, dict) and d.get("dist") not in (None, "constant")}
        for n, d in rows
    ]
    paths = []
    for p in cfg["paths"]:
        extra = {
            "circle": f"radius {fmt_dist(p['radius'])} m",
            "random": f"random smooth spline, length {p['length']:g} m, |κ| ≤ {p['curvature_margin']:g} · tan(δ_max)/L, "
            f"{p['n_waypoints']} waypoints, one per run",
            "spline": f"user-defined: natural cubic spline through {len(p.get('points') or [])} points, "
            f"from ({(p.get('points') or [[0, 0]])[0][0]:g}, {(p.get('points') or [[0, 0]])[0][1]:g}) m",
        }
        paths.append(
            {
                "name": p.get("name") or p["kind"],
                "kind": p["kind"],
                "detail": extra.get(p["kind"]) or _path_description(p["kind"]),
            }
        )
    ctrls = []
    for c in cfg["controllers"]:
        gains = summary["controllers"].get(c["name"], {}).get("gains", {})
        how = {
            "lmi": f"mixed H2/H∞ LMI design (α = {c['alpha']:g}, β = {c['beta']:g}) at the nominal speed and wheelbase",
            "state_feedback": "state feedback δ = K [d, θ_e]",
        }.get(c["type"]) or style(c["type"])["label"]
        ctrls.append(
            {
                "name": c["name"],
                "type": c["type"],
                "how": how,
                "gains": ", ".join(f"{k} = {v:.4g}" for k, v in gains.items()) or "defaults",
            }
        )
    m = cfg["margin"]
    return {
        "uncertain": uncertain,
        "paths": paths,
        "controllers": ctrls,
        "n_runs": cfg["n_runs"],
        "seed": cfg["seed"],
        "dtype": cfg["dtype"],
        "chunk_size": cfg["chunk_size"],
        "sim": f"horizon {sim['horizon']:g} s, RK4 step {1000 * sim['dt']:g} ms, controller every {sim['control_every']} step(s); "
        f"failure when |d| > {sim['d_fail']:g} m; steady state = last {sim['steady_window']:g} s; "
        f"settled within ±{100 * sim['settle_band']:g} cm",
        "success": f"|d| ≤ {100 * cfg['success']['band']:g} cm at every sample from t = {cfg['success']['from_s']:g} s "
        f"to the end of the horizon, and no failure flag (status 'ok')",
        "margin": (
            f"{m['n_per_amplitude']} runs per amplitude, per path and per controller at constant slip of magnitude A "
            f"(random sign) on {', '.join(m['axes'])}, A ∈ {{{', '.join(f'{a:g}' for a in m['amplitudes_deg'])}}} deg, "
            f"everything else sampled as above; margin = largest A with success ≥ 1 − ε = {100 * (1 - m['eps']):g} % "
            f"there and at every smaller A"
        )
        if m["enabled"]
        else "not run",
    }


def _paired(runs: pd.DataFrame, a: str, b: str) -> dict:
    """Paired comparison of controllers ``a`` and ``b`` over the scenarios both ran (module docstring)."""
    sa = runs.loc[runs.controller == a, ["path", "run", "success"]]
    sb = runs.loc[runs.controller == b, ["path", "run", "success"]]
    m = sa.merge(sb, on=["path", "run"], suffixes=("_a", "_b"))
    x, y = m["success_a"].to_numpy(bool), m["success_b"].to_numpy(bool)
    n, only_a, only_b = len(m), int((x & ~y).sum()), int((~x & y).sum())
    p = float(stats.binomtest(only_a, only_a + only_b, 0.5).pvalue) if only_a + only_b else 1.0
    diff = (only_a - only_b) / n if n else math.nan
    half = (
        stats.norm.ppf(0.975) * math.sqrt(max(only_a + only_b - (only_a - only_b) ** 2 / n, 0.0)) / n if n else math.nan
    )
    return {"n": n, "only_a": only_a, "only_b": only_b, "diff": diff, "ci": (diff - half, diff + half), "p": p}


def fmt_p(p: float) -> str:
    """A p-value: two significant digits, ``< 1e-16`` below double precision's resolution of 1 - p
    (a smaller number printed there would carry no information)."""
    if _bad(p):
        return DASH
    return "< 1e-16" if p < 1e-16 else (f"{p:.1e}" if p < 1e-3 else f"{p:.2g}")


def fmt_times(x: float) -> str:
    """A ratio as "4,150×" or "2.35×" (never in exponent notation)."""
    return f"{x:,.0f}×" if x >= 100 else f"{x:.3g}×"


def _verdict(summary: dict, runs: pd.DataFrame) -> tuple[str, list[str], list[list]]:
    """Controllers ranked by success rate (then its lower bound, then mean IAE), and how the best
    compares with each other one: sentences and a table."""
    ctrl = summary["controllers"]
    neg = lambda v: None if _bad(v) else -v
    key = lambda n: (neg(ctrl[n]["success_rate"]), neg(ctrl[n]["success_ci95"][0]), ctrl[n]["iae_mean"])
    ranked = sorted(ctrl, key=lambda n: tuple(math.inf if _bad(v) else v for v in key(n)))
    best = ranked[0]
    cb = ctrl[best]
    lines: list[str] = []
    rows: list[list[dict]] = []
    if len(ranked) == 1:
        return (
            best,
            [f"Only one controller, {best}: success {fmt_pct(cb['success_rate'])} {fmt_ci(cb['success_ci95'])}."],
            rows,
        )
    for other in ranked[1:]:
        co = ctrl[other]
        pr = _paired(runs, best, other)
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
                _cell(other),
                _cell(f"{-100 * pr['diff']:+.2f} pp"),
                _cell(f"[{-100 * pr['ci'][1]:+.2f}, {-100 * pr['ci'][0]:+.2f}] pp"),
                _cell(f"{pr['only_a']} / {pr['only_b']}"),
                _cell(fmt_p(pr["p"]), cls="good" if sig else ""),
                _cell(
                    DASH
                    if _bad(co["iae_mean"]) or _bad(cb["iae_mean"]) or not cb["iae_mean"]
                    else fmt_num(co["iae_mean"] / cb["iae_mean"]) + "×"
                ),
            ]
        )
    return best, lines, rows


def _headline_rows(summary: dict, colors: dict, axes: list[str]) -> list[list]:
    rows = []
    for n, c in summary["controllers"].items():
        rows.append(
            [
                _cell(n, swatch=colors[n]),
                _cell(f"{c['k']} / {c['n']}"),
                _cell(fmt_pct(c["success_rate"])),
                _cell(fmt_ci(c["success_ci95"])),
                _cell(fmt_num(c["iae_mean"])),
                _cell(fmt_num(c["iae_p95"])),
                _cell(fmt_mm(c["steady_abs_d_p95"])),
            ]
            + [_cell(fmt_margin(c.get("slip_margin", {}).get(x))) for x in axes]
        )
    return rows


def _per_path_rows(summary: dict, colors: dict) -> list[list]:
    rows = []
    for n, c in summary["controllers"].items():
        for p, b in c["per_path"].items():
            st = ", ".join(f"{k} {v}" for k, v in b["status_counts"].items())
            rows.append(
                [
                    _cell(n, swatch=colors[n]),
                    _cell(p),
                    _cell(f"{b['k']} / {b['n']}"),
                    _cell(fmt_pct(b["success_rate"])),
                    _cell(fmt_ci(b["success_ci95"])),
                    _cell(fmt_num(b["iae_mean"])),
                    _cell(fmt_num(b["iae_p95"])),
                    _cell(fmt_mm(b["steady_abs_d_p95"])),
                    _cell(st, cls="bad" if set(b["status_counts"]) - {"ok"} else ""),
                ]
            )
    return rows


def _status_table(runs: pd.DataFrame, colors: dict) -> tuple[list[str], list[list]]:
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
            _cell(n, swatch=colors[n]),
            _cell(path, cls="total" if total else ""),
            _cell(str(len(g))),
            _cell(str(int(succ.sum())), cls="good"),
            _cell(str(int((ok & ~succ).sum())), cls="warn" if (ok & ~succ).any() else ""),
        ]
        return r + [
            _cell(str(int(counts.get(s, 0))), cls="bad" if s != "ok" and counts.get(s, 0) else "") for s in names
        ]

    for n, g in runs.groupby("controller", sort=False):
        by_path = list(g.groupby("path", sort=False))
        rows += [row(n, p, gp) for p, gp in by_path]
        if len(by_path) > 1:
            rows.append(row(n, "all paths", g, total=True))
    return head, rows


def _precision_rows(summary: dict, colors: dict) -> list[list]:
    """The float32-vs-float64 check (:func:`pfjax.montecarlo.checks.float64_check`), one row per controller."""
    chk = summary.get("float64_check") or {}
    rows = []
    for n, c in (chk.get("controllers") or {}).items():
        mism = ", ".join(
            f"{m['path']} run {m['run']}: {m['float32']} vs {m['float64']}" for m in c["status_mismatches"][:3]
        )
        rows.append(
            [
                _cell(n, swatch=colors.get(n, "#888")),
                _cell(str(c["n"])),
                _cell(fmt_num(c["max_abs_diff_iae"], 3)),
                _cell(fmt_num(c["max_rel_diff_iae"], 3)),
                _cell(fmt_num(c["max_abs_diff_late_max_abs_d"], 3)),
                _cell(fmt_pct(c["status_agreement"]), cls="" if c["status_agreement"] == 1 else "warn"),
                _cell(fmt_pct(c["success_agreement"]), cls="" if c["success_agreement"] == 1 else "warn"),
                _cell(mism or DASH),
            ]
        )
    return rows


def _worst_runs(runs: pd.DataFrame, params: list[str], n_show: int = 5) -> dict[str, list[list]]:
    """Per controller, the worst sampled runs: failures first (earliest failure first), then the
    largest late max |d|."""
    out = {}
    for name, g in runs.groupby("controller", sort=False):
        g = g.assign(
            _failed=(g["status"] != "ok"), _ft=g["fail_time"].fillna(np.inf), _late=g["late_max_abs_d"].fillna(np.inf)
        )
        g = g.sort_values(["_failed", "_ft", "_late"], ascending=[False, True, False], kind="stable").head(n_show)
        out[name] = [
            [
                _cell(r.path),
                _cell(str(r.run)),
                _cell(r.status, cls="bad" if r.status != "ok" else ""),
                _cell(fmt_num(r.fail_time)),
                _cell(fmt_mm(r.late_max_abs_d)),
                _cell(fmt_num(r.iae)),
                _cell("yes" if r.success else "no", cls="good" if r.success else "warn"),
            ]
            + [_cell(fmt_num(getattr(r, p))) for p in params]
            for r in g.itertuples(index=False)
        ]
    return out


def _drivers(summary: dict) -> dict[str, list[list]]:
    out = {}
    for n, c in summary["controllers"].items():
        out[n] = [
            [
                _cell(d["parameter"]),
                _cell(fmt_num(d["rho_failure"], 2)),
                _cell(fmt_p(d["p_failure"])),
                _cell(fmt_num(d["rho_metric"], 2)),
                _cell(fmt_p(d["p_metric"])),
                _cell(fmt_num(d["effect_size"], 2)),
            ]
            for d in c.get("failure_drivers", [])
        ]
    return out


def _worst_case_rows(summary: dict, colors: dict) -> list:
    rows = []
    for n, c in summary["controllers"].items():
        wc = c.get("worst_case")
        if wc:
            rows.append(
                [
                    _cell(n, swatch=colors[n]),
                    _cell(wc["path"]),
                    _cell(wc["objective"]),
                    _cell(f"{wc['falsifier']:.4g} ({wc['falsifier_status']})"),
                    _cell(f"{wc['random']:.4g} ({wc['random_status']})"),
                    _cell(f"{wc['ratio']:.2f}×"),
                    _cell(str(wc["n_rollouts"])),
                    _cell(
                        f"d₀ = {wc['worst_ic']['d0']:+.3f} m, θₑ₀ = {wc['worst_ic']['theta_e0_deg']:+.1f}°, "
                        f"peak |β_r|, |β_f| = {wc['worst_slip_peak_deg'][0]:.1f}°, {wc['worst_slip_peak_deg'][1]:.1f}°"
                    ),
                ]
            )
    return rows


def _rare_event_rows(summary: dict, colors: dict) -> list:
    """Per controller: the rare-event estimate beside the plain failure rate of the study's runs, and
    the most likely failure point the estimate found (``[rare_event]``, :mod:`pfjax.rare`)."""
    rows = []
    for n, c in summary["controllers"].items():
        if "p_fail" not in c:
            continue
        lo, hi = c["p_fail_ci95"]
        plain = 1 - c["success_rate"]
        plain_ci = (1 - c["success_ci95"][1], 1 - c["success_ci95"][0])
        points = c["rare_event"].get("failure_points") or []
        top = (
            ", ".join(
                f"{k.split('.')[-1]} = {v:.3g}" if isinstance(v, (int, float)) else f"{k.split('.')[-1]} = {v}"
                for k, v in points[0].items()
                if k != "weight"
            )
            if points
            else "—"
        )
        rel = "—" if c["rel_error"] is None else f"{100 * c['rel_error']:.1f} %"
        rows.append(
            [
                _cell(n, swatch=colors[n]),
                _cell(f"{c['p_fail']:.3g} [{lo:.3g}, {hi:.3g}]"),
                _cell(rel),
                _cell(f"{c['n_rollouts']} ({c['method']})"),
                _cell(f"{plain:.3g} [{plain_ci[0]:.3g}, {plain_ci[1]:.3g}]"),
                _cell(top),
            ]
        )
    return rows


def write_report(
    out_dir: Path,
    spec: StudySpec,
    summary: dict,
    runs: pd.DataFrame,
    worst_trajectories: dict | None = None,
    figures: dict | None = None,
) -> None:
    """Write ``out_dir/report.html`` (self-contained) and ``out_dir/figures/<name>.png|svg``.

    Args:
        out_dir: the study's output directory (created if missing).
        spec: the validated study.
        summary: the study summary (:func:`pfjax.montecarlo.summary.summarize`).
        runs: one row per run (``runs.parquet``).
        worst_trajectories: the falsifier's worst runs per controller (:mod:`pfjax.montecarlo.worst_case`),
            or None when the study did no worst-case search.
        figures: :func:`pfjax.report.figure_set.report_figures` of the same study if already rendered.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = summary.get("config") or spec.model_dump(mode="json")
    colors = controller_colors(cfg["controllers"])
    ctrl = summary["controllers"]
    axes = [x for x in ("rear", "front", "joint") if any(x in c.get("slip_margin", {}) for c in ctrl.values())]
    params = [c for c in column_names(spec) if c in runs.columns and runs[c].nunique(dropna=True) > 1]
    best, verdict, verdict_rows = _verdict(summary, runs)
    status_head, status_rows = _status_table(runs, colors)
    eps = cfg["margin"]["eps"]
    margin_rows = [
        [_cell(n, swatch=colors[n]), _cell(x), _cell(fmt_margin(m)), _cell(fmt_num(m["resolution"]))]
        for n, c in ctrl.items()
        for x, m in c.get("slip_margin", {}).items()
    ]
    ctx = {
        "s": summary,
        "setup": _setup(cfg, summary),
        "colors": colors,
        "axes": axes,
        "eps": eps,
        "best": best,
        "verdict": verdict,
        "verdict_rows": verdict_rows,
        "headline_rows": _headline_rows(summary, colors, axes),
        "margin_heads": [f"slip margin, {x} [lo, hi]" for x in axes],
        "per_path_rows": _per_path_rows(summary, colors),
        "statements": {n: c["statement"]["text"] for n, c in ctrl.items()},
        "status_head": status_head,
        "status_rows": status_rows,
        "margin_rows": margin_rows,
        "drivers": _drivers(summary),
        "worst": _worst_runs(runs, params),
        "worst_params": params,
        "sample_size": {k: v for k, v in summary.get("sample_size", {}).items() if k != "note"},
        "sample_note": summary.get("sample_size", {}).get("note", ""),
        "n_sweep": summary.get("n_margin_runs", 0),
        "figures": figures
        if figures is not None
        else _figures(out_dir, spec, summary, runs, colors, worst_trajectories),
        "worst_case_rows": _worst_case_rows(summary, colors),
        "rare_event_rows": _rare_event_rows(summary, colors),
        "warnings": summary.get("warnings") or [],
        "precision_rows": _precision_rows(summary, colors),
        "precision": summary.get("float64_check") or {},
        "chunks": summary.get("chunks") or {},
        "wall": fmt_num(summary.get("wall_s"), 4),
        "written": _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC"),
    }
    env = Environment(
        loader=FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    html = env.get_template("study.html.j2").render(**ctx)
    (out_dir / "report.html").write_text(html, encoding="utf-8")
