"""``studies/kinematic_vs_dynamic.py``: its config schema (:mod:`pfjax.dynamic_study.config`) refuses a
bad key or value with one line naming it (exit 2, nothing written); ``--quick`` (shrunk further by
``--set``) writes every output; the report's Markdown and HTML carry the summary's headline numbers."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pandas as pd
import pytest

from pfjax.config import ConfigError
from pfjax.dynamic_study.config import load
from pfjax.dynamic_study.report import percent, report
from pfjax.provenance import config_hash
from pfjax.report.document import to_html, to_markdown

STUDY = Path(__file__).resolve().parents[1] / "studies" / "kinematic_vs_dynamic.py"


def _script():
    spec = importlib.util.spec_from_file_location("kinematic_vs_dynamic_for_test", STUDY)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize(
    "setting, key",
    [
        ("mu_lo=0.5", "mu_lo"),  # unknown key
        ("mu_high=0.1", "mu_high"),  # cross-field check
        ("slip_ranges_deg=[95.0]", "slip_ranges_deg"),
        ("car.params='vehicle9'", "car.params"),
        ("bench_runs=0", "bench_runs"),
        ("study.n_runs=0", "study.n_runs"),  # the arms' study config, validated by the study schema
        ("study.sim.dtt=0.1", "study.sim.dtt"),
        ("designs.alpha='x'", "designs.alpha"),  # wrong type
    ],
)
def test_bad_config_one_line_exit_2_nothing_written(tmp_path, capsys, setting, key):
    out = tmp_path / "out"
    assert _script().main(["--quick", "--out", str(out), "--set", setting]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"{key}:" in err, err
    assert not list(tmp_path.iterdir())


def test_quick_preset_sets_sizes_and_set_overrides_it():
    q = load(quick=True, overrides=["study.n_runs=5", "slip_ranges_deg=[3.0]"])
    assert (q.study["n_runs"], q.study["chunk_size"], q.slip_ranges_deg) == (5, 16, [3.0])
    assert q.study["sim"] == {"dt": 0.005, "horizon": 4.0, "steady_window": 2.0}
    assert load().study["n_runs"] == 400 and load().bench_repeats == 7
    with pytest.raises(ConfigError, match=r"^study\.nruns: unknown key \(did you mean 'study\.n_runs'\?\)$"):
        load(overrides=["study.nruns=3"])


SMALL = [
    "study.paths=[{kind='sine'}]",
    "study.controllers=[{name='stanley', type='stanley'}]",
    "study.sim.horizon=1.0",
    "study.sim.steady_window=0.5",
    "study.success.from_s=0.5",
    "study.n_runs=4",
    "designs.enabled=false",
    "car.enabled=false",
    "bench=false",
]


@pytest.mark.slow
def test_quick_study_writes_every_output_and_the_report_carries_the_headline(tmp_path):
    out = tmp_path / "out"
    argv = ["--quick", "--out", str(out)]
    for s in SMALL:
        argv += ["--set", s]
    assert _script().main(argv) == 0
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "report.html", "report.md", "runs.parquet", "summary.json",
    ]  # fmt: skip
    s = json.loads((out / "summary.json").read_text())
    assert s["config_sha256"] == config_hash(s["config"]) and s["throughput"] == {}
    runs = pd.read_parquet(out / "runs.parquet")
    assert set(runs.arm) == {"dynamic", "dynamic_mu3", "kinematic_10deg", "kinematic_0deg"}
    assert len(runs) == 4 * 4
    md, html = (out / "report.md").read_text(), (out / "report.html").read_text()
    x = s["robot"]["controllers"]["stanley"]
    headline = [percent(x["success"]["dynamic"]), percent(x["success"]["kinematic_10deg"])]
    headline.append(f"{100 * x['paired_dynamic_minus_kinematic']['diff']:+.1f} pp")
    headline.append(f"wall {s['wall_s']['total']:.0f} s")
    for text in headline:
        assert text in md and text in html, text
    # the throughput section, from a summary that has one (the full study's keys)
    row = {
        m: {"wall_s": 1.0, "ns_per_rollout_step": ns} for m, ns in (("kinematic", 40.0), ("st", 103.0), ("std", 532.0))
    }
    bench = {"runs": 2, "steps": 200, "controller": "stanley", "path": "sine"}
    for dtype in ("float32", "float64"):
        bench[dtype] = {**row, "ratio_st_over_kinematic": 2.5, "ratio_std_over_kinematic": 13.3}
    doc = report({**s, "throughput": bench})
    for text in (to_markdown(doc), to_html(doc)):
        assert all(v in text for v in ("103", "532", "2.50", "13.30")), text[-2000:]
