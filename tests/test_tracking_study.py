"""Smoke test of ``studies/vehicle_tracking.py --quick``: every output is written, pandas reads it, and the
numbers agree across files (summary.json vs the Parquet tables vs a recomputation from the run rows).

References: the config hash is recomputed with :func:`pfjax.provenance.config_hash` from the stored config;
the four-outcome table is recounted from ``lemma_runs.parquet``; Clopper-Pearson success is recounted
from ``mc_runs.parquet`` with scipy's beta quantiles; the geometric check must find no counterexample inside the bound (1e-12 rad).
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.stats import beta

from pfjax.provenance import config_hash

STUDY = Path(__file__).resolve().parents[1] / "studies" / "vehicle_tracking.py"
TABLES = ("lemma_runs", "lemma_table", "geometry", "mc_runs")


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    spec = importlib.util.spec_from_file_location("vehicle_tracking_for_test", STUDY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    d = tmp_path_factory.mktemp("vt") / "out"
    assert mod.main(["--quick", "--out", str(d)]) == 0
    return d


@pytest.mark.slow
def test_quick_study_outputs_consistent(out):
    s = json.loads((out / "summary.json").read_text())
    assert s["quick"] and s["config_sha256"] == config_hash(s["config"])
    for name in ("lemma_outcomes", "lemma_geometry", "mc_final_error"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 1000 and (out / "figures" / f"{name}.svg").exists()
    html = (out / "report.html").read_text()
    assert s["config_sha256"][:16] in html and "data:image/png;base64," in html
    frames = {}
    for name in TABLES:
        meta = pq.read_schema(out / f"{name}.parquet").metadata
        assert meta[b"pfjax.config_sha256"].decode() == s["config_sha256"] and meta[b"pfjax.seed"].decode() == str(
            s["seed"]
        )
        frames[name] = pd.read_parquet(out / f"{name}.parquet")
    assert not list(out.parent.glob(".vehicle_tracking.*"))  # the temporary directory was renamed away

    runs, table = frames["lemma_runs"], frames["lemma_table"]
    lem = s["config"]["lemma"]
    assert (
        len(runs)
        == s["lemma_grid"]["n_runs"]
        == 2 * 6 * len(lem["p"]) * len(lem["l_abs"]) * len(lem["gamma_max_deg"]) * len(lem["offsets"])
    )
    assert table.to_dict(orient="records") == s["lemma_grid"]["table"]
    ok = runs.status == "ok"
    for r in s["lemma_grid"]["table"]:
        g = runs[(runs["mode"] == r["mode"]) & (runs.region == r["region"])]
        gok = g.status == "ok"
        assert r["n"] == len(g) and r["failed"] == int((~gok).sum())
        assert r["both"] == int((gok & g.converged & g.phi_converged).sum())
        assert r["z_only"] + r["phi_only"] + r["neither"] + r["both"] + r["failed"] == r["n"]
    assert (
        runs[ok].window_max_z.notna().all()
        and (runs.inside_bound == (runs.p.abs() < math.pi / 2 / runs.gamma_max_deg.map(math.radians))).all()
    )

    geo = s["geometry"]
    assert geo["max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2"] < 1e-12 and geo["counterexamples_only_outside_bound"]
    assert len(frames["geometry"]) == 2 * geo["n_states_z_err_0"]

    mc = frames["mc_runs"]
    for mode, m in s["monte_carlo"].items():
        d = mc[mc["mode"] == mode]
        k = int(d.success.sum())
        assert m["n"] == len(d) == s["config"]["mc"]["n_runs"] and m["success_rate"] == pytest.approx(k / len(d))
        n = len(d)  # Clopper-Pearson from the beta quantiles directly
        ref = [beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0, beta.ppf(0.975, k + 1, n - k) if k < n else 1.0]
        assert m["success_ci95"] == pytest.approx(ref, abs=1e-9)
        assert sum(m["status_counts"].values()) == len(d)
