"""The rare-event verification (:mod:`pfjax.rare.verification`, ``studies/rare_events.py``) run whole
at tiny sizes on a one-controller, one-path, 4 s version of ``studies/rare_events.toml``: the
result's parts, its units and provenance record, the coverage and spread statistics recomputed
from the estimates, and the full sizes behind docs/rare-events.md's numbers."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from units_check import numbers_without_units

from pfjax.montecarlo.config import load_study
from pfjax.outputs import read_marker
from pfjax.provenance import config_hash
from pfjax.rare import verification

STUDY = Path(__file__).resolve().parents[1] / "studies" / "rare_events.toml"
#: every part on a few hundred rollouts; batches of 32 (one compiled shape per program); the
#: falsifier's starts, whose gradient program costs seconds to compile, left out
TINY = {
    **verification.QUICK,
    "coverage_repeats": 2,
    "subset_repeats": 2,
    "mc_known": 1000,
    "mc_study": 100,
    "start_seeds": 1,
    "starts": ["explore", "none"],
    "mc_sine": 100,
    "known_budget": {"n_per_level": 100, "batch": 32, "max_rollouts": 1000},
    "study_budget": {"n_per_level": 100, "batch": 32, "max_rollouts": 300},
}


def _small_study() -> dict:
    """``studies/rare_events.toml`` with ``pi-table3`` on the sine alone, 4 s long."""
    data = tomllib.loads(STUDY.read_text())
    data["sim"].update(horizon=4.0, steady_window=1.0)
    data["success"]["from_s"] = 3.0
    data["paths"] = [{"kind": "sine"}]
    data["controllers"] = [c for c in data["controllers"] if c["name"] == "pi-table3"]
    return data


@pytest.fixture(scope="module")
def verified(tmp_path_factory):
    """``(result, verification.json as read back, output directory, progress lines, study)``."""
    out, lines, study = tmp_path_factory.mktemp("rare") / "verification", [], _small_study()
    result = verification.run(TINY, out, study, log=lines.append)
    return result, json.loads((out / "verification.json").read_text()), out, lines, study


def test_every_part_is_there(verified):
    result, on_disk, _, lines, _ = verified
    assert set(result) >= {"known", "starts", "coverage", "study", "sine_check", "units", "config", "wall_s"}
    assert set(on_disk) == set(result)
    assert list(result["known"]) == list(verification.KNOWN_STD)
    for label, entry in result["known"].items():
        assert set(entry) == {"std_deg", "reference", "is", "subset"} | ({"mc"} if label == "1e-4" else set())
        assert entry["std_deg"] == verification.KNOWN_STD[label]
        for method in entry.keys() - {"std_deg", "reference"}:
            r = entry[method]
            assert r["method"] == method and r["holds_reference"] == (
                r["ci95"][0] <= entry["reference"] <= r["ci95"][1]
            )
    assert 0 < result["known"]["1e-4"]["mc"]["n_rollouts"] <= TINY["mc_known"]
    assert set(result["starts"]) == {"reference", *TINY["starts"]}
    assert all(len(result["starts"][how]["n_rollouts"]) == TINY["start_seeds"] for how in TINY["starts"])
    assert list(result["study"]) == ["pi-table3"]
    assert set(result["study"]["pi-table3"]) == {"path", "band"}
    assert set(result["study"]["pi-table3"]["band"]) == {"is", "subset", "mc"}
    assert result["study"]["pi-table3"]["band"]["mc"]["n_rollouts"] == TINY["mc_study"]
    assert set(result["sine_check"]) == {"mc", "is", "subset"}
    assert result["sine_check"]["mc"]["n_rollouts"] == TINY["mc_sine"]
    # the study's budget overrides reach its estimates (one stratum: the whole budget)
    for r in result["study"]["pi-table3"]["path"].values():
        assert r["n_rollouts"] <= 2 * TINY["study_budget"]["max_rollouts"]
    assert [line.split()[0] for line in lines].count("known") == 6 and lines[-1].startswith("sine check")


def test_every_number_has_a_unit(verified):
    result, on_disk, *_ = verified
    assert numbers_without_units(result) == []
    assert numbers_without_units(on_disk) == []
    # "coverage" is a block and a field: the block's other numbers have their own units
    for block in result["coverage"].values():
        assert numbers_without_units({"units": result["units"], "block": block}) == []
    assert result["units"]["p_fail"] == "probability per run"  # pfjax.rare.study.UNITS, not restated


def test_provenance_stamp(verified):
    result, on_disk, out, _, study = verified
    config = verification.verification_config(TINY, load_study(data=study)[0])
    assert result["config"] == config
    assert result["config_sha256"] == on_disk["config_sha256"] == config_hash(config)
    assert read_marker(out)["config_sha256"] == config_hash(config) and read_marker(out)["seed"] == 0
    import pfjax

    assert result["pfjax_version"] == pfjax.__version__ and result["seed"] == verification.SEED
    assert result["machine"] and set(result["cpu_settings"]) >= {"vector_width", "block_bytes"}
    # the same config, the same hash; other sizes, another
    assert verification.verification_config(dict(TINY), load_study(data=study)[0]) == config
    assert config_hash(verification.verification_config(verification.FULL, load_study(data=study)[0])) != config_hash(
        config
    )


def test_coverage_is_recomputed_from_the_estimates(verified):
    result, *_ = verified
    p = result["known"]["1e-4"]["reference"]
    for method, n in (("is", TINY["coverage_repeats"]), ("subset", TINY["subset_repeats"])):
        c = result["coverage"][method]
        assert c["reference"] == p and c["repeats"] == n == len(c["estimates"]) == len(c["ci95"])
        assert c["holds_reference"] == [lo <= p <= hi for lo, hi in c["ci95"]]
        assert c["coverage"] == pytest.approx(np.mean(c["holds_reference"]), abs=1e-15)
        assert c["mean_estimate_over_reference"] == pytest.approx(np.mean(c["estimates"]) / p, rel=1e-12)
        assert c["mean_rel_error"] == pytest.approx(np.mean(c["rel_error"]), rel=1e-12)
        assert c["mean_rollouts"] == pytest.approx(np.mean(c["n_rollouts"]), rel=1e-12)
    runs = result["coverage"]["subset"]["runs"]
    ps = np.asarray(runs["p"])
    assert runs["n_runs"] == len(ps) >= TINY["subset_repeats"]
    assert runs["observed_cov"] == pytest.approx(ps.std(ddof=1) / ps.mean(), rel=1e-12)
    assert runs["delta_uncorrelated_rms"] == pytest.approx(np.sqrt(np.mean(np.square(runs["delta_uncorrelated"]))))
    assert runs["delta_correlated_rms"] == pytest.approx(np.sqrt(np.mean(np.square(runs["delta_correlated"]))))


def test_coverage_and_run_spread_by_hand():
    """Three repeats of reference 1e-4: two intervals hold it; subset runs of p = 1, 2, 3 (x 1e-4)."""
    rs = [
        {"p_fail": 1.0e-4, "ci95": [0.8e-4, 1.2e-4], "rel_error": 0.1, "n_rollouts": 100},
        {"p_fail": 1.3e-4, "ci95": [1.1e-4, 1.5e-4], "rel_error": 0.2, "n_rollouts": 200},
        {"p_fail": 0.9e-4, "ci95": [0.5e-4, 1.0e-4], "rel_error": 0.3, "n_rollouts": 600},
    ]
    c = verification.coverage(rs, 1.0e-4)
    assert c["holds_reference"] == [True, False, True] and c["coverage"] == pytest.approx(2 / 3)
    assert c["mean_estimate_over_reference"] == pytest.approx(16 / 15)
    assert c["mean_rel_error"] == pytest.approx(0.2) and c["mean_rollouts"] == pytest.approx(300)
    run = lambda p, lo, hi: {"p": p, "delta_uncorrelated": lo, "delta_correlated": hi}
    rs = [
        {"strata": [{"run_estimates": [run(1e-4, 0.1, 0.3), run(2e-4, 0.2, 0.4)]}]},
        {"strata": [{"run_estimates": [run(3e-4, 0.2, 0.5)]}]},
    ]
    s = verification.run_spread(rs)
    assert s["n_runs"] == 3
    assert s["observed_cov"] == pytest.approx(0.5)  # std (ddof 1) 1e-4 over mean 2e-4
    assert s["delta_uncorrelated_rms"] == pytest.approx(math.sqrt(0.09 / 3))
    assert s["delta_correlated_rms"] == pytest.approx(math.sqrt(0.5 / 3))


def test_full_sizes_are_those_of_the_documented_numbers():
    """docs/rare-events.md quotes verification.json at these sizes and budgets."""
    assert verification.FULL == {
        "coverage_repeats": 50,
        "subset_repeats": 50,
        "mc_known": 1_000_000,
        "mc_study": 600_000,
        "start_seeds": 3,
        "starts": ["falsifier", "explore", "none"],
        "mc_sine": 1_000_000,
        "known_budget": {"n_per_level": 2000, "batch": 2000, "max_rollouts": 400_000},
        "known_falsifier": {},
        "study_budget": {},
    }
    full = verification.FULL
    case = verification.known_case(1.091, full["known_budget"], full["known_falsifier"])
    assert "falsifier" not in case  # the falsifier's defaults
    assert case["rare_event"] == {"enabled": True, "n_per_level": 2000, "batch": 2000, "max_rollouts": 400_000}
    assert case["sim"] == {"horizon": 8.0, "dt": 0.01, "steady_window": 2.0} and case["dtype"] == "float64"
    assert verification.K == [-2.7381, -2.0772] and verification.COVERAGE_SEED == 1000
    assert verification.KNOWN_STD == {"1e-4": 1.372, "1e-6": 1.091, "1e-8": 0.931} and verification.BAND == 0.05
