"""Verdicts on the parking source's reported outcomes (Yamakawa & Ebara 2017; docs/reproductions/parking.md §4's table):
one row per outcome and criterion, from the parking study's runs.

Inputs (``studies/parking.py``): ``outcomes``, the source's scenarios simulated by pfjax (each a
dict with ``status``, ``switches``, ``time_s``; ``+pause`` variants stand ``pause`` s at each
reversal, pfjax's model of the experiments' stop, the source's :data:`SOURCE_PAUSE_S`); ``calibration`` (the a_f calibration, with
the simulated first switch of case A); ``sweep`` (:func:`pfjax.parking.assumptions.sweep_summary`);
``ga`` (pfjax's own GA runs and grid, for the "several good solutions" statement).
"""

from __future__ import annotations

import math

from pfjax.reproduce.verdict import FILTERED, Verdict

#: Relative tolerance within which a parking time counts as reproduced.
TIME_TOL = 0.10
#: The source's GA solutions (X_s m, α₁, α₂).
GA_SOLUTIONS = ((-1.0, 4.57, 1.25), (-1.0, 0.82, 3.28))
#: s the source's experiments stood still at each reversal.
SOURCE_PAUSE_S = 1.0
#: Rounding under which two GA results count as the same parameters: X_s to 1 mm, α₁ and α₂ to 0.01.
DISTINCT_DIGITS = (3, 2, 2)


#: The wording of a parking-time criterion.
WITHIN = f"parking time within ±{100 * TIME_TOL:g} %"


def _outcome(o: dict) -> str:
    return f"{o['status'].replace('_', ' ')}, {o['switches']} switches, {o['time_s']:.1f} s"


def _says(holds: bool) -> str:
    return "reproduced" if holds else "not reproduced"


def _parks(o: dict) -> bool:
    return o["status"] == "converged"


def _time_verdict(t: float, source: float) -> str:
    return _says(math.isfinite(t) and abs(t - source) <= TIME_TOL * source)


def _parks_in(o: dict, source_s: float) -> str:
    """Reproduced when the run parks within ``TIME_TOL`` of the source's time (s)."""
    return _time_verdict(o["time_s"], source_s) if _parks(o) else "not reproduced"


def _row(*fields, **kw) -> Verdict:
    return Verdict(*fields, **kw).check()


def calibration_verdicts(calibration: dict) -> list[Verdict]:
    """Case A's first switch against the source's point (the point a_f is calibrated from)."""
    sw = calibration["simulated_first_switch"]
    dist = math.hypot(sw["x"] - calibration["switch_x"], sw["y"] - calibration["y_source"])
    return [
        _row(
            "A: first switch at (0.074, 0.047)",
            "parallel",
            "case A",
            "the simulated first switch lies within one scanner "
            "period of travel (5 mm) of the source's point; a_f was calibrated from this point",
            f"({sw['x']:.4f}, {sw['y']:.4f}), {1000 * dist:.1f} mm away",
            "(0.074, 0.047)",
            _says(dist <= 0.005),
            basis="used to calibrate a parameter",
        )
    ]


def case_a_verdicts(a: dict) -> list[Verdict]:
    """Case A parks with the source's 4 switches."""
    return [
        _row(
            "A: 4 switches, parks",
            "parallel",
            "case A",
            "parks, with the source's number of switches",
            _outcome(a),
            "parks, 4 switches",
            _says(_parks(a) and a["switches"] == 4),
        )
    ]


def case_b_verdicts(b: dict, sweep: dict, stuck_travel: float = 0.1, stuck_switches: int = 4) -> list[Verdict]:
    """Case B stuck: with pfjax's reading (stuck: less than ``stuck_travel`` m of travel over
    ``stuck_switches`` legs), and in some combination of the open assumptions."""
    n = sweep["n_combinations"]
    stuck = sweep["status_counts"]["B"].get("stuck", 0)
    zones = ", ".join(f"{z}: {v['B'].get('stuck', 0)}" for z, v in sweep["by_zone"].items())
    claim = "B: stuck, switching repeatedly in place"
    return [
        _row(
            claim,
            "parallel",
            "case B",
            f"status stuck (reverses again within {stuck_travel:g} m of travel over {stuck_switches} legs)",
            _outcome(b),
            "stuck",
            _says(b["status"] == "stuck"),
        ),
        _row(
            claim,
            "parallel",
            "case B under every assumption combination",
            f"B is stuck in some of the {n} combinations of the open assumptions (a_f, detection zone, scanner "
            "period, decision delay, yaw-rate loop, stop at reversal)",
            f"stuck in {stuck} of {n} (by detection zone: {zones}); shortest leg {100 * sweep['b_min_leg_m']:.1f} cm",
            "stuck",
            _says(bool(stuck)),
            basis=FILTERED,  # a search of the assumptions for the source's outcome: its hits are selected by it
        ),
    ]


def all_four_verdicts(sweep: dict) -> list[Verdict]:
    """The combinations of the open assumptions under which A, C, D park and B is stuck at once."""
    found = sweep["all_four_reproduced"]
    listed = "; ".join(", ".join(f"{kk}={vv}" for kk, vv in c.items()) for c in found[:5])
    return [
        _row(
            "A, C, D park and B is stuck",
            "parallel",
            "cases A-D together",
            f"combinations of the open assumptions (of {sweep['n_combinations']}) under which all four outcomes "
            "hold at once",
            f"{len(found)}" + (": " + listed if found else ""),
            "all four",
            _says(bool(found)),
            basis=FILTERED,  # the combinations are selected by the four outcomes they are checked on
        )
    ]


def case_c_verdicts(c: dict) -> list[Verdict]:
    """Case C parks, with 19 switches, in 115 s."""
    claim = "C: parks; 19 switches; 115 s"
    return [
        _row(claim, "parallel", "case C", "parks", _outcome(c), "parks", _says(_parks(c))),
        _row(
            claim,
            "parallel",
            "case C",
            "the same number of switches",
            f"{c['switches']}",
            "19",
            _says(c["switches"] == 19),
        ),
        _row(
            claim,
            "parallel",
            "case C",
            f"{WITHIN} of the source's",
            f"{c['time_s']:.1f} s",
            "115 s",
            _parks_in(c, 115.0),
        ),
    ]


def case_d_verdicts(d: dict, d_pause: dict, pause: float = SOURCE_PAUSE_S) -> list[Verdict]:
    """Case D parks in 44 s (simulation) and 47 s (experiment, the source's 1 s stop at each
    reversal; pfjax's run stands ``pause`` s)."""
    return [
        _row(
            "D: parks; 44 s", "parallel", "case D", f"parks, {WITHIN}", _outcome(d), "parks, 44 s", _parks_in(d, 44.0)
        ),
        _row(
            f"D: 47 s in the experiment, with a {SOURCE_PAUSE_S:g} s stop at each reversal",
            "parallel",
            f"case D, {pause:g} s stop at each reversal",
            f"{WITHIN} (the stop modelled as a pfjax option)",
            _outcome(d_pause),
            "47 s (experiment)",
            _parks_in(d_pause, 47.0),
        ),
    ]


def garage_verdicts(outcomes: dict, pause: float = SOURCE_PAUSE_S) -> list[Verdict]:
    """The garage experiments at X_s = -0.9 (4 switches), -1.2 (61 s) and -1.8 m (86 s), without and
    with a stop of ``pause`` s at each reversal."""
    out = []
    for xs, src, what in ((-0.9, 4, "switches"), (-1.2, 61.0, "time"), (-1.8, 86.0, "time")):
        for suffix, label in (("", ""), ("+pause", f", {pause:g} s stop at each reversal")):
            o = outcomes[f"garage {xs:g}{suffix}"]
            if what == "switches":
                criterion, source = "parks, with the source's number of switches", f"{src} switches"
                verdict = _says(_parks(o) and o["switches"] == src)
            else:
                criterion, source, verdict = f"parks, {WITHIN}", f"{src:g} s", _parks_in(o, src)
            claim = f"garage X_s = {xs:g}: {src:g} {'switches' if what == 'switches' else 's'} (experiment)"
            out.append(_row(claim, "garage", f"X_s = {xs:g}{label}", criterion, _outcome(o), source, verdict))
    return out


def ga_solution_verdicts(outcomes: dict, pause: float = SOURCE_PAUSE_S) -> list[Verdict]:
    """The source's two GA solutions: the first parks with 2 switches in 48 s (experiment; pfjax's
    run stands ``pause`` s at each reversal), the second is one of several good solutions."""
    (xs, a1, a2), (xs2, b1, b2) = GA_SOLUTIONS
    first, second = f"GA solution ({xs:g}, {a1:g}, {a2:g})", f"GA solution ({xs2:g}, {b1:g}, {b2:g})"
    o, op, o2 = outcomes[first], outcomes[first + "+pause"], outcomes[second]
    claim = f"{first}: parks with 2 switches in 48 s (experiment)"
    return [
        _row(
            claim,
            "garage",
            "as given",
            "parks with 2 switches",
            _outcome(o),
            "2 switches",
            _says(_parks(o) and o["switches"] == 2),
        ),
        _row(
            claim,
            "garage",
            f"{pause:g} s stop at each reversal",
            f"parks, {WITHIN}",
            _outcome(op),
            "48 s",
            _parks_in(op, 48.0),
        ),
        _row(
            f"{second}: one of several good solutions",
            "garage",
            "as given",
            "parks",
            _outcome(o2),
            "good solution",
            _says(_parks(o2)),
        ),
    ]


def ga_runs_verdicts(runs: list[dict]) -> list[Verdict]:
    """pfjax's GA runs end at distinct parameters (rounded as :data:`DISTINCT_DIGITS`), each within
    15 % of the grid's best fitness."""
    keys = {tuple(round(r[k], d) for k, d in zip(("xs", "alpha1", "alpha2"), DISTINCT_DIGITS)) for r in runs}
    distinct = len(keys) > 1
    return [
        _row(
            "The GA finds several good solutions",
            "garage",
            f"{len(runs)} GA runs",
            "the GA runs end at distinct (X_s, α₁, α₂) (X_s to 1 mm, α to 0.01), each within 15 % of the "
            "grid's best fitness",
            "; ".join(
                f"({r['xs']:.3f}, {r['alpha1']:.2f}, {r['alpha2']:.2f}): "
                + ("no grid point scores" if ratio is None else f"{100 * ratio:.0f} %")
                for r in runs
                for ratio in (r["fitness_ratio_to_grid_best"],)
            ),
            "several",
            _says(distinct and all((r["fitness_ratio_to_grid_best"] or 0.0) >= 0.85 for r in runs)),
            basis="assumed",
        )
    ]


def verdicts(
    outcomes: dict,
    calibration: dict,
    sweep: dict,
    ga: dict,
    *,
    pause: float = SOURCE_PAUSE_S,
    stuck_travel: float = 0.1,
    stuck_switches: int = 4,
) -> list[Verdict]:
    """Every verdict, in the table's order (one function per case). ``pause``: s the ``+pause``
    runs stood at each reversal (the study's ``experiment.pause``); ``stuck_travel`` (m) and
    ``stuck_switches``: the stuck test of the runs (``sim.stuck_travel``, ``sim.stuck_switches``)."""
    return [
        *calibration_verdicts(calibration),
        *case_a_verdicts(outcomes["A"]),
        *case_b_verdicts(outcomes["B"], sweep, stuck_travel, stuck_switches),
        *all_four_verdicts(sweep),
        *case_c_verdicts(outcomes["C"]),
        *case_d_verdicts(outcomes["D"], outcomes["D+pause"], pause),
        *garage_verdicts(outcomes, pause),
        *ga_solution_verdicts(outcomes, pause),
        *ga_runs_verdicts(ga["runs"]),
    ]
