"""The vehicle-tracking study's config refuses what ``pfjax track`` refuses (one check, shared), and
sizes that would not fit in memory, at load, with one line naming the study key; nothing is
simulated or written."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from pfjax.config import ConfigError
from pfjax.errors import InputError
from pfjax.tracking import api, study, study_config

STUDY = Path(__file__).resolve().parents[1] / "studies" / "vehicle_tracking.py"


@pytest.mark.parametrize(
    "settings, key",
    [
        # dt > horizon: no step at all; the horizon is named, since the quick preset changed it (15 s)
        (["sim.dt=100.0"], "sim.horizon"),
        (["sim.window=100.0"], "sim.window"),  # the final window longer than the run
        (["sim.dt=0.3", "sim.horizon=10.0"], "sim.horizon"),  # not a whole number of steps
        (["sim.horizon=1e9"], "sim.horizon/dt"),  # more steps than a run may take
        (["mc.p_forward=0.0"], "mc.p_forward"),
        (["mc.p_backward=0"], "mc.p_backward"),
        (["mc.speed_low=-2.0"], "mc.speed_low"),
        (["mc.speed_low=0.0"], "mc.speed_low"),
        (["mc.slip_max_deg=95.0"], "mc.slip_max_deg"),
        (["lemma.l_abs=[-1.0]"], "lemma.l_abs[0]"),
        (["lemma.l_abs=[1.0, 0.0]"], "lemma.l_abs[1]"),
        (["lemma.p=[1.0, 0.0]"], "lemma.p"),
    ],
)
def test_study_config_refuses_what_track_refuses(settings, key):
    with pytest.raises(ConfigError) as e:
        study_config.load(overrides=settings, quick=True)
    msg = str(e.value)
    assert msg.startswith(f"{key}: ") and "\n" not in msg, msg


def test_the_study_and_the_api_share_one_check():
    """The same value gives the same message; only the key carries the study's section."""
    cases = [
        ({"horizon": 3.0, "dt": 5.0}, ["sim.horizon=3.0", "sim.dt=5.0", "sim.window=1.0"], "sim."),
        ({"horizon": 10.0, "dt": 0.3}, ["sim.horizon=10.0", "sim.dt=0.3", "sim.window=1.0"], "sim."),
        ({"p": 0.0}, ["mc.p_forward=0.0"], "mc."),
    ]
    for kw, settings, section in cases:
        with pytest.raises(InputError) as a:
            api.run(**{"horizon": 3.0, "dt": 0.05, **kw})
        with pytest.raises(ConfigError) as s:
            study_config.load(overrides=settings, quick=True)
        api_key, api_msg = str(a.value).split(": ", 1)
        study_key, study_msg = str(s.value).split(": ", 1)
        assert study_msg == api_msg and study_key.startswith(section), (str(a.value), str(s.value))


def test_accepted_edges_load():
    c = study_config.load(overrides=["sim.horizon=10.0", "sim.dt=0.25", "sim.window=10.0", "mc.p_forward=-0.5"])
    assert (c.sim.dt, c.sim.window, c.mc.p_forward) == (0.25, 10.0, -0.5)


@pytest.mark.parametrize(
    "setting, key",
    [
        ("lemma.n_geometry=1000000000", "lemma.n_geometry"),
        ("mc.n_runs=100000000", "mc.n_runs"),
        ("lemma.offsets=" + str([[0.0, 0.001 * i] for i in range(20000)]), "lemma.offsets"),
    ],
)
def test_sizes_beyond_the_memory_budget_are_refused_at_load(monkeypatch, setting, key):
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(1 << 30))
    with pytest.raises(ConfigError) as e:
        study_config.load(overrides=[setting], quick=True)
    assert str(e.value).startswith(f"{key}: ") and "memory budget" in str(e.value), str(e.value)


def test_the_published_sizes_fit_a_small_budget(monkeypatch):
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(1 << 30))
    config = study_config.load()
    assert study_config.sizes(config) == {"lemma_runs": 1944, "geometry_states": 432_000, "mc_runs": 4000}


@pytest.mark.parametrize("setting", ["lemma.n_geometry=1000000000", "sim.horizon=1e9", "mc.p_forward=0.0"])
def test_the_script_exits_2_before_any_work(tmp_path, capsys, monkeypatch, setting):
    monkeypatch.setenv("PFJAX_MEMORY_BUDGET", str(1 << 30))
    monkeypatch.setattr(study, "run", lambda *a, **k: pytest.fail("ran despite a bad config"))
    spec = importlib.util.spec_from_file_location("vehicle_tracking_for_audit", STUDY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = tmp_path / "out"
    assert mod.main(["--quick", "--out", str(out), "--set", setting]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and setting.split("=")[0] in err, err
    assert not list(tmp_path.iterdir())


def test_the_study_columns_take_the_command_lines_units():
    """The study's columns and ``pfjax track --json`` read one table (pfjax.tables.TRACK_UNITS)."""
    assert study.COLUMNS["window_max_z"][0] == api.UNITS["window_max_z"] == "m"
    assert study.COLUMNS["gamma"][0] == api.UNITS["final.*"]["gamma"] == "rad"


def test_a_step_longer_than_the_default_horizon_names_the_step():
    """At the schema's horizon (TrackConfig's, 30 s) only the step was changed: sim.dt is named."""
    with pytest.raises(ConfigError, match=r"^sim\.dt: must be <= horizon \(30 s\), got 100"):
        study_config.load(overrides=["sim.dt=100.0"])
