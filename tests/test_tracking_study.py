"""Smoke test of ``studies/vehicle_tracking.py --quick``: every output is written, pandas reads it, and the
numbers agree across files (summary.json vs the Parquet tables vs a recomputation from the run rows), and every
number of summary.json has a unit in its ``units`` map (``tests/units_check.py``).

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
from units_check import numbers_without_units

from pfjax.provenance import config_hash
from pfjax.tracking.lemma import read_at

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
    units = s["units"]  # every number of summary.json has a unit, the metrics' those of pfjax track --json
    assert numbers_without_units(s) == []
    assert units["quantiles"]["iae"] == "m s" and units["quantiles"]["max_abs_gamma_deg"] == "deg"
    assert (
        units["wrong_distance_min_z_err"] == "m" and units["max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2"] == "rad"
    )
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

    # the flags read again from the window maxima at the configured tolerances are the simulator's
    # (the verdict's tighter reading, pfjax.tracking.lemma.read_at, applies the simulator's rule)
    again = read_at(runs, s["config"]["sim"]["tol_z"], s["config"]["sim"]["tol_phi"])
    assert (again.converged == runs.converged).all() and (again.phi_converged == runs.phi_converged).all()
    assert runs.converged.any() and (~runs.converged).any()  # both outcomes occur: the comparison can fail

    geo = s["geometry"]
    assert geo["max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2"] < 1e-12
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


def _load_script():
    spec = importlib.util.spec_from_file_location("vehicle_tracking_for_errors", STUDY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_every_column_of_every_table_has_a_unit(out):
    """Every Parquet column the study writes carries a unit and a description (field metadata); the
    numeric ones a unit that is not empty, codes and counts of runs aside; lemma_table.csv carries
    the config hash, as the other studies' CSV files do."""
    import pyarrow as pa

    from pfjax.tracking.study import COLUMNS

    physical = {
        "window_max_z": "m",
        "window_max_phi_err": "rad",
        "final_error_norm": "m",
        "final_d": "m",
        "offset_along": "m",
        "offset_left": "m",
        "gamma": "rad",
        "phi": "rad",
        "z_err": "m",
        "iae": "m s",
        "speed": "m/s",
        "fail_time": "s",
        "n": "runs",
    }
    seen = set()
    for path in sorted(out.glob("*.parquet")):
        for f in pq.read_schema(path):
            md = f.metadata or {}
            assert b"unit" in md and md.get(b"description"), (path.name, f.name)
            unit = md[b"unit"].decode()
            if pa.types.is_integer(f.type) or pa.types.is_floating(f.type):
                assert unit or f.name in ("run", "status_code"), (path.name, f.name)
            assert unit == COLUMNS[f.name][0]
            seen.add(f.name)
            if f.name in physical:
                assert unit == physical[f.name], (path.name, f.name, unit)
    assert set(physical) <= seen
    assert set(TABLES) == {p.stem for p in out.glob("*.parquet")}
    csv = pd.read_csv(out / "lemma_table.csv")
    s = json.loads((out / "summary.json").read_text())
    assert csv.columns[0] == "config_sha256" and (csv.config_sha256 == s["config_sha256"]).all()
    assert csv.drop(columns="config_sha256").to_dict(orient="records") == s["lemma_grid"]["table"]


@pytest.mark.parametrize(
    "setting, key",
    [
        ("mc.n_run=3", "mc.n_run"),  # unknown key
        ("mc.n_runs=0", "mc.n_runs"),  # out of range
        ("lemma.p=[0.0, 1.0]", "lemma.p"),  # cross-field check
        ("lemma.offsets=[[1.0]]", "lemma.offsets"),  # not a pair
        ("sim.dt='x'", "sim.dt"),  # wrong type
    ],
)
def test_bad_config_one_line_exit_2_nothing_written(tmp_path, capsys, setting, key):
    mod = _load_script()
    out = tmp_path / "out"
    assert mod.main(["--quick", "--out", str(out), "--set", setting]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err, err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_schema_defaults_are_the_shipped_toml():
    """The TOML lists every key with the schema's default (the study's published sizes)."""
    import tomllib

    from pfjax.tracking.study_config import TrackingStudy

    toml = STUDY.with_suffix(".toml")
    assert TrackingStudy().model_dump(mode="json") == tomllib.loads(toml.read_text())


@pytest.mark.slow
def test_report_md_and_html_carry_the_headline_numbers(out):
    s = json.loads((out / "summary.json").read_text())
    md, html = (out / "report.md").read_text(), (out / "report.html").read_text()
    for mode, m in s["monte_carlo"].items():
        rate = f"{100 * m['success_rate']:.2f} %"
        lo, hi = (f"{100 * x:.2f}" for x in m["success_ci95"])
        for text in (md, html):
            assert rate in text and lo in text and hi in text and mode in text
    n_runs = f"({s['lemma_grid']['n_runs']} runs)"
    g = f"{s['geometry']['wrong_distance_min_z_err']:.3f} m"
    for text in (md, html):
        assert n_runs in text and g in text and s["config_sha256"][:16] in text
    assert "![" in md and "data:image/png;base64," in html


def test_the_final_error_curve_counts_failed_runs_as_never_within_the_band():
    from pfjax.tracking.report import final_error_ecdf

    runs = pd.DataFrame(
        {"status": ["ok", "singular", "ok", "diverged"], "window_max_z": [0.02, float("nan"), 0.001, float("nan")]}
    )
    x, y = final_error_ecdf(runs)
    assert list(x) == [0.001, 0.02] and list(y) == [0.25, 0.5]  # ends at the share that finished, not at 1
