"""``studies/kinematic_vs_dynamic.py``: its config schema (:mod:`pfjax.dynamic_study.config`) refuses a
bad key or value with one line naming it (exit 2, nothing written); ``--quick`` (shrunk further by
``--set``) writes every output; the report's Markdown and HTML carry the summary's headline numbers."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

import pfjax
from pfjax.config import ConfigError
from pfjax.dynamic_study import runs as study_runs
from pfjax.dynamic_study.arms import ROBOT_WHEELBASE, car_study, check
from pfjax.dynamic_study.config import load
from pfjax.dynamic_study.report import percent, report
from pfjax.dynamic_study.summary import bins, compare, slip_summary
from pfjax.models import single_track as st
from pfjax.provenance import config_hash
from pfjax.report.document import to_html, to_markdown
from pfjax.tables import units

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
        # the arms' own study configs, checked before the runs: the car's step, the robot's step in the ST arm
        ("car.dt=0.1", "car.dt"),
        ("study.sim.dt=0.05", "study.sim.dt"),
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


def test_every_arm_is_checked_before_the_runs_naming_the_study_key():
    with pytest.raises(ConfigError, match=r"^car\.dt: .*dt <= .*\(arm car_dynamic\)$"):
        check(load(quick=True, overrides=["car.dt=0.1"]))
    with pytest.raises(ConfigError, match=r"^study\.sim\.dt: .*\(arm dynamic\)$"):
        check(load(quick=True, overrides=["study.sim.dt=0.05"]))
    with pytest.raises(ConfigError, match=r"^study\.paths\[0\]\.kind: the car arms scale fixed paths"):
        check(load(quick=True, overrides=["study.paths=[{kind='circle'}]"]))
    # a choice of speeds: the LMI design is made at their mean (pfjax.montecarlo.dists.nominal)
    check(load(quick=True, overrides=["study.vehicle.speed={dist='choice', values=[0.8, 1.2]}"]))
    check(load(quick=True, overrides=["study.paths=[{kind='circle'}]", "car.enabled=false"]))


def test_car_scaling_scales_every_distribution_kind():
    p = st.parameter_set("vehicle2")
    s = float(p.l_f + p.l_r) / ROBOT_WHEELBASE
    rs = math.sqrt(s)
    config = load(
        quick=True,
        overrides=[
            "study.initial.lateral_offset={dist='normal', mean=0.1, std=0.2}",
            "study.initial.start_along_m={dist='choice', values=[0.0, 1.0]}",
            "study.vehicle.speed={dist='truncnormal', mean=1.0, std=0.2, low=0.7, high=1.3}",
        ],
    )
    car = car_study(config)
    ini, speed = car["initial"], car["vehicle"]["speed"]
    assert ini["lateral_offset"] == pytest.approx({"dist": "normal", "mean": 0.1 * s, "std": 0.2 * s})
    assert ini["start_along_m"]["values"] == pytest.approx([0.0, s])
    want = {"dist": "truncnormal", "mean": rs, "std": 0.2 * rs, "low": 0.7 * rs, "high": 1.3 * rs}
    assert speed == pytest.approx(want)
    stanley = "study.controllers=[{name='stanley', type='stanley'}]"
    choice = load(quick=True, overrides=["study.vehicle.speed={dist='choice', values=[0.8, 1.2]}", stanley])
    assert car_study(choice)["vehicle"]["speed"]["values"] == pytest.approx([0.8 * rs, 1.2 * rs])
    assert car_study(load(quick=True, overrides=["study.vehicle.speed=1.0"]))["vehicle"]["speed"] == pytest.approx(rs)


def test_designs_take_the_speed_range_of_any_distribution():
    from pfjax.dynamic_study.designs import designs

    config = load(
        quick=True,
        overrides=[
            "study.vehicle.speed={dist='choice', values=[0.8, 1.4]}",
            "study.controllers=[{name='stanley', type='stanley'}]",
        ],
    )
    controllers, record = designs(config)
    assert record["operating_point"]["v"] == pytest.approx(1.1) and len(controllers) == 6


def test_bins_put_every_run_in_one_bin():
    # interior edges (1 and 2 of [0, 3] in 3 bins) fall in the bin above, the top edge in the last
    values = pd.Series([0.0, 0.5, 1.0, 1.0, 2.0, 2.5, 3.0, np.nan])
    got = [(lo, hi, int(mask.sum())) for lo, hi, mask in bins(values, 3)]
    assert got == [(0.0, 1.0, 2), (1.0, 2.0, 2), (2.0, 3.0, 3)]
    # a constant: one bin; empty bins left out
    assert [(lo, hi, int(m.sum())) for lo, hi, m in bins(pd.Series([1.0] * 36), 3)] == [(1.0, 1.0, 36)]
    assert [int(m.sum()) for _, _, m in bins(pd.Series([0.0, 0.1, 3.0]), 3)] == [2, 1]


def _runs(arm: str, n: int = 12, speed=None) -> pd.DataFrame:
    """A hand-made run table of one arm (the columns the summary reads)."""
    rng = np.random.default_rng(0)
    mu = np.linspace(0.3, 1.0, n)
    df = pd.DataFrame(
        {
            "path": "sine",
            "controller": "stanley",
            "run": np.arange(n),
            "speed": np.full(n, 1.0) if speed is None else speed,
            "beta_r_deg": 0.0,
            "beta_f_deg": 0.0,
            "success": np.arange(n) % 3 > 0,
            "status": "ok",
            "late_max_abs_d": rng.uniform(0.0, 0.1, n),
            **{c: rng.uniform(0.0, 10.0, n) for c in ("max_abs_beta_r_deg", "max_abs_beta_f_deg")},
            **{c: rng.uniform(0.0, 2.0, n) for c in ("mean_abs_beta_r_deg", "mean_abs_beta_f_deg")},
        }
    )
    if arm.startswith(("dynamic", "car_dynamic")):
        df["mu"] = 3.0 if arm == "dynamic_mu3" else mu
    return df.assign(arm=arm)


def test_slip_and_success_tables_count_each_run_once():
    dyn = _runs("dynamic", 36)  # a constant speed, the friction on [0.3, 1] with runs on the bin edges
    s = slip_summary(dyn, 10.0)
    assert [(b["speed"], b["n"]) for b in s["by_speed"]] == [([1.0, 1.0], 36)]
    assert sum(b["n"] for b in s["by_mu"]) == 36
    table = pd.concat([dyn, _runs("kinematic_10deg", 36), _runs("kinematic_0deg", 36)], ignore_index=True)
    c = compare(table, "dynamic", "kinematic_10deg", "kinematic_")["controllers"]["stanley"]
    assert sum(b["n"] for b in c["success_by_mu_dynamic"]) == 36
    assert sum(b["k"] for b in c["success_by_mu_dynamic"]) == int(dyn.success.sum())


@pytest.fixture
def hand_made_study(tmp_path, monkeypatch):
    """The study's outputs (``out``) and config, each arm's runs a hand-made table in place of a simulation."""
    config = load(quick=True, overrides=[*SMALL[:-1], "bench=false"])

    def fake_run_study(spec, out, **kw):  # each arm's runs, as pfjax.run_study returns them
        arm = next(a for a, s in study_runs.arms(config).items() if s == spec)
        return SimpleNamespace(runs=_runs(arm, 4).drop(columns="arm"))

    monkeypatch.setattr(pfjax, "run_study", fake_run_study)
    study_runs.run(config, tmp_path / "out")
    return tmp_path / "out", config


def test_dynamic_runs_declare_no_slip():
    """On st and std the tyres make the slip: the sampler declares none (NaN ``beta_r_deg`` and
    ``beta_f_deg``), as the kinematic runs have no friction (NaN ``mu``), so a filter on the declared
    slip never mixes the dynamic arms with the kinematic no-slip arm."""
    dyn = pfjax.scenarios("line", 4, model="st").table
    kin = pfjax.scenarios("line", 4, beta_r_deg=0.0, beta_f_deg=0.0).table
    assert dyn[["beta_r_deg", "beta_f_deg"]].isna().all().all() and dyn["mu"].notna().all()
    assert (kin[["beta_r_deg", "beta_f_deg"]] == 0.0).all().all()


def test_outputs_carry_units_and_provenance(hand_made_study):
    out, config = hand_made_study
    u = units(out / "runs.parquet")
    assert u["speed"]["unit"] == "m/s" and u["beta_r_deg"]["unit"] == "deg" and "arm" in u
    meta = pq.read_schema(out / "runs.parquet").metadata
    digest = config_hash(config.model_dump(mode="json"))
    assert meta[b"pfjax.config_sha256"].decode() == digest
    assert meta[b"pfjax.seed"] == b"2026" and meta[b"pfjax.version"].decode() == pfjax.__version__
    s = json.loads((out / "summary.json").read_text())
    assert (s["config_sha256"], s["seed"], s["pfjax_version"]) == (digest, 2026, pfjax.__version__)
    assert s["units"]["late_max_abs_d_q95"] == "m" and s["units"]["speed"].startswith("m/s")
