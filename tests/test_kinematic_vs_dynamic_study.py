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
from pfjax.dynamic_study.designs import designs
from pfjax.dynamic_study.report import design_tables, percent, report, slip_tables
from pfjax.dynamic_study.summary import SLIP_COLS, UNITS, bins, compare, slip_summary
from pfjax.jsonio import dumps
from pfjax.models import single_track as st
from pfjax.provenance import config_hash
from pfjax.report.document import Document, Table, to_html, to_markdown
from pfjax.tables import units

STUDY = Path(__file__).resolve().parents[1] / "studies" / "kinematic_vs_dynamic.py"


def _script():
    spec = importlib.util.spec_from_file_location("kinematic_vs_dynamic_for_test", STUDY)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_cars_runs_are_bounded_by_the_one_chunk_they_take(tmp_path, capsys):
    """car.n_runs is refused by its own bound, before any arm's study config is built from it."""
    out = tmp_path / "out"
    assert _script().main(["--quick", "--out", str(out), "--set", "car.n_runs=100000000"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("error: car.n_runs: must be <= 10000000 (got 100000000)"), err
    assert not list(tmp_path.iterdir())


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
        # the keys each arm sets itself, named as the user set them
        ("study.slip.beta_r_deg=3.0", "study.slip.beta_r_deg"),
        ("study.vehicle.model='st'", "study.vehicle.model"),
        ("study.vehicle.mu=0.5", "study.vehicle.mu"),
    ],
)
def test_bad_config_one_line_exit_2_nothing_written(tmp_path, capsys, setting, key):
    out = tmp_path / "out"
    assert _script().main(["--quick", "--out", str(out), "--set", setting]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"error: {key}:" in err, err
    assert not list(tmp_path.iterdir())


def test_arm_keys_are_refused_naming_the_key_set():
    """study.slip, study.vehicle.model and study.vehicle.mu are the arms' own: refused at load, named
    as set; an arm's error maps to the study key behind it (the kinematic arms' slip to
    slip_ranges_deg, the dynamic arms' friction to mu_high or mu_grip, anything else to study.*)."""
    from pfjax.dynamic_study.arms import _config_key

    for setting, message in (
        ("study.slip.beta_r_deg=3.0", r"^study\.slip\.beta_r_deg: the arms set the slip .*; remove it$"),
        ("study.vehicle.model='st'", r"^study\.vehicle\.model: the arms set the model .*; remove it$"),
        ("study.vehicle.mu=0.5", r"^study\.vehicle\.mu: the arms set the friction .*; remove it$"),
        ("study.vehicle.params='vehicle1'", r"^study\.vehicle\.params: the arms set the parameter set .*; remove it$"),
    ):
        with pytest.raises(ConfigError, match=message):
            load(quick=True, overrides=[setting])
    assert _config_key("dynamic", "slip.beta_r_deg", "dynamic_mu3") == "study.slip.beta_r_deg"
    assert _config_key("kinematic_10deg", "slip.beta_r_deg", "dynamic_mu3") == "slip_ranges_deg"
    assert _config_key("designs_kinematic_10deg", "vehicle.mu", "dynamic_mu3") == "study.vehicle.mu"
    assert _config_key("dynamic_mu3", "vehicle.mu", "dynamic_mu3") == "mu_grip"
    assert _config_key("car_dynamic", "vehicle.mu", "dynamic_mu3") == "mu_high"


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
    marker = json.loads((out / ".pfjax-output.json").read_text())
    assert marker["config_sha256"] == s["config_sha256"] and marker["seed"] == s["seed"]
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
    config = load(
        quick=True,
        overrides=[
            "study.vehicle.speed={dist='choice', values=[0.8, 1.4]}",
            "study.controllers=[{name='stanley', type='stanley'}]",
        ],
    )
    controllers, record = designs(config)
    assert record["operating_point"]["v"] == pytest.approx(1.1) and len(controllers) == 6


def test_each_dynamic_design_starts_from_its_own_kinematic_gain():
    """The polytopic redesign starts from the polytopic kinematic gain: its record's K0 is that gain
    and criterion0 the criterion there over the corner plants; a start that does not stabilise
    every plant gives no controller, and the record and the report say so."""
    from pfjax.dynamic_study.designs import _plants
    from pfjax.synthesis.dynamic_plant import _norms

    config = load(quick=True)
    controllers, record = designs(config)
    g = record["gains"]
    for name in ("mixed", "integral", "polytopic"):
        assert np.ravel(g[f"{name}-dyn"]["K0"]).tolist() == g[f"{name}-kin"]["K"], name
    corners = _plants(st.robot_params(), 0.05, [config.mu_low, config.mu_high], [0.7, 1.3])
    hn, h2, pole = _norms(corners, np.asarray(g["polytopic-kin"]["K"]))
    assert pole < 0
    want = config.designs.alpha * hn**2 + config.designs.beta * h2**2
    assert g["polytopic-dyn"]["criterion0"] == pytest.approx(want, rel=1e-12)
    assert g["polytopic-dyn"]["criterion"] < g["polytopic-dyn"]["criterion0"]
    # speeds 0.2-3 m/s: the polytopic kinematic gain does not stabilise every corner plant
    wide = load(quick=True, overrides=["study.vehicle.speed={dist='uniform', low=0.2, high=3.0}"])
    controllers, record = designs(wide)
    failed = record["gains"]["polytopic-dyn"]
    assert "polytopic-dyn" not in [c["name"] for c in controllers] and len(controllers) == 5
    assert "K" not in failed and failed["criterion0"] == math.inf
    assert failed["failed"].endswith("does not stabilise every plant")
    table = next(b for b in design_tables(record) if isinstance(b, Table))
    row = next(r for r in table.rows if r[0] == "polytopic-dyn")
    assert row[1] == "none" and row[2].startswith("no design: K0: ")


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


def test_slip_and_late_statistics_are_over_the_runs_that_ran_the_whole_horizon():
    """Failed runs are counted (``n_failed``; success over every run) and left out of the slip and
    late max |d| statistics: a run failed at t = 0 has NaN slip, one failed before the success
    window a NaN late max |d|, and one failed later a number that is not a settled error."""
    dyn = _runs("dynamic", 12)
    failed = np.arange(12) % 4 == 0  # runs 0, 4, 8
    dyn.loc[failed, "status"] = "diverged"
    dyn.loc[failed, "success"] = False
    dyn.loc[[0, 4], [*SLIP_COLS, "late_max_abs_d"]] = np.nan  # failed at t = 0
    dyn.loc[8, "late_max_abs_d"] = 0.5  # failed inside the success window
    dyn.loc[8, SLIP_COLS] = 40.0
    ok = dyn[~failed]
    s = slip_summary(dyn, 10.0)
    assert (s["n"], s["n_failed"]) == (9, 3)
    for part in ("by_mu", "by_speed"):  # bins over every run's range, statistics over the ok runs
        assert [sum(b[k] for b in s[part]) for k in ("n", "n_failed")] == [9, 3], part
    assert s["by_mu"][0]["mu"][0] == 0.3 and s["by_mu"][0]["n_failed"] == 1  # run 0 (mu 0.3) failed
    assert [(b["n"], b["n_failed"]) for b in s["by_path"]] == [(9, 3)]
    for c in SLIP_COLS:
        assert s["all"][c] == pytest.approx({"q50": ok[c].median(), "q95": ok[c].quantile(0.95), "max": ok[c].max()})
    assert s["fraction_max_beyond_declared"]["max_abs_beta_f_deg"] == pytest.approx(np.mean(ok.max_abs_beta_f_deg > 10))
    table = pd.concat([dyn, _runs("kinematic_10deg", 12), _runs("kinematic_0deg", 12)], ignore_index=True)
    c = compare(table, "dynamic", "kinematic_10deg", "kinematic_")["controllers"]["stanley"]
    assert c["success"]["dynamic"]["n"] == 12 and c["n_ok"] == {
        "dynamic": 9,
        "kinematic_10deg": 12,
        "kinematic_0deg": 12,
    }
    assert c["worst_late_max_abs_d"]["dynamic"] == ok.late_max_abs_d.max() < 0.5
    assert c["late_max_abs_d_q95"]["dynamic"] == pytest.approx(ok.late_max_abs_d.quantile(0.95))
    # an arm without a run that ran the whole horizon: no statistics, shown as a dash
    none_ok = dyn.assign(status="diverged")
    assert math.isnan(slip_summary(none_ok, 10.0)["all"]["max_abs_beta_r_deg"]["q50"])
    text = to_markdown(Document("t", "", slip_tables(json.loads(dumps(slip_summary(none_ok, 10.0))))))
    assert "| - / - / - |" in text and "rear - %" in text


@pytest.fixture
def hand_made_study(tmp_path, monkeypatch):
    """The study's outputs (``out``) and config, each arm's runs a hand-made table in place of a
    simulation, the designs made once, the throughput a made-up record of the real one's keys."""
    config = load(quick=True, overrides=[s for s in SMALL if s not in ("designs.enabled=false", "bench=false")])
    made = designs(config)

    def fake_run_study(spec, out, **kw):  # each arm's runs, as pfjax.run_study returns them
        arm = next(a for a, s in study_runs.arms(config, made[0]).items() if s == spec)
        return SimpleNamespace(runs=_runs(arm, 4).drop(columns="arm"))

    costs = {m: {"wall_s": 1.0, "ns_per_rollout_step": 100.0} for m in ("kinematic", "st", "std")}
    bench = {"runs": 2, "steps": 200, "controller": "stanley", "path": "sine"}
    for dtype in ("float32", "float64"):
        bench[dtype] = {**costs, "ratio_st_over_kinematic": 1.0, "ratio_std_over_kinematic": 1.0}
    monkeypatch.setattr(pfjax, "run_study", fake_run_study)
    monkeypatch.setattr(study_runs, "designs", lambda c: made)
    monkeypatch.setattr(study_runs, "throughput", lambda c: bench)
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
    assert s["units"]["late_max_abs_d_q95"].startswith("m ") and s["units"]["speed"].startswith("m/s")
    assert s["units"] == UNITS and s["designs"]["gains"] and s["throughput"]
    # every number of summary.json (the config's aside: its schema describes them) has its unit:
    # the unit of its own key or of a key above it
    numbers = []

    def walk(o, keys):
        if isinstance(o, dict):
            for k, v in o.items():
                walk(v, (*keys, k))
        elif isinstance(o, list):
            for v in o:
                walk(v, keys)
        elif isinstance(o, (int, float)) and not isinstance(o, bool):
            numbers.append(keys)

    walk({k: v for k, v in s.items() if k not in ("config", "units")}, ())
    assert len(numbers) > 100
    missing = sorted({keys[-1] for keys in numbers if not any(k in UNITS for k in keys)})
    assert not missing, missing
    for key in ("criterion", "criterion0", "hinf_norm", "h2_norm", "evaluations"):
        assert key in s["designs"]["gains"]["mixed-dyn"] and UNITS[key], key
