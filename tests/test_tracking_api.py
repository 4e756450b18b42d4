"""``pfjax.tracking.run``: the same dict as ``pfjax track --json`` (forward and backward), and every
bad argument refused before anything is simulated with an InputError whose message starts with the
argument's name."""

from __future__ import annotations

import json
import math

import pytest

import pfjax.tracking
from pfjax.cli import main
from pfjax.cli import track as cli_track
from pfjax.errors import InputError
from pfjax.tracking import api, run

FAST = {"horizon": 3.0, "dt": 0.05}


def test_run_is_exported():
    assert "run" in pfjax.tracking.__all__ and pfjax.tracking.run is api.run
    assert cli_track.LEADERS == api.LEADERS  # the command line's --leader choices are the library's


@pytest.mark.parametrize(
    "mode,extra",
    [
        ("forward", ["--leader", "circle", "--stop-and-go", "0.3"]),
        ("backward", ["--p", "-0.5", "--offset", "0.2", "-0.3", "--beta-r-deg", "2"]),
    ],
)
def test_run_equals_cli_json(capsys, mode, extra):
    rc = main(["track", "--mode", mode, "--horizon", "3", "--dt", "0.05", *extra, "--json"])
    out, err = capsys.readouterr()
    assert rc == 0 and err == ""
    cli = json.loads(out)
    kw = (
        {"leader": "circle", "stop_and_go": 0.3}
        if mode == "forward"
        else {"p": -0.5, "offset": (0.2, -0.3), "beta_r_deg": 2.0}
    )
    d = run(mode, **kw, **FAST)
    from pfjax.cli.records import RECORD  # the command adds its units, arguments and provenance

    assert json.loads(json.dumps(d)) == {k: v for k, v in cli.items() if k not in RECORD or k in d}
    assert set(cli) - set(d) == set(RECORD)
    assert d["mode"] == mode and d["f"] == (1 if mode == "forward" else -1) and d["T"] == pytest.approx(3.0)


@pytest.mark.parametrize(
    "kw,key",
    [
        ({"p": 0}, "p"),
        ({"p": 0.0}, "p"),
        ({"l": 0}, "l"),
        ({"gamma_max_deg": 95}, "gamma_max_deg"),
        ({"gamma_max_deg": 0}, "gamma_max_deg"),
        ({"speed": math.nan}, "speed"),
        ({"speed": -1.0}, "speed"),
        ({"stop_and_go": 1.5}, "stop_and_go"),
        ({"stop_and_go": math.nan}, "stop_and_go"),
        ({"stop_and_go": "0.5"}, "stop_and_go"),
        ({"leader": "spiral"}, "leader"),
        ({"leader": None}, "leader"),
        ({"mode": "sideways"}, "mode"),
        ({"mode": 1}, "mode"),
        ({"a": 0}, "a"),
        ({"k": math.inf}, "k"),
        ({"v_max": True}, "v_max"),
        ({"omega_max_deg": -90}, "omega_max_deg"),
        ({"offset": (0.0,)}, "offset"),
        ({"offset": (0.0, math.nan)}, "offset"),
        ({"heading_error_deg": "10"}, "heading_error_deg"),
        ({"beta_r_deg": 90}, "beta_r_deg"),
        ({"beta_f_deg": -91}, "beta_f_deg"),
        ({"horizon": 0}, "horizon"),
        ({"dt": 0}, "dt"),
        ({"dt": 5.0}, "horizon"),  # the horizon given too (3 s): it is named, as SimConfig names it
        ({"dt": 31.0, "horizon": 30.0}, "dt"),  # the default horizon: the step is named
        ({"horizon": 1e6, "dt": 0.1}, "horizon/dt"),
        ({"p": 1e-200}, "p"),  # 1 / p overflows: refused below 1e-12 in magnitude
        ({"p": -5e-324}, "p"),
        ({"l": 1e-300}, "l"),
        ({"offset": (-51.0, 0.0)}, "offset"),  # would start diverged (|z~| > 50 m)
    ],
)
def test_bad_argument_raises_input_error_naming_it(monkeypatch, kw, key):
    monkeypatch.setattr(api, "_simulate", lambda c: pytest.fail("simulated despite a bad argument"))
    args = {**FAST, **kw}
    mode = args.pop("mode", "forward")
    with pytest.raises(InputError) as e:
        run(mode, **args)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ") and "\n" not in str(e.value)


@pytest.mark.parametrize(
    "kw,argv,line",
    [
        ({"p": 0}, ["--p", "0"], "--p: must be nonzero (M is singular at p = 0), got 0"),
        # both changed (the horizon is 3 s here): the horizon is named, as SimConfig names it
        ({"dt": 5.0}, ["--dt", "5"], "--horizon: must be >= --dt (5 s), got 3"),
        ({"stop_and_go": 1.5}, ["--stop-and-go", "1.5"], "--stop-and-go: expected a depth in [0, 1], got 1.5"),
        # a value just past the bound is shown with every digit, not rounded onto the bound
        (
            {"stop_and_go": 1.0000001},
            ["--stop-and-go", "1.0000001"],
            "--stop-and-go: expected a depth in [0, 1], got 1.0000001",
        ),
        ({"gamma_max_deg": 95}, ["--gamma-max-deg", "95"], "--gamma-max-deg: magnitude must be < 90 deg, got 95"),
        ({"offset": (0.0, math.nan)}, ["--offset", "0", "nan"], "--offset: expected a finite number, got nan"),
        (
            {"horizon": 1e6, "dt": 0.1},
            ["--horizon", "1e6", "--dt", "0.1"],
            "--horizon/--dt: --horizon / --dt (a run's integrator step count) may be at most 2e+06, got 1e+06 / 0.1 = 1e+07",
        ),
    ],
)
def test_cli_names_the_flags_in_the_library_message(capsys, kw, argv, line):
    """The command line's one line is the library's message with the flags named (as before the move)."""
    with pytest.raises(InputError) as e:
        run(**{**FAST, **kw})
    assert main(["track", "--horizon", "3", "--dt", "0.05", *argv, "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == f"pfjax track: error: {line}\n"
    assert str(e.value).split(": ", 1)[1] == line.split(": ", 1)[1].replace("--horizon", "horizon").replace(
        "--dt", "dt"
    )
