"""Parking: a single run's start that touches an obstacle, the trajectory figures' legend and
limits, the histories' axis labels and the report's wording.

References: the simulation's own start test (:func:`pfjax.parking.geometry.obstacle_ahead`, closed
sets) for the touching start; the recorded path for the figure limits; the rendered text for the
report.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from pfjax.cli import main
from pfjax.parking import api
from pfjax.parking.maps import MapError

#: A start on the parallel map whose rectangle's lower edge lies on the kerb (y = -0.2):
#: y - L1/2 = -0.015 - 0.185 = -0.2 exactly in float64.
TOUCHING = (0.0, -0.015, 0.0)


def test_touching_start_is_refused_by_the_api_and_the_cli(capsys, tmp_path):
    """The rectangle touching the kerb at the start: the simulation would end at once as
    ``start_overlap``; the single run and the search refuse it, naming ``x0`` / ``--x0``."""
    with pytest.raises(MapError) as e:
        api.run("parallel", TOUCHING)
    assert e.value.key == "x0" and "touches obstacle 'kerb'" in str(e.value)
    with pytest.raises(MapError) as e:
        api.search("grid", map="parallel", x0=TOUCHING, n=2)
    assert e.value.key == "x0"
    rc = main(["parking", "--x0", *map(str, TOUCHING), "--json"])
    out, err = capsys.readouterr()
    assert rc == 2 and out == ""
    assert err.strip().count("\n") == 0 and "--x0: the robot's rectangle at the start pose touches" in err
    # 1 mm away it runs
    r = api.run("parallel", (0.0, -0.014, 0.0), t_max=1.0)
    assert r["status"] != "start_overlap"


def _run(x0, direction, schedule, xs=None, omap=None):
    from pfjax.parking.study_config import ParkingStudy
    from pfjax.parking.study_runs import one

    return one(ParkingStudy(), x0, direction, schedule, xs=xs, omap=omap)


def test_trajectory_figure_has_a_legend_and_shows_the_whole_path(tmp_path, monkeypatch):
    """A garage X_s far beyond the layout's limits stays in view, with the rectangle around it, and
    the figure explains its marks in a legend outside the panels."""
    from pfjax.parking import study_runs
    from pfjax.parking.maps import GARAGE, to_obstacle_map
    from pfjax.parking.schedules import GARAGE_START

    saved = {}
    monkeypatch.setattr(study_runs, "save", lambda fig, d, name: saved.setdefault(name, fig))
    run = _run(GARAGE_START, 1, (1.0,), xs=-2.6, omap=to_obstacle_map(list(GARAGE.values())))
    study_runs._trajectory_figure({"far": run}, ["far"], GARAGE, tmp_path, "garage_xs", "{name}", "sw.")
    fig = saved["garage_xs"]
    ax = fig.axes[0]
    p, r, tr = run
    st = np.asarray(tr.state)[np.asarray(tr.running)]
    reach = math.hypot(max(float(p.shape.front), float(p.shape.length - p.shape.front)), 0.5 * float(p.shape.width))
    x0, x1 = ax.get_xlim()
    assert x0 <= st[:, 0].min() - reach + 1e-9 and x1 >= st[:, 0].max() + reach - 1e-9
    assert st[:, 0].min() < -2.2  # beyond the layout's default limit
    assert len(fig.legends) == 1
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("start" in t for t in labels) and any("switch" in t for t in labels) and any("end" in t for t in labels)
    # the legend lies below the panels: it covers no axes
    fig.canvas.draw()
    box = fig.legends[0].get_window_extent()
    assert box.y1 <= ax.get_window_extent().y0 + 1e-6


def test_histories_axes_are_labelled():
    from pfjax.parking import figures as F
    from pfjax.parking.maps import PARALLEL, to_obstacle_map
    from pfjax.parking.schedules import CASES

    c = CASES["A"]
    p, r, tr = _run(c["x0"], c["direction"], c["schedule"], omap=to_obstacle_map(list(PARALLEL.values())))
    fig = F.histories_figure(tr, r, p.control, "A")
    assert all(ax.get_ylabel() for ax in fig.axes) and fig.axes[-1].get_xlabel() == "t [s]"
    fig.canvas.draw()
    for ax in fig.axes:  # each legend beside its axes, covering no curve
        assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1 - 1e-6


def test_report_wording():
    """The case-B verdict calls combinations matched to the source's outcomes a selection, not
    evidence; the Monte Carlo heading says all schedules share their runs."""
    from pfjax.parking import report

    a = {
        "n_combinations": 6,
        "all_four_reproduced": [{"zone": "whole"}],
        "by_zone": {"middle": {"B": {"converged": 3}}, "whole": {"B": {"stuck": 3}}},
    }
    sim = {"scan_period": 0.1, "stuck_travel": 0.1, "stuck_switches": 4}
    s = {
        "assumptions": a,
        "config": {"sim": sim},
        "calibration": {"front": 0.1746, "front_source": "calibrated"},
        "cases": [{"case": "B", "status": "converged", "switches": 9, "time_s": 63.9}],
        "verdicts": [{"subject": "case B", "verdict": "not reproduced"}],
    }
    text = report._b_verdict(s)
    assert "not evidence" in text and "before" not in text
    assert text.startswith("**Verdict on case B**: not reproduced") and "B parks after 9 switches" in text
    mc = {"n_runs": 2, "pos_scatter": 0.05, "theta_scatter_deg": 5.0, "scan_lo": 0.05, "scan_hi": 0.2}
    mc |= {"speed_lo": 0.04, "speed_hi": 0.06, "lag_probability": 0.5}
    row = {"success_ci95": [0.1, 0.9], "success_rate": 0.5, "status_counts": {"converged": 1, "timeout": 1}}
    row |= {"time_s": {"q50": 40.0, "q95": 50.0}, "by_lag": {}}
    blocks = report._montecarlo({"config": {"montecarlo": mc}, "montecarlo": {"a": row, "b": row, "c": row}})
    assert "the same runs for every schedule" in blocks[0].text


def test_monte_carlo_status_legend_covers_no_bar():
    import pandas as pd

    from pfjax.parking import figures as F

    rows = [
        {"schedule": lab, "converged": ok, "time_s": 50.0 if ok else float("nan"), "status": st}
        for lab in ("fixed: a", "GA best: b", "grid best: c")
        for ok, st in [(True, "converged")] * 8 + [(False, "timeout")] * 2
    ]
    fig = F.monte_carlo_figure(pd.DataFrame(rows))
    fig.canvas.draw()
    ax = fig.axes[1]
    legend = ax.get_legend().get_window_extent()
    assert legend.x0 >= ax.get_window_extent().x1 - 1e-6


def test_json_counts_carry_units(capsys):
    """Every number ``pfjax parking --json`` and ``pfjax parking-search --json`` print has a unit,
    the counts included."""
    import json

    rc = main(["parking", "--map", "garage", "--horizon", "5", "--json"])
    run = json.loads(capsys.readouterr().out)
    rc |= main(["parking-search", "--method", "grid", "--n", "2", "--horizon", "5", "--json"])
    grid = json.loads(capsys.readouterr().out)
    assert rc == 0
    for out in (run, grid):
        for key in ("switches", "time_s", "error"):
            assert out["units"].get(key), key
    assert grid["units"]["n_simulations"].startswith("runs") and grid["units"]["n"]


def test_rows_that_search_the_assumptions_for_the_outcome_are_not_independent():
    """ "B is stuck in some combination" and "all four outcomes at once" hold for readings selected by
    the source's outcomes: their basis says so (not independent evidence)."""
    from pfjax.reproduce.parking import all_four_verdicts, case_b_verdicts
    from pfjax.reproduce.verdict import FILTERED

    sweep = {
        "n_combinations": 504,
        "all_four_reproduced": [{"a_f": 0.17}],
        "by_zone": {"whole": {"B": {"stuck": 167}}},
        "status_counts": {"B": {"stuck": 167}},
        "b_min_leg_m": 0.21,
    }
    rows = [
        r for r in case_b_verdicts({"status": "stuck", "switches": 9, "time_s": 60.0}, sweep) if "every" in r.subject
    ]
    rows += all_four_verdicts(sweep)
    assert len(rows) == 2 and all(r.basis == FILTERED and r.verdict == "no verdict" for r in rows), rows
    assert rows[1].claim.startswith("pfjax's comparison, not a claim of the source")
