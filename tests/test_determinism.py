"""Reproducibility and failed runs as data.

- Same config and seed: bit-identical run tables across reruns and across chunk sizes, in float32
  and float64 (batches are padded to a multiple of ``BATCH_ALIGN`` runs, so XLA's vector code
  treats every run alike; without the padding a run's metrics moved by ~1e-6 in float32).
- Every status code (nonfinite, diverged, singular, path_end) is reached by some run of a study,
  kept as a row with its status name, counted in summary.json and shown in the report.
- Every output records the config, its hash, the seed and the pfjax version; the float32 study
  is checked against float64 on a sample.
"""

import copy
import json

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import pfjax
from pfjax.montecarlo.config import load_study, study_hash
from pfjax.montecarlo.runner import controller_of, precision, simulate_runs
from pfjax.montecarlo.study import run
from pfjax.sim.status import STATUS_NAMES

BASE = {
    "name": "det",
    "n_runs": 20,
    "seed": 11,
    "chunk_size": 20,
    "f64_check_runs": 0,
    "sim": {"horizon": 2.0, "steady_window": 1.0},
    "success": {"from_s": 1.0, "band": 0.2},
    "slip": {"kind": "ou", "beta_r_deg": {"dist": "uniform", "low": -5, "high": 5}, "ou_sigma_deg": 2.0},
    "initial": {
        "lateral_offset": {"dist": "uniform", "low": -0.3, "high": 0.3},
        "heading_error_deg": {"dist": "uniform", "low": -20, "high": 20},
    },
    "margin": {"enabled": False},
    "paths": [{"kind": "sine"}],
    "controllers": [{"name": "pi", "type": "pi"}],
}


def table(chunk: int, dtype: str) -> pd.DataFrame:
    spec = load_study(data=copy.deepcopy(BASE), overrides=[f"chunk_size={chunk}", f"dtype='{dtype}'"])[0]
    with precision(spec):
        ctrls = {c.name: controller_of(c, spec, i) for i, c in enumerate(spec.controllers)}
        return pd.concat([df for _, _, df in simulate_runs(spec, 0, np.arange(spec.n_runs), ctrls)], ignore_index=True)


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_bit_identical_across_chunk_sizes_and_reruns(dtype):
    ref = table(20, dtype)
    assert ref["iae"].dtype == np.dtype(dtype)
    for chunk in (20, 7, 1):  # 20 again: a rerun; 7 and 1: ragged chunks (every batch padded to 32 runs)
        pd.testing.assert_frame_equal(table(chunk, dtype), ref, check_exact=True)


def test_controllers_share_sampled_chunks_with_the_same_rows(monkeypatch):
    """Each chunk is sampled once for all controllers (kept while it fits the memory budget), and
    re-sampling per controller (budget 0) gives bit-identical rows: sampling is deterministic."""
    from pfjax.montecarlo import chunk_runs as runner  # the chunk loop reads these names from its home

    data = copy.deepcopy(BASE) | {
        "controllers": [{"name": "pi", "type": "pi"}, {"name": "pi2", "type": "pi"}, {"name": "st", "type": "stanley"}]
    }
    spec = load_study(data=data, overrides=["chunk_size=8"])[0]  # 20 runs: chunks of 8, 8, 4
    calls, real = [], runner.sample_aligned
    monkeypatch.setattr(runner, "sample_aligned", lambda *a, **k: calls.append(1) or real(*a, **k))

    def rows():
        calls.clear()
        with precision(spec):
            ctrls = {c.name: controller_of(c, spec, i) for i, c in enumerate(spec.controllers)}
            df = pd.concat(
                [df for _, _, df in simulate_runs(spec, 0, np.arange(spec.n_runs), ctrls)], ignore_index=True
            )
        return df, len(calls)

    shared, n_shared = rows()
    monkeypatch.setattr(runner, "SHARED_SAMPLES_BYTES", 0)
    resampled, n_resampled = rows()
    assert (n_shared, n_resampled) == (3, 9)
    assert list(shared.controller.unique()) == ["pi", "pi2", "st"]
    pd.testing.assert_frame_equal(shared, resampled, check_exact=True)


FAILING = {
    "name": "fail",
    "n_runs": 8,
    "seed": 2,
    "chunk_size": 8,
    "f64_check_runs": 8,
    "dtype": "float32",
    "sim": {"horizon": 3.0, "steady_window": 1.0, "d_fail": 0.4},
    "success": {"from_s": 1.0, "band": 0.3},
    "initial": {"lateral_offset": {"dist": "uniform", "low": -0.2, "high": 0.2}},
    # a quarter of the runs drive at 3e38 m/s (set below, past the schema's magnitude bound): float32 RK4
    # overflows to inf in the first step (status nonfinite)
    "vehicle": {"speed": {"dist": "choice", "values": [1.0, 1.0, 1.0, 1e12]}},
    "margin": {"enabled": False},
    "paths": [
        {"kind": "line", "name": "blowup"},  # state feedback with gains at the bound
        {"kind": "line", "name": "away"},  # positive feedback drives |d| past d_fail
        {
            "kind": "circle",
            "radius": 0.12,
        },  # tighter than the steering limit: the robot passes the centre (1 - kappa d <= 0)
        {
            "kind": "spline",
            "name": "short",
            "points": [[0, 0], [0.5, 0.05], [1.0, 0.0], [1.5, 0.05]],
        },  # ends after 1.6 m
    ],
    "controllers": [
        {"name": "bad", "type": "state_feedback", "K": [1e12, -1e12]},
        {"name": "unstable", "type": "state_feedback", "K": [2.0, 0.5]},
    ],
}


@pytest.fixture(scope="module")
def failing(tmp_path_factory):
    out = tmp_path_factory.mktemp("fail") / "out"
    spec = load_study(data=copy.deepcopy(FAILING))[0]
    # Values no config may hold (the schema bounds every number by 1e12) but the simulator may still
    # meet through the Python API: they must end as statuses, not exceptions.
    # (Gains are checked again where the controller is built, so they stay within the bound.)
    speed = spec.vehicle.speed.model_copy(update={"values": [1.0, 1.0, 1.0, 3e38]})
    spec = spec.model_copy(update={"vehicle": spec.vehicle.model_copy(update={"speed": speed})})
    return spec, out, run(spec, out, progress=False, report=True)


def test_every_status_is_reached_kept_and_counted(failing):
    spec, out, summary = failing
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(runs) == 8 * 4 * 2  # nothing dropped
    assert set(runs["status"]) == set(STATUS_NAMES.values()) - {"ok"} | ({"ok"} & set(runs["status"]))
    for name, code in ((n, c) for c, n in STATUS_NAMES.items()):
        assert (runs.loc[runs.status == name, "status_code"] == code).all()
    failed = runs[runs.status != "ok"]
    assert np.isfinite(failed["fail_time"]).all() and not failed["success"].any()
    on_disk = json.loads((out / "summary.json").read_text())
    for name, c in on_disk["controllers"].items():
        counts = runs[runs.controller == name]["status"].value_counts().to_dict()
        assert c["status_counts"] == counts
        for path, b in c["per_path"].items():
            assert (
                b["status_counts"]
                == runs[(runs.controller == name) & (runs.path == path)]["status"].value_counts().to_dict()
            )
    assert len(on_disk["warnings"]) == 2  # the circle (curvature) and the short spline (length)
    html = (out / "report.html").read_text()
    for s in STATUS_NAMES.values():
        assert f"status {s}" in html
    assert "Warnings" in html and "exceeds tan(delta_max)/L" in html


def test_outputs_record_config_hash_seed_version(failing):
    spec, out, summary = failing
    h = study_hash(spec)
    s = json.loads((out / "summary.json").read_text())
    assert (s["config_sha256"], s["seed"], s["pfjax_version"]) == (h, 2, pfjax.__version__)
    assert s["config"] == spec.model_dump(mode="json")
    meta = pq.read_schema(out / "runs.parquet").metadata
    assert meta[b"pfjax.config_sha256"].decode() == h and meta[b"pfjax.seed"] == b"2"
    assert meta[b"pfjax.version"].decode() == pfjax.__version__
    assert json.loads(meta[b"pfjax.config"]) == spec.model_dump(mode="json")
    html = (out / "report.html").read_text()
    assert h in html and pfjax.__version__ in html


def test_float32_runs_checked_against_float64(failing):
    """The f64 re-simulation of 8 runs per controller (some of them at 3e38 m/s): a status may differ
    only for those (float32 overflows; float64 fails too here, but later) and is then reported; where
    the statuses agree the IAE agrees to float32 accuracy accumulated over the horizon (relative 1e-3)."""
    spec, out, summary = failing
    chk = summary["float64_check"]
    assert chk["checked"] and chk["n_per_controller"] == 8
    runs = pd.read_parquet(out / "runs.parquet")
    fast = set(zip(runs.loc[runs.speed > 1e30, "path"], runs.loc[runs.speed > 1e30, "run"]))
    checked = set(zip(runs.path, runs.run)) & {(p.label, r) for p in spec.paths for r in chk["run_indices"]}
    assert checked & fast, "the sample should hold an overflowing run"
    for name, c in chk["controllers"].items():
        assert c["n"] == 8, c
        for m in c["status_mismatches"]:
            assert (m["path"], m["run"]) in fast and m["float32"] == "nonfinite", m
        assert c["status_agreement"] == 1 - len(c["status_mismatches"]) / 8
        assert c["max_rel_diff_iae"] < 1e-3, c
    assert "Numerical precision" in (out / "report.html").read_text()
    assert len(runs) == 64
