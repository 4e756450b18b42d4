"""The parking verdict table's rules (pfjax.reproduce.parking) and the report's sentences built from
it: verdicts follow the data and the config, each row names its tolerance and its basis."""

from __future__ import annotations

import pytest

from pfjax.reproduce.parking import (
    GOOD_FRACTION,
    TIME_TOL,
    TIME_TOL_REASON,
    calibration_verdicts,
    case_b_verdicts,
    ga_solution_verdicts,
    garage_verdicts,
)
from pfjax.reproduce.verdict import ASSUMED, FILTERED


def _study(tmp_path, *overrides):
    from pfjax.parking.study import run

    _, summary = run(None, tmp_path / "out", overrides=list(overrides), quick=True, progress=False)
    return summary, (tmp_path / "out" / "report.md").read_text()


def _row(summary, subject):
    return next(v for v in summary["verdicts"] if v["subject"] == subject)


def test_case_b_verdict_and_report_follow_the_run(tmp_path):
    """With a stuck test that case B meets, its row says reproduced and the report agrees with it,
    naming the configured stuck test as pfjax's reading."""
    s, md = _study(tmp_path, "sim.stuck_switches=1", "sim.stuck_travel=0.3")
    b = next(c for c in s["cases"] if c["case"] == "B")
    row = _row(s, "case B")
    assert b["status"] == "stuck" and row["verdict"] == "reproduced" and row["basis"] == ASSUMED
    assert "less than 0.3 m of travel over the last 1 leg " in row["criterion"]
    assert "**Verdict on case B**: reproduced with pfjax's reading" in md
    assert "less than 0.3 m of travel over the last 1 leg" in md.split("**Verdict on case B**")[1]
    assert f"pfjax's case B gets stuck after {b['switches']} switches" in md
    assert "not reproduced with pfjax's reading" not in md and "case B parks" not in md


def test_the_first_switch_check_uses_the_configured_front(tmp_path):
    """sim.front overrides the calibrated a_f: the first-switch row checks the configured value
    (basis assumed), with one scanner period of travel as the tolerance, and the report says so."""
    s, md = _study(tmp_path, "sim.front=0.25", "sim.scan_period=0.05")
    cal, row = s["calibration"], _row(s, "case A")
    assert cal["front"] == 0.25 and cal["front_source"] == "sim.front"
    assert cal["tolerance_m"] == pytest.approx(0.05 * 0.05)
    assert row["claim"].startswith("A: first switch") and row["basis"] == ASSUMED
    assert row["verdict"] == "not reproduced" and "a_f = 0.25 m (sim.front, assumed" in row["criterion"]
    assert "within 2.5 mm of the source's point: one scanner period of travel" in row["criterion"]
    assert "The runs use a_f = 0.25 m (sim.front), not the calibrated value" in md
    assert "scanner period of 0.05 s" in md and "beyond one scanner period of travel (2.5 mm)" in md


def _cal(dist_mm, source="calibrated"):
    return {
        "simulated_first_switch": {"x": 0.074 + dist_mm / 1000, "y": 0.047},
        "switch_x": 0.074,
        "y_source": 0.047,
        "a_f": 0.1746,
        "front": 0.1746 if source == "calibrated" else 0.2,
        "front_source": source,
        "scan_period": 0.1,
        "speed": 0.05,
        "tolerance_m": 0.005,
    }


def test_the_calibration_row_tolerance_is_one_period_of_travel():
    (row,) = calibration_verdicts(_cal(4.9))
    assert row.verdict == "reproduced" and row.basis == "used to calibrate a parameter"
    (row,) = calibration_verdicts(_cal(5.1))
    assert row.verdict == "not reproduced" and "within 5.0 mm" in row.criterion
    (row,) = calibration_verdicts(_cal(1.0, "sim.front"))
    assert row.basis == ASSUMED and "not the calibrated 0.1746 m" in row.criterion


def test_sweep_rows_give_no_verdict_and_the_combined_row_is_pfjax_s():
    sweep = {
        "n_combinations": 504,
        "all_four_reproduced": [{"front": 0.15}],
        "by_zone": {"whole": {"B": {"stuck": 167}}},
        "status_counts": {"B": {"stuck": 167}},
        "b_min_leg_m": 0.0,
    }
    main, swept = case_b_verdicts({"status": "converged", "switches": 9, "time_s": 63.9}, sweep, 0.1, 4)
    assert main.verdict == "not reproduced" and main.basis == ASSUMED
    assert "sim.stuck_travel, sim.stuck_switches" in main.criterion
    assert swept.verdict == "no verdict" and swept.basis == FILTERED and "no verdict: " in swept.criterion


def _o(status="converged", switches=2, time_s=50.0):
    return {"status": status, "switches": switches, "time_s": time_s}


def test_experiment_stop_rows_are_assumed_and_show_the_run_without_it():
    outcomes = {f"garage {xs:g}{sfx}": _o() for xs in (-0.9, -1.2, -1.8) for sfx in ("", "+pause")}
    outcomes["garage -1.2+pause"] = _o(time_s=61.0 * (1 + TIME_TOL) + 0.1)
    outcomes["garage -1.2"] = _o(time_s=61.0)
    rows = garage_verdicts(outcomes, 1.0)
    assert len(rows) == 3 and all(r.basis == ASSUMED and "case D's experiment only" in r.criterion for r in rows)
    assert rows[1].verdict == "not reproduced" and "without the stop: converged, 2 switches, 61.0 s" in rows[1].pfjax
    assert TIME_TOL_REASON in rows[1].criterion


def test_the_second_ga_solution_is_judged_by_its_fitness():
    outcomes = {
        f"GA solution {t}{sfx}": _o() for t in ("(-1, 4.57, 1.25)", "(-1, 0.82, 3.28)") for sfx in ("", "+pause")
    }
    sol = [{"fitness_ratio_to_grid_best": 0.9}, {"fitness_ratio_to_grid_best": GOOD_FRACTION - 0.01}]
    first, second = ga_solution_verdicts(outcomes, sol, 1.0)
    assert first.basis == second.basis == ASSUMED
    assert second.verdict == "not reproduced" and f"at least {100 * GOOD_FRACTION:g} %" in second.criterion
    sol[1] = {"fitness_ratio_to_grid_best": GOOD_FRACTION}
    assert ga_solution_verdicts(outcomes, sol, 1.0)[1].verdict == "reproduced"
    sol[1] = {"fitness_ratio_to_grid_best": None}
    assert ga_solution_verdicts(outcomes, sol, 1.0)[1].verdict == "not reproduced"
