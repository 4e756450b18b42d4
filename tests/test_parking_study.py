"""The parking study's config schema (:mod:`pfjax.parking.study_config`): defaults, the ``--quick``
preset, one-line errors naming the key, and the script's exit code 2 with nothing written."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from pfjax.config import ConfigError
from pfjax.parking.study_config import QUICK, ParkingStudy, load

ROOT = Path(__file__).resolve().parents[1]
TOML = ROOT / "studies" / "parking.toml"

#: the study's settings as the reproduction documents them (docs/reproductions/parking.md)
REFERENCE = {
    "name": "parking",
    "seed": 0,
    "controller": {"k1": 32.0, "k2": 8.0, "speed": 0.05},
    "sim": {
        "scan_period": 0.1,
        "t_max": 200.0,
        "tol": 0.02,
        "n_sub": 2,
        "front": 0.0,
        "chunk": 1024,
        "stuck_switches": 4,
        "stuck_travel": 0.1,
    },
    "assumptions": {
        "fronts": [0.10, 0.125, 0.15, 0.175, 0.20, 0.225, 0.25],
        "zones": ["middle", "axle", "whole"],
        "scan_periods": [0.05, 0.1, 0.2],
        "decision_delays": [False, True],
        "lags": [False, True],
        "pauses": [0.0, 1.0],
    },
    "garage": {"xs_values": [-0.9, -1.2, -1.8]},
    "experiment": {"pause": 1.0},
    "search": {"weight": 100.0, "population": 20, "generations": 100, "grid_n": 32, "ga_seeds": 3, "max_switches": 10},
    "start_map": {"x0": [-1.5, -1.3, -1.1, -0.9, -0.7], "theta0_deg": [-80.0, -40.0, 0.0, 40.0, 80.0], "grid_n": 10},
    "montecarlo": {
        "n_runs": 1000,
        "pos_scatter": 0.05,
        "theta_scatter_deg": 5.0,
        "scan_lo": 0.05,
        "scan_hi": 0.2,
        "speed_lo": 0.04,
        "speed_hi": 0.06,
        "lag_probability": 0.5,
    },
}


def test_defaults_and_the_shipped_toml_are_the_documented_settings():
    assert ParkingStudy().model_dump(mode="json") == REFERENCE
    assert load(TOML).model_dump(mode="json") == REFERENCE


def test_the_schema_offers_exactly_the_simulated_detection_zones():
    from typing import get_args

    from pfjax.parking.assumptions import ZONES
    from pfjax.parking.study_config import Zone

    assert get_args(Zone) == tuple(ZONES)


def test_quick_preset_sets_only_sizes_and_set_overrides_it():
    q = load(TOML, quick=True)
    assert q.montecarlo.n_runs == QUICK["montecarlo"]["n_runs"] == 16 and q.search.grid_n == 3
    assert q.controller == ParkingStudy().controller and q.sim.scan_period == 0.1
    assert load(TOML, ["montecarlo.n_runs=5"], quick=True).montecarlo.n_runs == 5


def test_every_field_has_a_description_with_a_unit():
    def walk(model):
        for name, f in model.model_fields.items():
            assert f.description, name
            sub = f.annotation
            if isinstance(sub, type) and issubclass(sub, ParkingStudy.__mro__[1]):
                walk(sub)
            else:
                assert "[" in f.description and f.description.rstrip().endswith("]"), (name, f.description)

    walk(ParkingStudy)


@pytest.mark.parametrize(
    "override, key",
    [
        ("sim.scan_perod=0.1", "sim.scan_perod: unknown key"),
        ("controller.k1=0", "controller.k1:"),
        ("sim.front=0.6", "sim.front:"),
        ("sim.scan_period=0.001", "sim.scan_period: sim.t_max / scan period may be at most 20000, got 200 / 0.001"),
        ("assumptions.fronts=[0.1, 0.7]", "assumptions.fronts[1]:"),
        ("assumptions.zones=['front']", "assumptions.zones"),
        ("assumptions.pauses=[-1.0]", "assumptions.pauses[0]:"),
        ("search.grid_n=65", "search.grid_n:"),
        ("start_map.theta0_deg=[90.0]", "start_map.theta0_deg[0]: magnitude must be < 90"),
        ("montecarlo.scan_lo=0.3", "montecarlo.scan_lo: must be <= scan_hi"),
        ("montecarlo.lag_probability=1.5", "montecarlo.lag_probability:"),
        ("seed=-1", "seed:"),
        ("sim.stuck_switches=10000000000", "sim.stuck_switches:"),
        ("sim.n_sub=1000000000", "sim.n_sub:"),
        ("sim.chunk=1000000000000", "sim.chunk: must be <= 10000000"),
        ("search.max_switches=1000000000000", "search.max_switches: must be <= 1000"),
        ("search.ga_seeds=1000000", "search.ga_seeds:"),
        ("search.ga_seeds=900", "search.ga_seeds: the GA runs together may simulate at most 1e+08"),
        ("montecarlo.n_runs=10000000000", "montecarlo.n_runs: the Monte Carlo may simulate at most 1e+08"),
        ("sim.t_max=2000.5", "sim.scan_period: sim.t_max / scan period may be at most 20000, got 2000.5 / 0.1 = 20005"),
    ],
)
def test_a_bad_key_or_value_is_one_line_naming_the_key(override, key):
    with pytest.raises(ConfigError) as e:
        load(TOML, [override])
    assert str(e.value).startswith(key) and "\n" not in str(e.value)


def test_a_batch_beyond_the_memory_budget_names_sim_chunk():
    """A batch of sim.chunk runs with the searches' switch logs (1.4 TB here) is refused by the
    memory budget, before anything is compiled or allocated."""
    with pytest.raises(ConfigError, match=r"^sim\.chunk: a batch of sim\.chunk = 9000000 runs needs about"):
        load(TOML, ["sim.chunk=9000000", "search.max_switches=1000"])


@pytest.mark.parametrize("override, key", [("sim.tol=-1", "sim.tol"), ("montecarlo.n_runs=0", "montecarlo.n_runs")])
def test_the_script_exits_2_with_one_line_and_writes_nothing(tmp_path, override, key):
    out = tmp_path / "out"
    bad = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "parking.py"), "--quick", "--set", override, "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and key in bad.stderr, bad.stderr
    assert not out.exists()


def test_a_search_where_every_candidate_fails_is_data_not_a_crash(tmp_path):
    """With one switch allowed no candidate parks (fitness 0 everywhere): the study finishes, the
    GA's ratio to the grid's best is null and the verdict says not reproduced."""
    import json

    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, str(ROOT / "studies" / "parking.py"), "--quick", "--set", "search.max_switches=1"]
        + ["--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    s = json.loads((out / "summary.json").read_text())
    assert s["search"]["grid"]["fitness"] == 0
    assert all(g["fitness_ratio_to_grid_best"] is None for g in s["search"]["ga_runs"])
    assert "no grid point scores" in (out / "report.md").read_text()
