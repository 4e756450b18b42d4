"""Verdicts on the parking source's reported outcomes (Yamakawa & Ebara 2017; docs/reproductions/parking.md §4's table):
one row per outcome and criterion, from the parking study's runs.

Inputs (``studies/parking.py``): ``outcomes``, the source's scenarios simulated by pfjax, keyed as
:data:`SCENARIOS` (each a dict with ``status``, ``switches``, ``time_s``; ``+pause`` variants stand
1 s at each reversal, as the source's experiments did); ``calibration`` (the a_f calibration, with
the simulated first switch of case A); ``sweep`` (:func:`pfjax.parking.assumptions.sweep_summary`);
``ga`` (pfjax's own GA runs and grid, for the "several good solutions" statement).
"""

from __future__ import annotations

import math

from pfjax.reproduce.verdict import Verdict

#: Relative tolerance within which a parking time counts as reproduced.
TIME_TOL = 0.10
#: The scenarios the verdicts need: name -> (map, start, first direction, alpha schedule, X_s).
GA_SOLUTIONS = ((-1.0, 4.57, 1.25), (-1.0, 0.82, 3.28))


def _outcome(o: dict) -> str:
    return f"{o['status'].replace('_', ' ')}, {o['switches']} switches, {o['time_s']:.1f} s"


def _time_verdict(t: float, source: float) -> str:
    return "reproduced" if math.isfinite(t) and abs(t - source) <= TIME_TOL * source else "not reproduced"


def verdicts(outcomes: dict, calibration: dict, sweep: dict, ga: dict) -> list[Verdict]:
    out: list[Verdict] = []
    add = lambda *a, **k: out.append(Verdict(*a, **k).check())
    parks = lambda o: o["status"] == "converged"
    pct = f"±{100 * TIME_TOL:g} %"

    sw = calibration["simulated_first_switch"]
    dist = math.hypot(sw["x"] - calibration["switch_x"], sw["y"] - calibration["y_source"])
    add(
        "A: first switch at (0.074, 0.047)",
        "parallel",
        "case A",
        "the simulated first switch lies within one scanner "
        "period of travel (5 mm) of the source's point; a_f was calibrated from this point",
        f"({sw['x']:.4f}, {sw['y']:.4f}), {1000 * dist:.1f} mm away",
        "(0.074, 0.047)",
        "reproduced" if dist <= 0.005 else "not reproduced",
        basis="used to calibrate a parameter",
    )
    a = outcomes["A"]
    add(
        "A: 4 switches, parks",
        "parallel",
        "case A",
        "parks, with the source's number of switches",
        _outcome(a),
        "parks, 4 switches",
        "reproduced" if parks(a) and a["switches"] == 4 else "not reproduced",
    )
    b = outcomes["B"]
    add(
        "B: stuck, switching repeatedly in place",
        "parallel",
        "case B",
        "status stuck (reverses again within 0.1 m of travel over 4 legs)",
        _outcome(b),
        "stuck",
        "reproduced" if b["status"] == "stuck" else "not reproduced",
    )
    n = sweep["n_combinations"]
    stuck = sweep["status_counts"]["B"].get("stuck", 0)
    zones = ", ".join(f"{z}: {v['B'].get('stuck', 0)}" for z, v in sweep["by_zone"].items())
    add(
        "B: stuck, switching repeatedly in place",
        "parallel",
        "case B under every assumption combination",
        f"B is stuck in some of the {n} combinations of the open assumptions (a_f, detection zone, scanner period, "
        "decision delay, yaw-rate loop, stop at reversal)",
        f"stuck in {stuck} of {n} (by detection zone: {zones}); shortest leg {100 * sweep['b_min_leg_m']:.1f} cm",
        "stuck",
        "reproduced" if stuck else "not reproduced",
    )
    k = len(sweep["all_four_reproduced"])
    add(
        "A, C, D park and B is stuck",
        "parallel",
        "cases A-D together",
        f"combinations of the open assumptions (of {n}) under which all four outcomes hold at once",
        f"{k}"
        + (
            ": " + "; ".join(", ".join(f"{kk}={vv}" for kk, vv in c.items()) for c in sweep["all_four_reproduced"][:5])
            if k
            else ""
        ),
        "all four",
        "reproduced" if k else "not reproduced",
    )
    c = outcomes["C"]
    add(
        "C: parks; 19 switches; 115 s",
        "parallel",
        "case C",
        "parks",
        _outcome(c),
        "parks",
        "reproduced" if parks(c) else "not reproduced",
    )
    add(
        "C: parks; 19 switches; 115 s",
        "parallel",
        "case C",
        "the same number of switches",
        f"{c['switches']}",
        "19",
        "reproduced" if c["switches"] == 19 else "not reproduced",
    )
    add(
        "C: parks; 19 switches; 115 s",
        "parallel",
        "case C",
        f"parking time within {pct} of the source's",
        f"{c['time_s']:.1f} s",
        "115 s",
        _time_verdict(c["time_s"], 115.0) if parks(c) else "not reproduced",
    )
    d = outcomes["D"]
    add(
        "D: parks; 44 s",
        "parallel",
        "case D",
        f"parks, parking time within {pct}",
        _outcome(d),
        "parks, 44 s",
        _time_verdict(d["time_s"], 44.0) if parks(d) else "not reproduced",
    )
    dp = outcomes["D+pause"]
    add(
        "D: 47 s in the experiment, with a 1 s stop at each reversal",
        "parallel",
        "case D, 1 s stop at each reversal",
        f"parking time within {pct} (the stop modelled as a pfjax option)",
        _outcome(dp),
        "47 s (experiment)",
        _time_verdict(dp["time_s"], 47.0) if parks(dp) else "not reproduced",
    )
    for xs, src, what in ((-0.9, 4, "switches"), (-1.2, 61.0, "time"), (-1.8, 86.0, "time")):
        for suffix, label in (("", ""), ("+pause", ", 1 s stop at each reversal")):
            o = outcomes[f"garage {xs:g}{suffix}"]
            if what == "switches":
                add(
                    f"garage X_s = {xs:g}: {src} switches (experiment)",
                    "garage",
                    f"X_s = {xs:g}{label}",
                    "parks, with the source's number of switches",
                    _outcome(o),
                    f"{src} switches",
                    "reproduced" if parks(o) and o["switches"] == src else "not reproduced",
                )
            else:
                add(
                    f"garage X_s = {xs:g}: {src:g} s (experiment)",
                    "garage",
                    f"X_s = {xs:g}{label}",
                    f"parks, parking time within {pct}",
                    _outcome(o),
                    f"{src:g} s",
                    _time_verdict(o["time_s"], src) if parks(o) else "not reproduced",
                )
    for i, (xs, a1, a2) in enumerate(GA_SOLUTIONS):
        name = f"GA solution ({xs:g}, {a1:g}, {a2:g})"
        o, op = outcomes[name], outcomes[name + "+pause"]
        if i == 0:
            add(
                f"{name}: parks with 2 switches in 48 s (experiment)",
                "garage",
                "as given",
                "parks with 2 switches",
                _outcome(o),
                "2 switches",
                "reproduced" if parks(o) and o["switches"] == 2 else "not reproduced",
            )
            add(
                f"{name}: parks with 2 switches in 48 s (experiment)",
                "garage",
                "1 s stop at each reversal",
                f"parks, parking time within {pct}",
                _outcome(op),
                "48 s",
                _time_verdict(op["time_s"], 48.0) if parks(op) else "not reproduced",
            )
        else:
            add(
                f"{name}: one of several good solutions",
                "garage",
                "as given",
                "parks",
                _outcome(o),
                "good solution",
                "reproduced" if parks(o) else "not reproduced",
            )
    runs = ga["runs"]
    add(
        "The GA finds several good solutions",
        "garage",
        f"{len(runs)} GA runs",
        "the GA runs end at distinct (X_s, α₁, α₂), each within 15 % of the grid's best fitness",
        "; ".join(
            f"({r['xs']:.3f}, {r['alpha1']:.2f}, {r['alpha2']:.2f}): {100 * r['fitness_ratio_to_grid_best']:.0f} %"
            for r in runs
        ),
        "several",
        "reproduced"
        if len({(round(r["xs"], 3), round(r["alpha1"], 2)) for r in runs}) > 1
        and all(r["fitness_ratio_to_grid_best"] >= 0.85 for r in runs)
        else "not reproduced",
        basis="assumed",
    )
    return out
