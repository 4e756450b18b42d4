"""``pfjax.tracking.run`` / ``pfjax track``: a horizon that is not a whole number of steps is
refused (never rounded one way or the other), and a mapping is not an offset pair.

References: hand-computed step counts (2.5 s / 1 s and 0.015 s / 0.01 s are 2.5 and 1.5 steps; 30 s
/ 0.01 s is 3000 up to round-off)."""

from __future__ import annotations

import pytest

from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.tracking import api


def _never(monkeypatch):
    monkeypatch.setattr(api, "_simulate", lambda c: (_ for _ in ()).throw(AssertionError("simulated")))


@pytest.mark.parametrize("horizon,dt,steps", [(2.5, 1.0, "2.5"), (0.015, 0.01, "1.5"), (3.0, 0.7, "4.28571")])
def test_horizon_must_be_whole_steps(monkeypatch, horizon, dt, steps):
    _never(monkeypatch)
    with pytest.raises(InputError) as e:
        api.run(horizon=horizon, dt=dt)
    assert e.value.key == "horizon"
    assert str(e.value).startswith(
        f"horizon: must be a whole number of steps dt = {dt:g} s, got {horizon:g} s = {steps}"
    )


def test_whole_steps_up_to_round_off_pass(monkeypatch):
    seen = []
    monkeypatch.setattr(api, "_simulate", lambda c: seen.append((c["horizon"], c["dt"])))
    for horizon, dt in ((30.0, 0.01), (0.3, 0.1), (12.0, 0.02), (3.0, 0.05)):
        api.run(horizon=horizon, dt=dt)
    assert len(seen) == 4


def test_horizon_error_on_the_command_line(capsys):
    rc = main(["track", "--horizon", "2.5", "--dt", "1", "--json"])
    out, err = capsys.readouterr()
    assert (rc, out) == (2, "")
    assert err == (
        "pfjax track: error: --horizon: must be a whole number of steps --dt = 1 s, got 2.5 s = 2.5 steps "
        "(e.g. 2 or 3 s)\n"
    )


def test_offset_mapping_refused(monkeypatch):
    _never(monkeypatch)
    with pytest.raises(InputError) as e:
        api.run(offset={1: 2, 3: 4})
    assert e.value.key == "offset" and str(e.value).startswith("offset: expected two numbers")


@pytest.mark.parametrize(
    "override, key",
    [("lemma.offsets=[[60.0, 0.0]]", "lemma.offsets[0]"), ("mc.offset_max=100", "mc.offset_max")],
)
def test_the_study_config_checks_offsets_as_pfjax_track_does(override, key):
    """A start 50 m or more from the leading vehicle's start point would end at once as diverged:
    refused in a study config too, naming the key (the one check, api.check_offset)."""
    from pfjax.config import ConfigError
    from pfjax.tracking.study_config import load

    with pytest.raises(ConfigError) as e:
        load(None, [override], quick=True)
    assert str(e.value).startswith(f"{key}: must start less than 50 m"), str(e.value)
    if key == "mc.offset_max":  # the distance refused is the sample's farthest start, and says so
        assert str(e.value).endswith("got 141.421 m for the sample's corner (100, 100) m"), str(e.value)
    assert load(None, ["mc.offset_max=35"], quick=True).mc.offset_max == 35  # 35 sqrt(2) = 49.5 m


@pytest.mark.parametrize(
    "argv", [["track", "--horizon", "10", "--T", "20"], ["parking", "--horizon", "5", "--t-max", "6"]]
)
def test_a_flag_and_its_deprecated_spelling_together_are_refused(capsys, argv):
    """Which one won was argparse's order: refused, naming both."""
    with pytest.raises(SystemExit) as e:
        main([*argv, "--json"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert e.value.code == 2 and "not with" in err and argv[1] in err and argv[3] in err, err


def test_a_step_that_does_not_divide_the_default_horizon_names_the_step(monkeypatch, capsys):
    """Only the step was changed: the error names ``dt`` (``--dt``), as pfjax.sim.settings.SimConfig
    does, with the steps that divide the horizon; a horizon given too names ``horizon``. Reference:
    30 s / 0.0031 s = 9677.419355 steps; 30/9678 and 30/9677 s, with every digit (each accepted as given)."""
    _never(monkeypatch)
    with pytest.raises(InputError) as e:
        api.run(dt=0.0031)
    assert e.value.key == "dt"
    assert str(e.value) == (
        "dt: must divide horizon = 30 s into whole steps, got 0.0031 s = 9677.419355 steps "
        "(e.g. 0.00309981401115933 or 0.0031001343391547 s)"
    )
    from pfjax.tracking.api import check_time

    assert main(["track", "--horizon", "0.001", "--json"]) == 2  # only the horizon changed: it is named
    assert capsys.readouterr().err == "pfjax track: error: --horizon: must be >= --dt (0.01 s), got 0.001\n"
    assert main(["track", "--dt", "31", "--json"]) == 2  # only the step: the step
    assert capsys.readouterr().err == "pfjax track: error: --dt: must be <= --horizon (30 s), got 31\n"

    assert check_time(30.0, 0.00309981401115933) == 9678 and check_time(30.0, 0.0031001343391547) == 9677
    with pytest.raises(InputError) as e:
        api.run(horizon=20.0, dt=0.0031)
    assert e.value.key == "horizon"
    rc = main(["track", "--dt", "0.0031", "--json"])
    out, err = capsys.readouterr()
    assert (rc, out) == (2, "")
    assert err == (
        "pfjax track: error: --dt: must divide --horizon = 30 s into whole steps, got 0.0031 s = 9677.419355 "
        "steps (e.g. 0.00309981401115933 or 0.0031001343391547 s)\n"
    )


def test_the_study_names_its_step_by_the_same_rule():
    from pfjax.config import ConfigError
    from pfjax.tracking.study_config import load

    with pytest.raises(ConfigError) as e:
        load(None, ["sim.dt=0.0031"])
    assert str(e.value).startswith("sim.dt: must divide horizon = 30 s into whole steps"), str(e.value)
