"""The parking study's report: :func:`report` builds one :class:`pfjax.report.document.Document` from
the study's summary and tables (every number read from them, none recomputed), and :func:`write_report`
renders it to ``report.md`` and ``report.html``."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd

from pfjax.parking.runs import SEARCH_MAX_SWITCHES
from pfjax.report import document as D
from pfjax.reproduce.parking import SOURCE_PAUSE_S, TIME_TOL, TIME_TOL_REASON, first_switch_distance, stuck_test
from pfjax.reproduce.verdict import Verdict, verdict_cells


def _f(x, nd=1):
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def assumptions_table(sweep: pd.DataFrame) -> D.Table:
    """Per detection zone and reach a_f: how often each case parks, gets stuck or times out over the
    other assumptions (scanner period, decision delay, yaw-rate loop, stop at reversal)."""
    rows = []
    for (zone, f), g in sweep.groupby(["zone", "front"], sort=False):
        cells = []
        for case in "ABCD":
            counts = g[g["case"] == case]["status"].value_counts()
            n = int(counts.sum())
            cells.append(", ".join(f"{k.replace('_', ' ')} {v}/{n}" for k, v in counts.items()))
        rows.append([zone, f"{f:.3f}", *cells])
    return D.Table(["detection zone", "a_f [m]", "A", "B", "C", "D"], rows)


def _zone_sentence(a: dict) -> str:
    """How case B and the cases the source reports parking fare under each detection zone."""
    parts = []
    for zone, by_case in a["by_zone"].items():
        n = sum(by_case["B"].values())
        stuck = {c: by_case[c].get("stuck", 0) for c in "ABCD"}
        parts.append(
            f"with the **{zone}** zone, B is stuck in {stuck['B']} of {n} combinations, and A, C, D (which the "
            f"source reports parking) in {stuck['A']}, {stuck['C']}, {stuck['D']}"
        )
    return (
        "Over all combinations case B's shortest leg between two reversals is "
        f"{100 * a['b_min_leg_m']:.1f} cm; " + "; ".join(parts) + "."
    )


#: How each run status reads in a sentence ("pfjax's case B parks after ...").
_ENDS = {"converged": "parks", "stuck": "gets stuck", "timeout": "times out"}


def _ends(c: dict) -> str:
    """How a case's run ends, from its row of ``cases``: "parks after 9 switches (63.9 s)"."""
    how = _ENDS.get(c["status"], f"ends {c['status'].replace('_', ' ')}")
    return f"{how} after {c['switches']} switches ({c['time_s']:.1f} s)"


def _reading(s: dict) -> str:
    """pfjax's reading of the open assumptions for the single runs, from the config and the calibration."""
    sim, cal = s["config"]["sim"], s["calibration"]
    reach = (
        f"a_f = {cal['front']:.3f} m, calibrated"
        if cal["front_source"] == "calibrated"
        else f"a_f = {cal['front']:g} m (sim.front)"
    )
    return (
        f"{reach}; the half toward the travel direction, split at the middle; decisions on the current pose; no "
        f"stop; scanner period {sim['scan_period']:g} s; stuck: {stuck_test(sim['stuck_travel'], sim['stuck_switches'])}"
        "; docs/reproductions/parking.md §3"
    )


def _b_row(s: dict) -> dict:
    """Case B's verdict row on pfjax's reading."""
    return next(v for v in s["verdicts"] if v["subject"] == "case B")


def _b_verdict(s: dict) -> str:
    """The verdict on case B, from its verdict row, its run and the sweep."""
    a, row = s["assumptions"], _b_row(s)
    b = next(c for c in s["cases"] if c["case"] == "B")
    k, n = len(a["all_four_reproduced"]), a["n_combinations"]
    per_zone = {
        z: sum(c["zone"] == z for c in a["all_four_reproduced"]) / max(1, sum(v["B"].values()))
        for z, v in a["by_zone"].items()
    }
    best = max(per_zone, key=lambda z: per_zone[z]) if per_zone else None
    share = (
        f"; the most in one detection zone: {100 * per_zone[best]:.0f} % of the {best} zone's combinations" if k else ""
    )
    return (
        f"**Verdict on case B**: {row['verdict']} with pfjax's reading ({_reading(s)}), under which B "
        f"{_ends(b)}. {k} of the {n} combinations give all four outcomes together{share}; a combination "
        "found by matching the source's outcomes is a reading selected by them, not evidence for it."
    )


def _header(s: dict) -> list[D.Block]:
    """The settings every section shares."""
    c, sim = s["config"]["controller"], s["config"]["sim"]
    return [
        D.Paragraph(
            f"Wall time {s['wall_s']:.0f} s on {s['machine']}. "
            f"Controller k₁ = {c['k1']:g}, k₂ = {c['k2']:g}, |v₁| = {c['speed']:g} m/s; "
            f"scanner period {sim['scan_period']:g} s, {sim['n_sub']} RK4 steps per period; timeout {sim['t_max']:g} s; "
            f"stop when |x| + √(y² + tan²θ) < {sim['tol']:g}. Runs end converged, stuck (less than "
            f"{sim['stuck_travel']:g} m of travel over the last {sim['stuck_switches']} legs between reversals: "
            "reversing in place), timed out, at the heading limit, non-finite, or not started (the rectangle meets "
            "an obstacle at the start pose); only the search fails a candidate beyond "
            f"{s['config']['search']['max_switches']} switches (search.max_switches; the source's search "
            f"cuts off beyond {SEARCH_MAX_SWITCHES}).",
            style="note",
        )
    ]


def _verdicts(s: dict) -> list[D.Block]:
    header, rows = verdict_cells([Verdict(**v) for v in s["verdicts"]])
    return [
        D.Heading("Verdicts on the source's reported outcomes"),
        D.Paragraph(
            f"One row per outcome and criterion. Times count as reproduced within ±{100 * TIME_TOL:g} % "
            f"({TIME_TOL_REASON}). The source states a {SOURCE_PAUSE_S:g} s stop at each reversal for case D's "
            f"experiment; pfjax models that stop as an option ({s['config']['experiment']['pause']:g} s here, "
            "experiment.pause) and applies it to the garage and GA experiments too, where it is assumed: their "
            "rows judge the run with the stop and show the run without it beside it."
        ),
        D.Table(header, rows),
    ]


def _calibration(s: dict) -> list[D.Block]:
    cal = s["calibration"]
    sw, tol = cal["simulated_first_switch"], cal["tolerance_m"]
    dist = first_switch_distance(cal)
    if cal["front_source"] == "calibrated":
        used = "Simulated with this a_f"
    else:
        used = f"The runs use a_f = {cal['front']:g} m (sim.front), not the calibrated value. Simulated with it"
    text = (
        "On case A's first leg the loop is linear in the x time scale; the closed form gives "
        f"y = {cal['y_closed_form_at_switch_x']:.4f} m at x = {cal['switch_x']} (the source reports "
        f"y = {cal['y_source']}), with θ = {cal['theta_deg_at_switch']:.2f}°. The smallest reach a_f for which the "
        "rectangle's right front corner touches an obstacle at that pose is "
        f"**a_f = {cal['a_f']:.4f} m** (the {cal['obstacle']}; the car ahead would need "
        f"{cal['reach_per_obstacle']['car_ahead']:.3f} m). {used}, a scanner period of {cal['scan_period']:g} s "
        f"and |v₁| = {cal['speed']:g} m/s, the first switch happens at t = {sw['t']:.1f} s with the robot at "
        f"({sw['x']:.4f}, {sw['y']:.4f}), θ = {sw['theta_deg']:.2f}°: {1000 * dist:.1f} mm from the source's point, "
        f"{'within' if dist <= tol else 'beyond'} one scanner period of travel ({1000 * tol:.1f} mm)."
    )
    return [D.Heading("Calibration of a_f"), D.Paragraph(text)]


def _cases_table(cases: list[dict]) -> D.Table:
    header = ["case", "start (x, y, θ°)", "first direction", "α schedule", "X_s", "outcome", "switches", "time [s]"]
    rows = [
        [
            c["case"],
            c["start"],
            c["direction"],
            c["schedule"],
            _f(c["xs"], 2),
            c["status"],
            c["switches"],
            _f(c["time_s"]),
            c["switch_times_s"],
        ]
        for c in cases
    ]
    return D.Table([*header, "switch times [s]"], rows)


def _cases(s: dict, sweep: pd.DataFrame) -> list[D.Block]:
    a = s["assumptions"]
    b = next((c for c in s["cases"] if c["case"] == "B"), None)
    four = a["all_four_reproduced"]
    listed = "; ".join(", ".join(f"{k}={v}" for k, v in c.items()) for c in four[:8])
    return [
        D.Heading("Every source case"),
        _cases_table(s["cases"]),
        D.Figure("cases_parallel", "parallel parking cases"),
        D.Figure("garage_xs", "garage with the source's X_s"),
        D.Figure("histories_D", "case D histories"),
        D.Heading("Case B: what would make it stuck", level=3),
        D.Paragraph(
            'The source reports case B stuck, switching repeatedly in place, "because it turns sharply at each '
            'switch and, not being round, touches again". '
            f"pfjax's case B {_ends(b) if b else 'is not run'}. Which of the assumptions the source leaves open "
            "(docs/reproductions/parking.md §3) could change that? The study simulates cases A-D under all "
            f"{a['n_combinations']} combinations of: the rectangle's reach a_f, the detection zone checked toward the "
            "travel direction (the half beyond the middle, the part beyond the wheel axle, or the whole rectangle), "
            "the scanner period, a decision taken on the pose one period old, the yaw-rate PI loop of the "
            "experiments, and a stop at each reversal. Counts per detection zone and a_f (over the other assumptions):"
        ),
        assumptions_table(sweep),
        D.Paragraph(
            f"{_zone_sentence(a)} {len(four)} of the {a['n_combinations']} combinations give all four of the "
            f"source's outcomes at once (A, C and D park, B stuck){': ' + listed if four else ''}."
        ),
        D.Paragraph(_b_verdict(s), style="verdict"),
    ]


def _search(s: dict) -> list[D.Block]:
    se, ga, grid = s["config"]["search"], s["search"]["ga"], s["search"]["grid"]
    runs = s["search"].get("ga_runs", [ga])

    def row(label, r):
        return [label, f"{r['xs']:.3f}", f"{r['alpha1']:.3f}", f"{r['alpha2']:.3f}", r["status"]] + [
            _f(r["time_s"]),
            r["switches"],
            f"{r['fitness']:.5f}",
            r["n_simulations"],
        ]

    header = ["method", "X_s [m]", "α₁", "α₂", "outcome", "parking time [s]", "switches", "J [1/s]", "simulations"]
    rows = [row(f"GA run {r.get('seed_index', 0) + 1}", r) for r in runs] + [row("grid", grid)]
    return [
        D.Heading("Search of (X_s, α₁, α₂) in the garage"),
        D.Paragraph(
            f"Fitness J = 1/(t_e + {se['weight']:g}·e_e) (assumed; 0 for too many switches). GA: population "
            f"{se['population']}, {se['generations']} generations, 24 bits, {ga['n_simulations']} simulations per run "
            f"in {ga['wall_s']:.0f} s. Grid: {grid['n']}³ = {grid['n_simulations']} simulations on the chromosome "
            f"lattice in {grid['wall_s']:.0f} s."
        ),
        D.Table(header, rows),
        D.Paragraph(
            f"Over {len(runs)} independent GA run(s) the best reaches {_share(ga['fitness_ratio_to_grid_best'])} "
            f"of the grid's best J ({100 * ga['grid_fraction_better']:.2f} % of the grid points are better); per run: "
            + ", ".join(_share(r["fitness_ratio_to_grid_best"]) for r in runs)
            + " of the grid's best."
        ),
        D.Figure("search", "search"),
    ]


def _share(ratio: float | None) -> str:
    """A fitness ratio to the grid's best as a percentage; none where no grid point scored."""
    return "n/a (no grid point scores)" if ratio is None else f"{100 * ratio:.1f} %"


def _start_map(s: dict) -> list[D.Block]:
    def unused(r, v, k):
        return _f(v, 3) if r["switches"] >= k else "(unused)"

    header = ["x₀ [m]", "θ₀ [°]", "best X_s", "α₁", "α₂", "outcome", "time [s]", "switches", "grid runs converged"]
    rows = [
        [r["x0"], r["theta0_deg"], unused(r, r["xs"], 1), unused(r, r["alpha1"], 1), unused(r, r["alpha2"], 2)]
        + [r["status"], _f(r["time_s"]), r["switches"], f"{100 * r['converged_fraction']:.0f} %"]
        for r in s["start_map"]
    ]
    y0 = s["start_map"][0]["y0"] if s["start_map"] else "—"
    return [
        D.Heading(
            f"Other starts (y₀ = {y0} m): best parameters on a {s['config']['start_map']['grid_n']}³ grid per start"
        ),
        D.Table(header, rows),
        D.Paragraph(
            'A parameter is "(unused)" when the best run switched too few times to reach it (α₁ applies from the '
            "1st switch, α₂ from the 2nd, X_s only while backing); every value then ties and the grid's first level "
            "is listed."
        ),
        D.Figure("start_map", "start map"),
    ]


def _montecarlo(s: dict) -> list[D.Block]:
    m = s["config"]["montecarlo"]
    rows = []
    for lab, r in s["montecarlo"].items():
        ci, t, lag = r["success_ci95"], r["time_s"], r["by_lag"]
        rows.append(
            [
                lab,
                f"{100 * r['success_rate']:.1f} % [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]",
                ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in r["status_counts"].items() if v),
                f"{_f(t['q50'])} / {_f(t['q95'])}",
                f"{100 * lag.get('lag_off', {}).get('success_rate', float('nan')):.1f} % / "
                f"{100 * lag.get('lag_on', {}).get('success_rate', float('nan')):.1f} %",
            ]
        )
    header = ["schedule", "success [95 % CI]", "statuses", "parking time p50 / p95 [s]", "success lag off / on"]
    return [
        D.Heading(
            f"Robustness Monte Carlo (garage, {m['n_runs']} runs per schedule, the same runs for every schedule)"
        ),
        D.Paragraph(
            f"Start scatter ±{m['pos_scatter']:g} m and ±{m['theta_scatter_deg']:g}°, scanner period "
            f"U[{m['scan_lo']:g}, {m['scan_hi']:g}] s, speed U[{m['speed_lo']:g}, {m['speed_hi']:g}] m/s, yaw-rate "
            f"PI loop (k_P 0.8, k_I 16) on with probability {m['lag_probability']:g}."
        ),
        D.Table(header, rows),
        D.Figure("montecarlo", "monte carlo"),
    ]


def report(summary: dict, tables: dict[str, pd.DataFrame]) -> D.Document:
    """The study's report from its ``summary`` (``summary.json``) and ``tables`` (at least
    ``assumptions``): header, verdicts, calibration, cases, search, start map, Monte Carlo."""
    s = summary
    subtitle = f"Config SHA-256 `{s['config_sha256']}`, seed {s['seed']}, pfjax {s['pfjax_version']}" + (
        " (**quick mode: small sizes**)" if s["quick"] else ""
    )
    blocks = [
        *_header(s),
        *_verdicts(s),
        *_calibration(s),
        *_cases(s, tables["assumptions"]),
        *_search(s),
        *_start_map(s),
        *_montecarlo(s),
    ]
    return D.Document("Parking by switching travel direction and gain — pfjax study", subtitle, blocks)


def write_report(out: Path, summary: dict, tables: dict[str, pd.DataFrame]) -> list[Path]:
    """``out/report.md`` and ``out/report.html`` from one :func:`report` Document."""
    return D.write(report(summary, tables), out)
