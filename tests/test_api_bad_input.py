"""Bad input to the public API (pfjax.api) is an InputError whose one-line message starts with the
argument's name, refused before any work, with the limits the command line and study configs use:
pole regions, PRNG keys, tune's and falsify's arguments, distributions, success rates, output
directories, a tuning check's memory and a finished study's corrupt files."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pfjax
from pfjax import controllers as C
from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.falsification import falsify, random_search
from pfjax.paths import line
from pfjax.sim import SimConfig

ROOT = Path(__file__).resolve().parents[1]
SHORT = SimConfig(dt=0.02, horizon=1.0, record=False)
STUDY = {
    "name": "x",
    "n_runs": 1,
    "seed": 0,
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "a", "type": "pi"}],
}


def _refused(call, key: str) -> str:
    """The message of the InputError ``call()`` raises, checked: one line, starting with ``key``."""
    with pytest.raises(pfjax.InputError) as e:
        call()
    msg = str(e.value)
    assert "\n" not in msg and re.match(rf"{re.escape(key)}\b", msg), msg
    head = msg.partition(": ")[0]
    assert e.value.key == head or " " in head, (e.value.key, msg)  # the key is the whole key the message names
    return msg


@pytest.mark.parametrize(
    "call, key",
    [
        (lambda: pfjax.design_mixed(region="bogus"), "region"),
        (lambda: pfjax.design_mixed(region={"max_real": float("nan")}), "region"),
        (lambda: pfjax.design_mixed(region={"maxreal": -1.0}), "region"),
        (lambda: pfjax.design_mixed(region={"disk_radius": 1.0}), "region"),
    ],
)
def test_design_mixed_region(call, key):
    _refused(call, key)


def test_design_mixed_region_dict_is_a_pole_region():
    from pfjax.synthesis import PoleRegion

    a = pfjax.design_mixed(region={"max_real": -0.5})
    b = pfjax.design_mixed(region=PoleRegion(max_real=-0.5))
    np.testing.assert_allclose(a.K, b.K)


@pytest.mark.parametrize(
    "key",
    [1.5, "a", True, None, np.array([1, 2, 3], np.uint32), np.array([0.0, 1.0])],
    ids=["float", "str", "bool", "none", "3-words", "float-array"],
)
def test_scenarios_key(key):
    msg = _refused(lambda: pfjax.scenarios("line", n=2, key=key), "key")
    assert "Traceback" not in msg


def test_scenarios_key_batch_of_keys_refused_one_key_accepted():
    import jax

    _refused(lambda: pfjax.scenarios("line", n=2, key=jax.random.split(jax.random.key(0), 2)), "key")
    typed = pfjax.scenarios("line", n=2, key=jax.random.key(3)).table
    raw = pfjax.scenarios("line", n=2, key=jax.random.PRNGKey(3)).table
    pd.testing.assert_frame_equal(typed, raw)


@pytest.mark.parametrize(
    "kw, key",
    [
        (dict(key=1.5), "key"),
        (dict(key="a"), "key"),
        (dict(cost="iae"), "cost"),
        (dict(config="x"), "config"),
        (dict(config={"horizont": 3.0}), "config"),
        (dict(multistart="x"), "multistart"),
        (dict(scenario=3), "scenario"),  # not a name or a path: one line, not a TypeError
        (dict(scenario=["x"]), "scenario"),
    ],
)
def test_tune_arguments(kw, key):
    kw = {"scenario": "paper-line", **kw}
    _refused(lambda: pfjax.tune("pi", method="gradient", **kw), key)


@pytest.mark.parametrize(
    "kw", [dict(k_v=5.0), dict(tau_delta_s=0.05), dict(vehicle_params="robot"), dict(mu=1.0), dict(k_v=7.0)]
)
def test_scenarios_refuse_a_single_track_setting_on_the_kinematic_model_at_any_value(kw):
    """As ``pfjax simulate --k-v 5`` is refused without ``--model st``: given is given, default or not."""
    (name,) = kw
    _refused(lambda: pfjax.scenarios("line", n=1, horizon=1.0, **kw), name)


def test_simulate_records_every_gain_given():
    """``Simulation.gains``: the controller's own gains and every one given (two runs that differ
    by their feedforward differ in their recorded gains)."""
    R = pfjax.scenarios("sine", n=2, horizon=2.0, key=0)
    a = pfjax.simulate(R, "state_feedback", config={"horizon": 2.0})
    b = pfjax.simulate(R, "state_feedback", gains={"feedforward": 1.0}, config={"horizon": 2.0})
    assert a.gains == {"k_d": -2.7381, "k_theta": -2.0772} and b.gains == {**a.gains, "feedforward": 1.0}
    assert a.table.iae[0] != b.table.iae[0]


def test_tune_refuses_a_design_as_the_command_line_does(capsys):
    msg = _refused(lambda: pfjax.tune("lmi", "line", "ga"), "controller")
    assert main(["tune", "--controller", "lmi", "--method", "ga"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("pfjax tune: error: --controller: value 'lmi', expected one of "), err
    assert msg.startswith("controller: value 'lmi', expected one of "), msg
    _refused(lambda: pfjax.tune(5), "controller")


def test_tune_check_memory_is_refused_before_any_work(monkeypatch, capsys):
    """A check whose batches exceed the memory budget is refused as tuning is, before the cost is
    built, compiled or run (here a budget of 1 kB refuses the smallest check)."""
    from pfjax.tuning import problem

    def no_work(*a, **kw):
        raise AssertionError("the check's work started")

    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", "1000")
    monkeypatch.setattr(problem, "cost_functions", no_work)
    msg = _refused(lambda: pfjax.tune("stanley", "paper-line", check=[1.0, 1.0]), "check")
    assert "memory budget of 1000 B" in msg, msg
    assert main(["tune", "--controller", "stanley", "--check", "1,1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("pfjax tune: error: --check: ") and "memory budget of 1000 B" in err, err


def test_tune_on_a_study_refuses_runs_beyond_the_budget_before_drawing_them(monkeypatch, capsys):
    """One evaluation's runs (n_runs per path of the study) beyond the memory budget: refused naming
    n_runs (--n-runs) before a single run is drawn, whatever the method."""
    from pfjax.montecarlo import chunk_runs, sampling

    def no_draws(*a, **kw):
        raise AssertionError("runs were drawn")

    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(10**9))
    # both homes of the sampler: chunk_runs binds it at its import (imported above, before the patch,
    # so that a later first import cannot keep the stand-in)
    monkeypatch.setattr(sampling, "sample_runs", no_draws)
    monkeypatch.setattr(chunk_runs, "sample_runs", no_draws)
    heldout = str(ROOT / "studies" / "tuning_heldout.toml")
    msg = _refused(lambda: pfjax.tune("stanley", heldout, check=[1.0, 1.0], n_runs=100_000), "n_runs")
    assert "one evaluation of 100000 runs x 3 paths" in msg, msg
    assert main(["tune", "--controller", "stanley", "--scenario", heldout, "--method", "ga", "--n-runs", "100000"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("pfjax tune: error: --n-runs: one evaluation") and err.endswith("lower --n-runs"), err


@pytest.mark.parametrize(
    "values",
    [["a"], [True], "12", 5, [], [float("nan")]],
    ids=["str-item", "bool-item", "str", "int", "empty", "nan"],
)
def test_choice_values(values):
    msg = _refused(lambda: pfjax.choice(values), "choice")
    assert "values" in msg, msg


def test_choice_takes_a_tuple_or_an_array():
    assert pfjax.choice((1, 2)).values == pfjax.choice(np.array([1.0, 2.0])).values == [1.0, 2.0]


@pytest.mark.parametrize(
    "kw, key",
    [
        (dict(slip_bound_deg=float("nan")), "slip_bound_deg"),
        (dict(slip_bound_deg=95), "slip_bound_deg"),
        (dict(slip_bound_deg=0.0), "slip_bound_deg"),
        (dict(f_max_hz=-1), "f_max_hz"),
        (dict(f_max_hz=11.0), "f_max_hz"),
        (dict(objective="foo"), "objective"),
        (dict(heading_error_deg=95.0), "heading_error_deg"),
        (dict(lateral_offset=-0.1), "lateral_offset"),
        (dict(restarts=0), "restarts"),
        (dict(restarts=1000), "restarts"),
        (dict(steps=20_000), "steps"),
        (dict(key=1.5), "key"),
        (dict(config="x"), "config"),
    ],
)
def test_falsify_arguments(kw, key):
    small = dict(restarts=1, steps=1, config=SHORT)  # a search that is not refused stays short
    _refused(lambda: pfjax.falsify(**(small | kw)), key)


def test_falsify_limits_are_the_study_configs():
    from pfjax.montecarlo.config import load_study

    for setting, value in (("slip_bound_deg", 95), ("f_max_hz", -1), ("n_restarts", 1000)):
        with pytest.raises(pfjax.InputError) as config_error:
            load_study(ROOT / "studies" / "robustness_default.toml", values={f"falsifier.{setting}": value})
        arg = "restarts" if setting == "n_restarts" else setting
        with pytest.raises(pfjax.InputError) as api_error:
            pfjax.falsify(**{arg: value})
        assert str(config_error.value) == f"falsifier.{setting}{str(api_error.value).removeprefix(arg)}"


@pytest.mark.parametrize(
    "kw, key",
    [
        (dict(slip_bound_deg=95.0), "slip_bound_deg"),
        (dict(slip_bound_deg=float("nan")), "slip_bound_deg"),
        (dict(f_max_hz=-1.0), "f_max_hz"),
        (dict(objective="foo"), "objective"),
    ],
)
def test_library_searches_check_their_settings(kw, key):
    import jax

    args = dict(config=SHORT, slip_bound_deg=5.0, f_max_hz=0.5, ic_bounds={}, key=jax.random.PRNGKey(0)) | kw
    sf = C.state_feedback_params()
    _refused(lambda: falsify(C.state_feedback, sf, line(), n_restarts=1, steps=1, **args), key)
    _refused(lambda: random_search(C.state_feedback, sf, line(), n_samples=1, **args), key)


@pytest.mark.parametrize(
    "kw, key",
    [(dict(n_restarts=300), "n_restarts"), (dict(steps=0), "steps"), (dict(n_restarts=1.5), "n_restarts")],
)
def test_library_falsify_checks_its_budget(kw, key):
    import jax

    args = dict(config=SHORT, slip_bound_deg=5.0, f_max_hz=0.5, ic_bounds={}, key=jax.random.PRNGKey(0))
    sf = C.state_feedback_params()
    _refused(lambda: falsify(C.state_feedback, sf, line(), **(dict(n_restarts=1, steps=1) | kw), **args), key)
    _refused(lambda: random_search(C.state_feedback, sf, line(), n_samples=0, **args), "n_samples")
    _refused(lambda: random_search(C.state_feedback, sf, line(), n_samples=1, batch_size=0.5, **args), "batch_size")


@pytest.mark.parametrize(
    "x, index",
    [("abc", 0), ([True, "x", 5], 1), ([0, 1, 1], 0), ([True, float("nan")], 1), ([[True], [True, False]], 0)],
    ids=["str", "mixed", "ints", "nan", "ragged"],
)
def test_success_rate_takes_only_booleans(x, index):
    msg = _refused(lambda: pfjax.success_rate(x), "success")
    assert msg.startswith(f"success[{index}]: expected a boolean"), msg


def test_success_rate_tables_and_object_booleans():
    _refused(lambda: pfjax.success_rate(pd.DataFrame({"ok": [True]})), "success")
    r = pfjax.success_rate(np.array([True, False, True], dtype=object))
    assert (r.k, r.n) == (2, 3)
    assert pfjax.success_rate(pd.DataFrame({"success": [True, False]})).k == 1


@pytest.mark.parametrize("out", [123, b"dir", ""], ids=["int", "bytes", "empty"])
def test_run_and_load_study_out(out, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _refused(lambda: pfjax.run_study(STUDY, out), "out")
    _refused(lambda: pfjax.load_study(out), "out")
    assert list(tmp_path.iterdir()) == []  # nothing written


def _marked(out):
    """``out`` marked as a study's output holding its files as they are now (the marker
    :class:`pfjax.outputs.OutputDir` writes): files that were corrupt when the study wrote them, as
    a disk's damage that keeps their size and time would leave them."""
    from pfjax.outputs import MARKER

    files = {f.name: [f.stat().st_size, f.stat().st_mtime_ns] for f in out.iterdir() if f.name != MARKER}
    (out / MARKER).write_text(json.dumps({"command": "study", "config_sha256": "0" * 64, "files": files, "dirs": []}))
    return out


@pytest.mark.parametrize(
    "summary",
    ["{bad", "[]", json.dumps({"controllers": {"a": {}}}), "\xff"],
    ids=["not-json", "a-list", "no-numbers", "not-utf8"],
)
def test_load_study_corrupt_summary_is_the_report_commands_error(summary, tmp_path, capsys):
    out = tmp_path / "s"
    out.mkdir()
    (out / "summary.json").write_bytes(summary.encode("latin-1"))
    pd.DataFrame({"run": [0]}).to_parquet(out / "runs.parquet")
    msg = _refused(lambda: pfjax.load_study(_marked(out)), "out")
    assert str(out / "summary.json") in msg and "re-run the study" in msg, msg
    if summary != json.dumps({"controllers": {"a": {}}}):  # pfjax report reads the file as load_study does
        from pfjax.montecarlo.study import read_finished

        with pytest.raises(pfjax.InputError) as e:
            read_finished(out)
        assert str(e.value) == "--out" + msg.removeprefix("out")


def test_load_study_corrupt_runs_or_margin(tmp_path):
    out = tmp_path / "s"
    out.mkdir()
    from pfjax.montecarlo.summary import SUMMARY_KEYS

    (out / "runs.parquet").write_text("not parquet")
    (out / "summary.json").write_text(json.dumps({"controllers": {"a": {}}}))  # a summary the study did not write
    assert "summary.json is not a study summary (no study)" in _refused(lambda: pfjax.load_study(_marked(out)), "out")
    (out / "summary.json").write_text(json.dumps({**dict.fromkeys(SUMMARY_KEYS), "controllers": {}}))
    assert "runs.parquet cannot be read" in _refused(lambda: pfjax.load_study(_marked(out)), "out")
    pd.DataFrame({"run": [0]}).to_parquet(out / "runs.parquet")
    (out / "margin.parquet").write_text("not parquet")
    assert "margin.parquet cannot be read" in _refused(lambda: pfjax.load_study(_marked(out)), "out")


def test_a_design_that_cannot_be_made_names_the_controller():
    """As pfjax simulate --controller polytopic-integral --speed 1e6: the synthesis fails, one line."""
    sc = pfjax.scenarios("line", 2, speed=1e6)
    with pytest.raises(InputError, match=r"^controller: polytopic-integral synthesis failed: solver CLARABEL"):
        pfjax.simulate(sc, "polytopic-integral")


@pytest.mark.parametrize(
    "call, key",
    [
        (lambda: pfjax.scenarios("line", 2, horizon=1e12), "horizon"),
        (lambda: pfjax.scenarios("spline", 2), "path"),
        (lambda: pfjax.simulate(pfjax.scenarios("line", 2), "pi", None, {"dt": float("nan")}), "config.dt"),
        (lambda: pfjax.simulate(pfjax.scenarios("line", 2), "pi", None, {"horizon": -1.0}), "config.horizon"),
        (lambda: pfjax.replay(5, "line", "a", 0), "study"),
    ],
)
def test_errors_name_the_argument_the_caller_passed(call, key):
    """Not the study-config key or simulator field behind it (sim.dt, paths[0].points, dt, record)."""
    _refused(call, key)


def test_recording_beyond_the_memory_budget_names_trajectories(monkeypatch):
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(10**6))
    msg = _refused(
        lambda: pfjax.simulate(pfjax.scenarios("line", 8), "pi", None, {"horizon": 20.0}, trajectories=True),
        "trajectories",
    )
    assert "trajectories=False" in msg and "record=" not in msg
    assert "recording 8 runs (padded to 32)" in msg  # the caller's runs, and the batch that is recorded


def test_scenarios_beyond_the_memory_budget_are_refused_before_drawing(monkeypatch):
    from pfjax.resources import SCENARIO_BYTES

    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(1000 * SCENARIO_BYTES))
    msg = _refused(lambda: pfjax.scenarios("line", 1001), "n")
    assert "1001 runs" in msg and "pfjax.run_study" in msg
    assert pfjax.scenarios("line", 1000).n == 1000


def test_replay_of_a_directory_without_a_study_or_of_no_runs_names_its_argument(tmp_path):
    _refused(lambda: pfjax.replay(tmp_path, "line", "a", 0), "study")
    _refused(lambda: pfjax.replay(_spec(), "line", "a", []), "runs")
    _refused(lambda: pfjax.replay(_spec(), "line", "a", [0, [1]]), "runs")  # ragged
    # each index checked as given, the bad one named: True is no run index, 0 is not blamed for 1.5
    msg = _refused(lambda: pfjax.replay(_spec(), "line", "a", [0, True]), "runs")
    assert msg.startswith("runs[1]: ") and msg.endswith("got True"), msg
    msg = _refused(lambda: pfjax.replay(_spec(), "line", "a", [0, 1.5]), "runs")
    assert msg.startswith("runs[1]: ") and msg.endswith("got 1.5"), msg
    _refused(lambda: pfjax.replay(_spec(), "line", "a", True), "runs")


def _spec():
    from pfjax.montecarlo.config import load_study

    return load_study(data=STUDY)[0]


def test_run_study_names_out_in_the_whole_refusal(tmp_path):
    """A user's directory refused as ``pfjax study --out`` refuses it, every mention of the argument
    its Python name (the advice too: "choose another out"), and the directory untouched."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    msg = _refused(lambda: pfjax.run_study(STUDY, mine), "out")
    assert "choose another out" in msg and "--out" not in msg, msg
    assert [p.name for p in mine.iterdir()] == ["notes.txt"] and (mine / "notes.txt").read_text() == "keep"


#: A study that runs in seconds (the refusals below come before any of it runs).
TINY = {
    "name": "tiny",
    "n_runs": 4,
    "seed": 0,
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "a", "type": "pi"}],
    "sim": {"horizon": 2.0, "dt": 0.01, "steady_window": 1.0},
    "success": {"from_s": 1.0},
    "falsifier": {"enabled": False},
    "margin": {"enabled": False},
}


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished tiny study's directory."""
    out = tmp_path_factory.mktemp("finished") / "study"
    pfjax.run_study(TINY, out, report=False, progress=False)
    return out


def _snapshot(folder: Path) -> list:
    """Every entry beside and under ``folder`` with its size and modification time."""
    return sorted(
        (str(p.relative_to(folder.parent)), p.stat().st_size, p.stat().st_mtime_ns) for p in folder.parent.rglob("*")
    )


@pytest.mark.parametrize(
    "kw, key",
    [
        (dict(overwrite="no"), "overwrite"),
        (dict(overwrite=1, n_runs=8), "overwrite"),
        (dict(fresh="no"), "fresh"),
        (dict(progress="x"), "progress"),
        (dict(report=None), "report"),
    ],
    ids=["overwrite-str", "overwrite-int", "fresh-str", "progress-str", "report-none"],
)
def test_run_study_flags_take_only_booleans(finished, kw, key):
    """bool("no") is True: a string would replace a finished study. Refused, nothing touched."""
    before = _snapshot(finished)
    msg = _refused(lambda: pfjax.run_study(TINY, finished, **{"report": False, "progress": False, **kw}), key)
    assert re.search(r"expected True(,| or) False", msg), msg
    assert _snapshot(finished) == before


def test_rare_event_and_tune_progress_take_only_booleans():
    _refused(lambda: pfjax.rare_event(TINY, method="mc", max_rollouts=100, progress="x"), "progress")
    _refused(lambda: pfjax.tune("pi", "paper-line", progress="no"), "progress")
    _refused(lambda: pfjax.tune("pi", "paper-line", progress=None), "progress")


def test_run_study_overwrite_advice_is_the_argument(finished):
    """Another config's output is refused with the caller's words: overwrite=True, not --overwrite."""
    before = _snapshot(finished)
    msg = _refused(lambda: pfjax.run_study(TINY, finished, report=False, progress=False, n_runs=8), "out")
    assert "pass overwrite=True to replace it" in msg and "--overwrite" not in msg, msg
    assert _snapshot(finished) == before


def test_study_configs_take_numpy_and_jax_numbers():
    import jax.numpy as jnp

    from pfjax.montecarlo.config import load_study

    spec = load_study(data={**STUDY, "n_runs": np.int64(3)}, values={"seed": jnp.int32(2), "sim.dt": np.float32(0.5)})[
        0
    ]
    assert (spec.n_runs, spec.seed, spec.sim.dt) == (3, 2, 0.5)
    for bad in (np.bool_(True), jnp.array(True), np.float64(3.0), np.str_("3")):  # still refused as before
        with pytest.raises(pfjax.InputError, match=r"^n_runs: "):
            load_study(data=STUDY, values={"n_runs": bad})


def test_run_study_takes_numpy_integers(finished, tmp_path):
    """In the config and as an override, as pfjax.scenarios takes them: the same study as with ints."""
    a = pfjax.run_study({**TINY, "n_runs": np.int64(4)}, tmp_path / "a", report=False, progress=False)
    b = pfjax.run_study(TINY, tmp_path / "b", report=False, progress=False, n_runs=np.int32(4), seed=np.uint8(0))
    assert a.summary["config"] == b.summary["config"] == pfjax.load_study(finished).summary["config"]
    _refused(lambda: pfjax.run_study(TINY, tmp_path / "c", report=False, n_runs=np.bool_(True)), "n_runs")
    assert not (tmp_path / "c").exists()


def test_choice_takes_a_jax_array():
    import jax.numpy as jnp

    assert pfjax.choice(jnp.array([1.0, 2.0])).values == [1.0, 2.0]
    _refused(lambda: pfjax.choice(jnp.array([True, False])), "choice")
    _refused(lambda: pfjax.choice(np.zeros((2, 2))), "choice")


def test_simulate_and_replay_trajectories_take_only_booleans_and_config_has_no_record():
    """``trajectories="no"`` would record (Python's truth); ``config={"record": True}`` was silently
    replaced by ``trajectories``: one way to ask, refused otherwise, naming the argument."""
    sc = pfjax.scenarios("line", 2)
    _refused(lambda: pfjax.simulate(sc, "pi", trajectories="no"), "trajectories")
    _refused(lambda: pfjax.simulate(sc, "pi", config={"horizon": 1.0, "record": True}), "config.record")
    _refused(lambda: pfjax.replay("/nonexistent", "line", "pi", 0, trajectories=1), "trajectories")


@pytest.mark.parametrize("horizon", [10.0, 4.0, 0.3, 20.0013])
def test_scenarios_take_any_positive_horizon(horizon):
    """The horizon only sizes the slip sequences: the study config behind it keeps its windows
    inside it (a horizon under 15 s was refused naming success.from_s, a key nobody passed)."""
    assert pfjax.scenarios("sine", 2, horizon=horizon).n == 2


def test_nan_is_not_a_finite_number_rather_than_too_small():
    msg = _refused(lambda: pfjax.scenarios("line", 2, horizon=float("nan")), "horizon")
    assert msg == "horizon: expected a finite number, got nan"
    msg = _refused(lambda: pfjax.scenarios("line", 2, model="st", tau_delta_s=float("nan")), "tau_delta_s")
    assert "expected a finite number, got nan" in msg


def test_numpy_booleans_are_flags_and_arrays_are_not_numbers():
    """A NumPy boolean (``np.True_``, ``np.bool_``) is a flag wherever one is taken; an array, even
    of one number, is refused as a number with one line (a value pfjax keeps, e.g. in the
    simulator's static settings, must be a plain number)."""
    import jax.numpy as jnp
    import numpy as np

    from pfjax import errors

    assert errors.boolean("t", np.True_) is True and errors.boolean("t", np.bool_(False)) is False
    assert errors.number("v", np.float32(2.0)) == 2.0
    for bad in (np.array(1.0), jnp.float32(1.0), np.array([1.0]), "1", True):
        _refused(lambda: errors.number("v", bad), "v")
    R = pfjax.scenarios("line", n=2, key=0)
    _refused(lambda: pfjax.simulate(R, "state_feedback", config={"horizon": np.array(1.0)}), "config.horizon")


def test_keyword_overrides_reach_list_items():
    from pfjax.api.studies import dotted

    assert dotted("controllers__0__gains__k_d") == "controllers[0].gains.k_d"
    assert dotted("sim__horizon") == "sim.horizon" and dotted("n_runs") == "n_runs"
    assert dotted("paths__12") == "paths[12]"
    with pytest.raises(pfjax.InputError, match=r"^controllers\[0\]\.gains\.k_d: "):
        pfjax.run_study(STUDY, controllers__0__gains__k_d="x")


def test_messages_name_the_argument_as_the_command_line_does(tmp_path):
    """``run_study`` on a directory says what ``pfjax study`` says; a continuous controller on the
    single-track model names ``config.control_every``; ``scenarios("spline")`` says why it cannot."""
    msg = _refused(lambda: pfjax.run_study(str(tmp_path)), "config")
    assert msg == f"config: {tmp_path} is not a file", msg
    st = pfjax.scenarios("line", 2, model="st")
    _refused(lambda: pfjax.simulate(st, "state_feedback", config={"control_every": None}), "config.control_every")
    assert "waypoints" in _refused(lambda: pfjax.scenarios("spline"), "path")


@pytest.mark.parametrize(
    "call, key",
    [
        (lambda: pfjax.simulate(pfjax.scenarios("line", 2), "state_feedback", gains={"foo": 1}), "gains.foo"),
        (lambda: pfjax.simulate(pfjax.scenarios("line", 2), "stanley", config={"foo": 1}), "config.foo"),
        (lambda: pfjax.design_mixed(region={"sector_angle": 2.0}), "region.sector_angle"),
        (lambda: pfjax.tune("stanley", "line", check={"k": 1, "foo": 2}), "check.foo"),
    ],
)
def test_a_nested_key_is_the_errors_key_as_the_message_names_it(call, key):
    with pytest.raises(pfjax.InputError) as e:
        call()
    assert e.value.key == key and str(e.value).startswith(f"{key}: ")


@pytest.mark.parametrize(
    "kwargs, argv, key, flags",
    [
        ({"v": 1e6}, ["--speed", "1e6"], "v/L", "--speed/--wheelbase"),
        ({"region": {"max_real": -1e6}}, ["--max-real", "-1e6"], "region", "--max-real/--disk/--sector-deg"),
    ],
)
def test_no_design_is_bad_input_named_alike_by_the_api_and_pfjax_synth(kwargs, argv, key, flags, capsys):
    from pfjax.errors import SynthesisError

    with pytest.raises(InputError) as e:
        pfjax.design_mixed(**kwargs)
    # an InputError naming what the caller can change, and a SynthesisError with the solver's status
    assert e.value.key == key and isinstance(e.value, SynthesisError) and e.value.status == "infeasible"
    assert main(["synth", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"pfjax synth: error: {flags}: {str(e.value).removeprefix(key + ': ')}"


@pytest.mark.parametrize(
    "call, key, hint",
    [
        (lambda: pfjax.run_study(STUDY, "unused", overwite=True), "overwite", "overwrite"),
        (lambda: pfjax.rare_event(STUDY, max_rollout=100), "max_rollout", "max_rollouts"),
        (lambda: pfjax.rare_event(STUDY, controler="a"), "controler", "controller"),
        (lambda: pfjax.tracking.run(horizn=1.0), "horizn", "horizon"),
        (lambda: pfjax.parking.run(t_mx=1.0), "t_mx", "t_max"),
        (lambda: pfjax.parking.search(metod="ga"), "metod", "method"),
    ],
)
def test_a_misspelt_keyword_is_named_with_the_argument_meant(call, key, hint, tmp_path, monkeypatch):
    """A keyword a function does not take, also where the function reads config overrides as
    keywords (``run_study``, ``rare_event``), is an ArgumentError naming it and the closest
    argument; nothing is run or written."""
    from pfjax.errors import ArgumentError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(ArgumentError) as e:
        call()
    assert e.value.key == key and str(e.value).endswith(f"(did you mean {hint!r}?)") and list(tmp_path.iterdir()) == []


def test_a_missing_argument_is_named():
    with pytest.raises(InputError) as e:
        pfjax.simulate()
    assert e.value.key == "scenarios" and str(e.value) == "scenarios: pfjax.simulate needs this argument"


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda out: (out / "summary.json").write_text((out / "summary.json").read_text() + " "), "changed after"),
        (lambda out: pd.read_parquet(out / "runs.parquet").head(2).to_parquet(out / "runs.parquet"), "changed after"),
        (lambda out: (out / "runs.parquet").unlink(), "is missing (the study wrote it)"),
        (
            lambda out: (out / ".pfjax-output.json").unlink(),
            "no finished study in",
        ),
        (
            lambda out: (out / ".pfjax-output.json").write_text(
                (out / ".pfjax-output.json").read_text().replace('"command": "study"', '"command": "tune"')
            ),
            "(the output of pfjax tune)",
        ),
        (lambda out: shutil.copy(out / "runs.parquet", out / "margin.parquet"), "margin.parquet was not written by"),
    ],
    ids=["summary-edited", "runs-cut", "runs-deleted", "no-marker", "another-command", "margin-added"],
)
def test_load_study_reads_only_the_studys_own_files(finished, tmp_path, edit, message):
    """As pfjax report: tables edited, cut or mixed in after the study wrote them are refused, not
    returned as the study's."""
    import shutil

    out = tmp_path / "s"
    shutil.copytree(finished, out)  # sizes and times kept: the copy is the study's own
    assert pfjax.load_study(out).summary == pfjax.load_study(finished).summary
    edit(out)
    msg = _refused(lambda: pfjax.load_study(out), "out")
    assert message in msg and "--out" not in msg, msg


def test_a_study_copied_with_new_times_is_still_the_studys_own(finished, tmp_path):
    """cp -r, an archive extracted: new modification times, the same contents (the marker's
    SHA-256). load_study, replay and pfjax report read it; a re-run into it needs no overwrite."""
    import shutil

    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.study import rewrite_report

    out = tmp_path / "copy"
    shutil.copytree(finished, out, copy_function=shutil.copy)  # contents only: times are new
    marker = json.loads((out / ".pfjax-output.json").read_text())
    assert any(marker["files"][f.name][1] != f.stat().st_mtime_ns for f in out.iterdir() if f.name in marker["files"])
    assert pfjax.load_study(out).summary == pfjax.load_study(finished).summary
    row = pfjax.load_study(out).runs.iloc[0]
    assert pfjax.replay(out, row.path, row.controller, [int(row.run)]).table.iae[0] == row.iae
    rewrite_report(out, load_study(data=TINY)[0])  # no overwrite needed: the study's own output
    assert (out / "report.html").is_file()


def test_report_on_an_edited_summary_says_to_re_run_the_study_first(finished, tmp_path):
    """The real way out, not --overwrite (which is then refused for the same file)."""
    import shutil

    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.study import rewrite_report

    out = tmp_path / "s"
    shutil.copytree(finished, out)
    (out / "summary.json").write_text((out / "summary.json").read_text() + " ")
    spec = load_study(data=TINY)[0]
    for overwrite in (False, True):
        with pytest.raises(pfjax.InputError) as e:
            rewrite_report(out, spec, overwrite=overwrite)
        assert "summary.json changed after the study wrote it" in str(e.value) and "re-run the study" in str(e.value)


def test_run_study_memory_refusal_comes_first_in_the_apis_words(tmp_path):
    """As pfjax study: the budget before the output directory; the advice names report=False."""
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    msg = _refused(lambda: pfjax.run_study(TINY, mine, n_runs=100_000_000), "n_runs")
    assert "report=False" in msg and "--no-report" not in msg, msg
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]


def test_a_config_nested_too_deeply_is_one_line_naming_it(tmp_path):
    import functools

    deep = functools.reduce(lambda a, _: [a], range(5000), [])
    assert _refused(lambda: pfjax.run_study(TINY, tmp_path / "x", paths=deep), "paths").endswith("nested too deeply")
    assert _refused(lambda: pfjax.run_study({**TINY, "paths": deep}, tmp_path / "x"), "config").endswith(
        "nested too deeply"
    )
    assert list(tmp_path.iterdir()) == []


def test_run_study_takes_any_path_like_config(tmp_path):
    from pathlib import PurePosixPath

    from pfjax.api.studies import _study_spec

    toml = tmp_path / "s.toml"
    toml.write_text(
        'name = "s"\nn_runs = 3\nseed = 0\n[[paths]]\nkind = "line"\n[[controllers]]\nname = "a"\ntype = "pi"\n'
    )
    assert _study_spec(PurePosixPath(toml), {}).n_runs == 3


def test_run_study_warns_as_pfjax_study_prints(tmp_path):
    """A path sharper than the steering limit follows: a RuntimeWarning (pfjax study: stderr), the
    study runs, and summary.json records it."""
    with pytest.warns(RuntimeWarning, match=r"paths\[0\]") as w:
        res = pfjax.run_study(
            TINY, tmp_path / "w", paths=[{"kind": "circle", "radius": 0.3}], n_runs=2, report=False, progress=False
        )
    assert {x.filename for x in w if issubclass(x.category, RuntimeWarning)} == {__file__}  # the caller's line
    assert res.summary["warnings"] and "paths[0]" in res.summary["warnings"][0]
    assert "slip_margin_fails_at_deg" in res.headline.columns


def test_a_design_the_solver_cannot_make_names_the_weights_given():
    """alpha = 1e12 leaves the solver without a design where the source's weights find one: the
    refusal names the weights with the operating point, in the API and the command line alike."""
    with pytest.raises(pfjax.InputError) as e:
        pfjax.design_mixed(alpha=1e12)
    assert str(e.value).startswith(
        "v/L/alpha: the solver found no mixed design at speed 1 m/s, wheelbase 0.2 m, alpha 1e+12"
    )
    code = main(["synth", "--alpha", "1e12"])
    assert code == 2


def test_scenarios_leave_the_single_track_step_to_simulate():
    """pfjax.scenarios takes any positive steering time constant (its horizon only sizes slip
    sequences, and it does not step the runs): it does not refuse one naming ``sim.dt``, a key no
    caller passed. pfjax.simulate checks the step the runs take: its default, the stable step of
    the runs' worst case, bounds the horizon (named ``config.horizon``), a ``dt`` given is checked
    against the tyre modes and actuators (``config.dt``), and a horizon short enough runs."""
    sc = pfjax.scenarios("sine", 1, model="st", tau_delta_s=1e-6)
    assert sc.n == 1 and sc.spec.vehicle.tau_delta_s == 1e-6
    msg = _refused(lambda: pfjax.simulate(sc, "pi"), "config.horizon")
    assert msg.startswith("config.horizon: must be at most 4 s (2e+06 steps of 2e-06 s, the stable step of the runs'")
    assert msg.endswith("got 20 s"), msg
    msg = _refused(lambda: pfjax.simulate(sc, "pi", config={"dt": 1e-5}), "config.dt")
    assert "needs dt <= 2.5e-06 s for a stable RK4 step, got 1e-05" in msg
    r = pfjax.simulate(sc, "pi", config={"horizon": 0.02})
    assert list(r.table["status"]) == ["ok"]


@pytest.mark.parametrize("out", ["", "."])
def test_run_study_judges_out_in_the_words_of_pfjax_study(out, tmp_path, monkeypatch, capsys):
    """An output directory the command refuses is refused by the API with the same message, the
    flag named as the argument (``--out`` as ``out``)."""
    import pfjax
    from pfjax.cli import main

    monkeypatch.chdir(tmp_path)
    config = Path(__file__).resolve().parents[1] / "studies" / "robustness_default.toml"
    with pytest.raises(pfjax.InputError) as e:
        pfjax.run_study(str(config), out)
    assert main(["study", str(config), "--out", out]) == 2
    cli = capsys.readouterr().err.strip().removeprefix("pfjax study: error: ")
    assert cli == "--" + str(e.value) and e.value.key == "out"
    assert list(tmp_path.iterdir()) == []
