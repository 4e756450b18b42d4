"""The parking study's Markdown report (every number read from the study's summary)."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd


def _f(x, nd=1):
    return "—" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def _table(header: list[str], rows: list[list]) -> str:
    from pfjax.report.markdown import table

    return table(header, rows)


def assumptions_table(sweep: pd.DataFrame) -> str:
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
    return _table(["detection zone", "a_f [m]", "A", "B", "C", "D"], rows)


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


def _b_verdict(a: dict, b_outcome: str) -> str:
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
        f"**Verdict on case B**: not reproduced with pfjax's reading (the half toward the travel direction, "
        f"split at the middle, decisions on the current pose, no stop; chosen from the model's reading before and "
        f"independently of these outcomes), under which B {b_outcome}. {k} of the {n} combinations reproduce "
        f"all four outcomes together{share}."
    )


def _header(s: dict) -> str:
    """The title and the settings every section shares."""
    cfg = s["config"]
    return f"""# Parking by switching travel direction and gain — pfjax study

Config SHA-256 `{s["config_sha256"]}`, seed {s["seed"]}, pfjax {s["pfjax_version"]}{" (**quick mode: small sizes**)" if s["quick"] else ""};
wall time {s["wall_s"]:.0f} s on {s["machine"]}.
Controller k₁ = {cfg["controller"]["k1"]:g}, k₂ = {cfg["controller"]["k2"]:g}, |v₁| = {cfg["controller"]["speed"]:g} m/s;
scanner period {cfg["sim"]["scan_period"]:g} s, {cfg["sim"]["n_sub"]} RK4 steps per period; timeout {cfg["sim"]["t_max"]:g} s;
stop when |x| + √(y² + tan²θ) < {cfg["sim"]["tol"]:g}. Runs end converged, stuck (less than {cfg["sim"]["stuck_travel"]:g} m of
travel over the last {cfg["sim"]["stuck_switches"]} legs between reversals: reversing in place), timed out, at the heading limit,
non-finite, or not started (the rectangle meets an obstacle at the start pose); only the search fails a candidate
beyond {cfg["search"]["max_switches"]} switches (the source's search cut-off)."""


def _verdicts(s: dict) -> str:
    from pfjax.reproduce import Verdict, verdict_table

    verdicts = verdict_table([Verdict(**v) for v in s["verdicts"]])
    return f"""## Verdicts on the source's reported outcomes

One row per outcome and criterion. Times count as reproduced within ±10 %. The source's experiments stood
{s["config"]["experiment"]["pause"]:g} s at each reversal; pfjax models that stop as an option and shows both.

{verdicts}"""


def _calibration(s: dict) -> str:
    cal = s["calibration"]
    sw = cal["simulated_first_switch"]
    return f"""## Calibration of a_f

On case A's first leg the loop is linear in the x time scale; the closed form gives y = {cal["y_closed_form_at_switch_x"]:.4f} m
at x = {cal["switch_x"]} (the source reports y = {cal["y_source"]}), with θ = {cal["theta_deg_at_switch"]:.2f}°. The smallest
reach a_f for which the rectangle's right front corner touches an obstacle at that pose is **a_f = {cal["a_f"]:.4f} m**
(the {cal["obstacle"]}; the car ahead would need {cal["reach_per_obstacle"]["car_ahead"]:.3f} m). Simulated with this a_f
and 0.1 s scanner sampling, the first switch happens at t = {sw["t"]:.1f} s with the robot at
({sw["x"]:.4f}, {sw["y"]:.4f}), θ = {sw["theta_deg"]:.2f}° — within one scanner period of travel (5 mm) of the source's point."""


def _cases_table(cases: list[dict]) -> str:
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
    return _table([*header, "switch times [s]"], rows)


def _cases(s: dict, sweep: pd.DataFrame) -> str:
    a = s["assumptions"]
    by_case = {
        c["case"]: f"{c['status'].replace('_', ' ')} after {c['switches']} switches ({c['time_s']:.1f} s)"
        for c in s["cases"]
    }
    return f"""## Every source case

{_cases_table(s["cases"])}

![parallel parking cases](figures/cases_parallel.png)

![garage with the source's X_s](figures/garage_xs.png)

![case D histories](figures/histories_D.png)

### Case B: what would make it stuck

The source reports case B stuck, switching repeatedly in place, "because it turns sharply at each switch and, not
being round, touches again". pfjax's case B parks ({by_case.get("B", "—")}). Which of the assumptions the source
leaves open (docs/reproductions/parking.md §3) could change that? The study simulates cases A-D under all {a["n_combinations"]} combinations of:
the rectangle's reach a_f, the detection zone checked toward the travel direction (the half beyond the middle,
the part beyond the wheel axle, or the whole rectangle), the scanner period, a decision taken on the pose one
period old, the yaw-rate PI loop of the experiments, and a stop at each reversal. Counts per detection zone and a_f
(over the other assumptions):

{assumptions_table(sweep)}

{_zone_sentence(a)}
{len(a["all_four_reproduced"])} of the {a["n_combinations"]} combinations give all four of the source's outcomes at once
(A, C and D park, B stuck){": " + "; ".join(", ".join(f"{k}={v}" for k, v in c.items()) for c in a["all_four_reproduced"][:8]) if a["all_four_reproduced"] else ""}.
{_b_verdict(a, by_case.get("B", "—"))}"""


def _search(s: dict) -> str:
    cfg, ga, grid = s["config"], s["search"]["ga"], s["search"]["grid"]
    runs = s["search"].get("ga_runs", [ga])
    ga_rows = "\n".join(
        f"| GA run {r.get('seed_index', 0) + 1} | {r['xs']:.3f} | {r['alpha1']:.3f} | {r['alpha2']:.3f} | {r['status']} | {_f(r['time_s'])} | "
        f"{r['switches']} | {r['fitness']:.5f} | {r['n_simulations']} |"
        for r in runs
    )
    return f"""## Search of (X_s, α₁, α₂) in the garage

Fitness J = 1/(t_e + {cfg["search"]["weight"]:g}·e_e) (assumed; 0 for too many switches). GA: population
{cfg["search"]["population"]}, {cfg["search"]["generations"]} generations, 24 bits, {ga["n_simulations"]} simulations per run in {ga["wall_s"]:.0f} s.
Grid: {grid["n"]}³ = {grid["n_simulations"]} simulations on the chromosome lattice in {grid["wall_s"]:.0f} s.

| method | X_s [m] | α₁ | α₂ | outcome | parking time [s] | switches | J [1/s] | simulations |
|---|---|---|---|---|---|---|---|---|
{ga_rows}
| grid | {grid["xs"]:.3f} | {grid["alpha1"]:.3f} | {grid["alpha2"]:.3f} | {grid["status"]} | {_f(grid["time_s"])} | {grid["switches"]} | {grid["fitness"]:.5f} | {grid["n_simulations"]} |

Over {len(runs)} independent GA run(s) the best reaches {100 * ga["fitness_ratio_to_grid_best"]:.1f} % of the grid's best J
({100 * ga["grid_fraction_better"]:.2f} % of the grid points are better); per run:
{", ".join(f"{100 * r['fitness_ratio_to_grid_best']:.1f} %" for r in runs)} of the grid's best.

![search](figures/search.png)"""


def _start_map(s: dict) -> str:
    unused = lambda r, v, k: _f(v, 3) if r["switches"] >= k else "(unused)"
    smap = _table(
        ["x₀ [m]", "θ₀ [°]", "best X_s", "α₁", "α₂", "outcome", "time [s]", "switches", "grid runs converged"],
        [
            [
                r["x0"],
                r["theta0_deg"],
                unused(r, r["xs"], 1),
                unused(r, r["alpha1"], 1),
                unused(r, r["alpha2"], 2),
                r["status"],
                _f(r["time_s"]),
                r["switches"],
                f"{100 * r['converged_fraction']:.0f} %",
            ]
            for r in s["start_map"]
        ],
    )
    return f"""## Other starts (y₀ = {s["start_map"][0]["y0"] if s["start_map"] else "—"} m): best parameters on a {s["config"]["start_map"]["grid_n"]}³ grid per start

{smap}

A parameter is "(unused)" when the best run switched too few times to reach it (α₁ applies from the 1st switch,
α₂ from the 2nd, X_s only while backing); every value then ties and the grid's first level is listed.

![start map](figures/start_map.png)"""


def _montecarlo(s: dict) -> str:
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
    return f"""## Robustness Monte Carlo (garage, {m["n_runs"]} runs per schedule, same runs for both)

Start scatter ±{m["pos_scatter"]:g} m and ±{m["theta_scatter_deg"]:g}°, scanner period
U[{m["scan_lo"]:g}, {m["scan_hi"]:g}] s, speed U[{m["speed_lo"]:g},
{m["speed_hi"]:g}] m/s, yaw-rate PI loop (k_P 0.8, k_I 16) on with probability {m["lag_probability"]:g}.

{_table(header, rows)}

![monte carlo](figures/montecarlo.png)"""


def write_report(out: Path, s: dict, sweep: pd.DataFrame) -> Path:
    """``out/report.md``: header, verdicts, calibration, cases, search, start map, Monte Carlo."""
    sections = [_header(s), _verdicts(s), _calibration(s), _cases(s, sweep), _search(s), _start_map(s), _montecarlo(s)]
    p = out / "report.md"
    p.write_text("\n\n".join(sections) + "\n")
    return p
