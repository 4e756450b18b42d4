"""The parking study's settings reach what it computes and writes: runs are never cut off before
``t_max``, the start map runs the study's controller and scanner, the verdicts, report and figures
state the configured values (and the source's as the source's), the searches' size is checked at
config load, the search's fitness is 1/s, the GA verdict's distinctness counts α₂, and the Case B
numbers of docs/reproductions/parking.md are the assumptions sweep's.

References: ``t_max`` and the scanner period (hand-computed period counts), the config's values as
typed, the source's (docs/reproductions/parking.md §4: 1 s stops, the search's cut-off at 10), and
the sweep :func:`pfjax.parking.assumptions.case_sweep` itself.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import matplotlib
import numpy as np
import pytest

from pfjax.config import ConfigError
from pfjax.errors import InputError
from pfjax.parking.maps import GARAGE, PARALLEL, to_obstacle_map
from pfjax.parking.model import control_params
from pfjax.parking.simulate import (
    ParkingConfig,
    Status,
    periods_needed,
    run_jit,
    run_many,
    run_params,
    stack_params,
)
from pfjax.parking.study_config import load

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
TOML = ROOT / "studies" / "parking.toml"
PMAP, GMAP = to_obstacle_map(list(PARALLEL.values())), to_obstacle_map(list(GARAGE.values()))
CASE_C = ((0.1, 0.5, 0.0), -1, (1.0, 0.5))


@pytest.mark.parametrize(
    "override, key",
    [
        (["assumptions.scan_periods=[0.1, 0.005]"], "assumptions.scan_periods[1]: sim.t_max / scan period"),
        (
            ["montecarlo.scan_lo=0.002", "montecarlo.scan_hi=0.004"],
            "montecarlo.scan_lo: sim.t_max / scan period may be at most 20000, got 200 / 0.002",
        ),
    ],
)
def test_a_study_period_beyond_the_loop_bound_is_refused_naming_its_key(override, key):
    with pytest.raises(ConfigError) as e:
        load(TOML, override, quick=True)
    assert str(e.value).startswith(key)
    load(TOML, ["assumptions.scan_periods=[0.01]", "montecarlo.scan_lo=0.01"], quick=True)  # 20000 periods pass


def test_a_batch_that_the_loop_bound_would_cut_off_is_refused_and_a_sized_one_runs_to_t_max():
    p = run_params(*CASE_C, scan_period=0.005)
    with pytest.raises(InputError) as e:
        run_many(stack_params([p]), PMAP, ParkingConfig(t_max=200.0, max_samples=20000))
    assert e.value.key == "scan_period" and "40001 scanner periods" in str(e.value)
    cfg = ParkingConfig(t_max=3.0, max_samples=periods_needed(3.0, 0.005))
    r = run_many(stack_params([p, run_params(*CASE_C, scan_period=0.1)]), PMAP, cfg, chunk=2)
    assert list(r.status) == [int(Status.TIMEOUT)] * 2 and np.allclose(r.time, 3.0, rtol=1e-9, atol=0)
    assert periods_needed(200.0, 0.1) == 2001 and ParkingConfig().max_samples == 20001


def test_the_timeout_is_relative_to_the_step():
    """t_max = 1e-9 s at T_s = 1e-12 s: 1,000 periods, the timeout at t_max, not after one step."""
    r = run_jit(run_params(*CASE_C, scan_period=1e-12), PMAP, ParkingConfig(t_max=1e-9))
    assert int(r.status) == Status.TIMEOUT and float(r.time) == pytest.approx(1e-9, rel=1e-9)


def test_the_start_map_runs_the_given_base():
    from pfjax.parking.switch_search import garage_base, start_map

    kw = dict(n=2, chunk=8)
    slow = start_map(GMAP, [-0.9], [-80.0], **kw)[0]
    fast = start_map(GMAP, [-0.9], [-80.0], base=garage_base(control=control_params(speed=0.1)), **kw)[0]
    assert fast["time_s"] != slow["time_s"]


def test_the_study_start_map_uses_the_study_run_settings(monkeypatch):
    from pfjax.parking import study_parts

    seen = {}

    def capture(*args, **kwargs):
        seen.update(kwargs)
        raise RuntimeError("captured")

    monkeypatch.setattr(study_parts, "start_map", capture)
    cfg = load(TOML, ["controller.speed=0.1", "controller.k1=20", "sim.scan_period=0.05", "sim.front=0.2"], quick=True)
    with pytest.raises(RuntimeError, match="captured"):
        study_parts.part_start_map(cfg, None, GMAP)
    b = seen["base"]
    assert float(b.control.speed) == 0.1 and float(b.control.k1) == 20.0 and float(b.scan_period) == 0.05
    assert float(b.shape.front) == pytest.approx(0.2)


def _outcome(status="converged", switches=2, time_s=50.0):
    return {"status": status, "switches": switches, "time_s": time_s}


def _verdict_inputs():
    from pfjax.reproduce.parking import GA_SOLUTIONS

    outcomes = {k: _outcome() for k in ("A", "B", "C", "D", "D+pause")}
    for xs in (-0.9, -1.2, -1.8):
        outcomes[f"garage {xs:g}"] = outcomes[f"garage {xs:g}+pause"] = _outcome()
    for xs, a1, a2 in GA_SOLUTIONS:
        name = f"GA solution ({xs:g}, {a1:g}, {a2:g})"
        outcomes[name] = outcomes[name + "+pause"] = _outcome()
    calibration = {"simulated_first_switch": {"x": 0.074, "y": 0.047}, "switch_x": 0.074, "y_source": 0.047}
    calibration |= {"a_f": 0.1746, "front": 0.1746, "front_source": "calibrated", "scan_period": 0.1, "speed": 0.05}
    calibration["tolerance_m"] = 0.005
    counts = {c: {"converged": 1} for c in "ABCD"}
    sweep = {
        "n_combinations": 1,
        "status_counts": counts,
        "by_zone": {"middle": counts},
        "b_min_leg_m": 0.2,
        "all_four_reproduced": [],
    }
    runs = [dict(xs=-1.0, alpha1=4.57, alpha2=1.25, fitness_ratio_to_grid_best=0.95)]
    solutions = [dict(fitness_ratio_to_grid_best=0.9)] * 2
    return outcomes, calibration, sweep, {"runs": runs, "source_solutions": solutions, "grid_n": 32}


def test_verdicts_state_the_configured_stop_and_stuck_test_and_the_source_its_own():
    from pfjax.reproduce.parking import verdicts

    rows = verdicts(*_verdict_inputs(), pause=2.5, stuck_travel=0.3, stuck_switches=3)
    text = " | ".join(" | ".join(map(str, v)) for v in rows)
    assert "less than 0.3 m of travel over the last 3 legs" in text and "0.1 m" not in text
    assert "2.5 s stop at each reversal" in text
    assert "D: 47 s in the experiment, with a 1 s stop at each reversal" in text  # the source's stop
    scenarios = [v.subject for v in rows if "stop" in v.subject]
    assert len(scenarios) == 5 and all("2.5 s stop" in s for s in scenarios)


def test_the_report_attributes_the_stop_and_the_cut_off():
    from pfjax.parking import report

    config = load(TOML, ["experiment.pause=2.5", "search.max_switches=5", "sim.stuck_travel=0.3"], quick=True)
    s = {"config": config.model_dump(mode="json"), "wall_s": 1.0, "machine": "m", "verdicts": []}
    header = report._header(s)[0].text
    assert "beyond 5 switches" in header and "cuts off beyond 10" in header and "0.3 m of travel" in header
    intro = report._verdicts(s)[1].text
    assert "source states a 1 s stop at each reversal for case D's experiment" in intro and "2.5 s here" in intro


def test_the_search_figure_states_the_weight():
    from pfjax.parking.figures import search_figure

    table = {
        "fitness": np.linspace(0.001, 0.01, 8),
        "xs": np.repeat([-1.0, -0.9], 4),
        "alpha1": np.tile(np.repeat([1.0, 2.0], 2), 2),
        "alpha2": np.tile([1.0, 2.0], 4),
    }
    ga = {"history_best_fitness": [0.01], "history_mean_fitness": [0.005], "xs": -1.0, "alpha1": 1.0}
    fig = search_figure(ga, table, 2, weight=7.0)
    assert fig.axes[0].get_ylabel() == "J = 1/(t_e + 7 e) [1/s]"


def test_search_json_fitness_is_in_inverse_seconds():
    from pfjax.tables import PARKING_SEARCH_UNITS as SEARCH_UNITS

    for key in ("fitness", "history_best_fitness", "history_mean_fitness"):
        assert SEARCH_UNITS[key].startswith("1/s "), key


@pytest.mark.parametrize(
    "override, key",
    [
        ("search.population=2000000", "search.population: must be <= 1000000"),
        ("search.generations=2000000", "search.generations: must be <= 1000000"),
        ("search.grid_n=64", "search.grid_n: the search may simulate at most 1e+08 scanner periods"),
        ("search.population=1000", "search.population/search.generations: the search may simulate at most 1e+08"),
        ("start_map.grid_n=20", "start_map.grid_n: the search may simulate at most 1e+08"),
    ],
)
def test_the_searches_size_is_checked_at_config_load(override, key):
    with pytest.raises(ConfigError) as e:
        load(TOML, [override])
    assert str(e.value).startswith(key) and "\n" not in str(e.value)
    if "grid_n=64" in override:  # the API's limit: n = 64 passes at a 38 s horizon
        load(TOML, [override, "sim.t_max=38"])


def test_scatter_and_weight_descriptions_match_the_sampling_and_the_fitness():
    from pfjax.parking.study_config import MonteCarlo, Search

    for key in ("pos_scatter", "theta_scatter_deg"):
        d = MonteCarlo.model_fields[key].description
        assert "uniform" in d and "half-width" in d and "standard deviation" not in d
    d = Search.model_fields["weight"].description
    assert "end error" in d and d.endswith("[s/m]")


def test_ga_runs_are_distinct_when_a_grid_spacing_apart():
    """Two good GA runs count as distinct solutions when some gene differs by at least the grid's
    spacing in lattice steps (255 / (grid_n - 1)); adjacent lattice points do not."""
    from pfjax.reproduce.parking import LATTICE_STEP, ga_runs_verdicts

    runs = [dict(xs=-1, alpha1=4.57, alpha2=a, fitness_ratio_to_grid_best=0.95) for a in (1.25, 3.28)]
    assert ga_runs_verdicts(runs, 32)[0].verdict == "reproduced"  # 52 steps apart in alpha2, spacing 8.2
    near = [
        dict(xs=-1, alpha1=4.57, alpha2=1.25 + k * LATTICE_STEP[1], fitness_ratio_to_grid_best=0.95) for k in (0, 8)
    ]
    assert ga_runs_verdicts(near, 32)[0].verdict == "not reproduced"  # 8 steps: one grid cell
    assert ga_runs_verdicts(near, 33)[0].verdict == "reproduced"  # spacing 7.97 steps
    weak = [dict(r, fitness_ratio_to_grid_best=0.8) if i else r for i, r in enumerate(runs)]
    assert ga_runs_verdicts(weak, 32)[0].verdict == "not reproduced"  # one run below 85 % of the grid's best


def test_the_documented_whole_rectangle_counts_are_the_sweeps():
    """docs/reproductions/parking.md, Case B: the whole-rectangle reading's counts and the
    combinations that reproduce all four outcomes, recomputed (the half readings never get B stuck)."""
    from pfjax.parking.assumptions import DEFAULT_GRID, case_sweep, sweep_summary

    df = case_sweep(PMAP, {**DEFAULT_GRID, "zone": ["whole"]}, chunk=672)
    stuck = df[df.status == "stuck"].case.value_counts()
    s = sweep_summary(df)
    n = s["n_combinations"]
    page = " ".join((ROOT / "docs" / "reproductions" / "parking.md").read_text().split())
    sentence = (
        f"B get stuck ({stuck['B']} of {n} combinations), but then so do the cases the source reports "
        f"parking: A in {stuck['A']}, C in {stuck['C']} and D in {stuck['D']} of {n}."
    )
    assert sentence in page
    words = {5: "Five"}
    assert re.search(rf"{words[len(s['all_four_reproduced'])]} combinations, scattered", page)
    assert math.isfinite(s["b_min_leg_m"])
