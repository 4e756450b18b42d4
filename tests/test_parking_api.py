"""``pfjax.parking.run`` / ``pfjax.parking.search``: the command line's results and checks as a
Python API.

References: ``pfjax parking --json`` (the same run through the command line, parsed from its
output) for case A and the garage; for bad arguments, the argument's name at the start of the
:class:`~pfjax.errors.InputError` (map errors: :class:`~pfjax.parking.maps.MapError` with key
``map`` or ``x0``), and nothing simulated.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from pfjax import parking
from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.parking import api
from pfjax.parking.maps import MapError


def cli_json(capsys, *args):
    rc = main(list(args) + ["--json"])
    out, err = capsys.readouterr()
    assert rc == 0, err
    return json.loads(out)


def result(cli: dict, api_result: dict) -> dict:
    """The command's JSON without the record it adds to the result (pfjax.cli.records.RECORD)."""
    from pfjax.cli.records import RECORD

    return {k: v for k, v in cli.items() if k not in RECORD or k in api_result}


def test_exports_are_the_api_functions():
    import pfjax.parking.switch_search  # noqa: F401

    assert parking.run is api.run and parking.search is api.search
    assert set(parking.__all__) == {"run", "run_study", "search"}
    from pfjax.parking import study

    assert parking.run_study.__doc__ and "pfjax.parking.study.run" in parking.run_study.__doc__ and study.run


def test_run_case_a_equals_cli(capsys):
    o = cli_json(capsys, "parking")
    r = api.run()
    assert r == result(o, r)
    assert r["converged"] and r["x0"] == {"x": -0.4, "y": 0.5, "theta_deg": 0.0} and r["xs"] is None
    # the same run from explicit arguments, in the Python forms
    assert api.run("parallel", np.array([-0.4, 0.5, 0]), direction="forward", alpha_schedule=[1]) == r


def test_run_garage_equals_cli(capsys):
    o = cli_json(capsys, "parking", "--map", "garage", "--alpha-schedule", "1,0.5")
    r = api.run("garage", alpha_schedule="1,0.5")
    assert r == result(o, r)
    assert r["xs"] == -0.9 and r["map"] == "garage" and r["x0"] == {"x": -0.9, "y": 0.6, "theta_deg": -85.0}
    assert r["alpha_schedule"][:3] == [1.0, 0.5, 0.5] and r["switches"] == len(r["switch_log"]) >= 1


OK = {"map": "parallel", "x0": (0.1, 0.5, 0.0)}
NAN = math.nan


@pytest.mark.parametrize(
    "kw, key",
    [
        ({"x0": (0.1, NAN, 0.0)}, "x0"),
        ({"x0": (0.1, 0.5, 90.0)}, "x0"),
        ({"x0": (0.1, 0.5)}, "x0"),
        ({"x0": "0 0.5 0"}, "x0"),
        ({"x0": (0.0, -0.5, 0.0)}, "x0"),  # axle point inside the kerb
        ({"x0": (0.0, 0.0, 60.0)}, "x0"),  # body overlapping the kerb
        ({"x0": (0.0, 0.3, 0.0), "front": 0.53}, "x0"),  # body overlapping car_ahead with a longer reach
        ({"speed": -0.05}, "speed"),
        ({"speed": 0}, "speed"),
        ({"speed": NAN}, "speed"),
        ({"k1": math.inf}, "k1"),
        ({"k2": True}, "k2"),
        ({"t_max": -1.0}, "t_max"),
        ({"scan_period": 0.001}, "scan_period"),
        ({"scan_period": 11.0}, "scan_period"),
        ({"front": 0.54}, "front"),
        ({"front": 0.6}, "front"),
        ({"front": NAN}, "front"),
        ({"front": 0.0}, "front"),
        ({"map": "nowhere.toml"}, "map"),
        ({"map": "Parallel"}, "map"),
        ({"map": 3}, "map"),
        ({"alpha_schedule": "1,-1"}, "alpha_schedule"),
        ({"alpha_schedule": "1,a"}, "alpha_schedule"),
        ({"alpha_schedule": ""}, "alpha_schedule"),
        ({"alpha_schedule": [1.0, NAN]}, "alpha_schedule"),
        ({"alpha_schedule": []}, "alpha_schedule"),
        ({"alpha_schedule": [1.0] * 9}, "alpha_schedule"),
        ({"alpha_schedule": None}, "alpha_schedule"),
        ({"xs": NAN}, "xs"),
        ({"xs": "-0.9"}, "xs"),
        ({"direction": "reverse"}, "direction"),
        ({"direction": -1}, "direction"),
        ({"lag": "yes"}, "lag"),
    ],
)
def test_run_bad_argument_names_it(kw, key):
    with pytest.raises(InputError) as e:
        api.run(**{**OK, **kw})
    assert re.split(r"[.\[]", e.value.key)[0] == key
    assert str(e.value).startswith(key) and "\n" not in str(e.value)


@pytest.mark.parametrize(
    "kw, key",
    [
        ({"method": "annealing"}, "method"),
        ({"n": 1}, "n"),
        ({"n": 65}, "n"),
        ({"n": 2.0}, "n"),
        ({"population": 1}, "population"),
        ({"generations": 0}, "generations"),
        ({"seed": -1}, "seed"),
        ({"seed": 2**64}, "seed"),
        ({"weight": -1.0}, "weight"),
        ({"weight": NAN}, "weight"),
        ({"speed": -1.0}, "speed"),
        ({"front": 0.54}, "front"),
        ({"map": "nowhere.json"}, "map"),
        ({"map": "parallel"}, "x0"),  # no default start there
        ({"x0": (-0.7, 0.6, 40.0)}, "x0"),  # body overlapping the garage's left wall
    ],
)
def test_search_bad_argument_names_it(kw, key):
    method = "ga" if set(kw) & set(api.SEARCH_SETTINGS["ga"]) else "grid"  # the value checked by its method
    with pytest.raises(InputError) as e:
        api.search(**{"method": method, **kw})
    assert e.value.key == key and str(e.value).startswith(key) and "\n" not in str(e.value)
    assert "not with method" not in str(e.value)


@pytest.mark.parametrize(
    "method, kw",
    [("grid", {"generations": 5}), ("grid", {"population": 5}), ("grid", {"seed": 1}), ("ga", {"n": 2})],
)
def test_search_refuses_a_setting_its_method_does_not_read(method, kw, capsys):
    """As ``pfjax tune`` refuses ``steps`` with the GA: a setting the method would ignore is named,
    at its default value too, in the library and on the command line."""
    (key,) = kw
    with pytest.raises(InputError, match=rf"^{key}: not with method {method}"):
        api.search(method, **kw)
    assert main(["parking-search", "--method", method, f"--{key}", str(kw[key]), "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith(f"pfjax parking-search: error: --{key}: not with --method {method}"), err


def test_map_errors_keep_their_message_and_name_the_argument(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[obstacles]]\nvertices = [[0, 0], [1, 0], [1, 1]]\n")
    with pytest.raises(MapError) as e:
        api.run(str(bad), (-1.0, 0.0, 0.0))
    assert e.value.key == "map"
    assert (
        str(e.value) == "obstacles[0].vertices: polygon not closed (the last vertex must repeat the first, [0.0, 0.0])"
    )
    with pytest.raises(MapError) as e:
        api.search("ga", map=tmp_path)  # a directory, given as a path object
    assert e.value.key == "map" and str(e.value).startswith(f"map: {tmp_path}: is a directory")
    with pytest.raises(MapError) as e:
        api.run(x0=(0.0, -0.5, 0.0))
    assert e.value.key == "x0" and str(e.value) == "x0: start point (0, -0.5) lies inside obstacle 'kerb'"


def test_cli_names_the_flags(capsys):
    """The API's message with the flag's name: the command line's one line."""
    for args, msg in [
        (["parking", "--front", "0.6"], "--front: must be < 0.54 (the rectangle length), got 0.6"),
        (
            ["parking", "--alpha-schedule", "1,-1"],
            "--alpha-schedule[1]: must be > 0, got -1",
        ),
        (["parking", "--x0", "0", "-0.5", "0"], "--x0: start point (0, -0.5) lies inside obstacle 'kerb'"),
        (
            ["parking", "--map", "nowhere.toml"],
            "--map: nowhere.toml: not 'parallel', 'garage' or an existing TOML/JSON map file",
        ),
        (["parking-search", "--method", "grid", "--n", "1"], "--n: must be >= 2, got 1"),
        (["parking", "--horizon", "-1"], "--horizon: must be > 0, got -1"),  # the API's t_max
    ]:
        rc = main(args)
        out, err = capsys.readouterr()
        assert rc == 2 and out == "" and err == f"pfjax {args[0]}: error: {msg}\n"


@pytest.mark.parametrize("t_max, expected", [(2.0, 2.0), (3.0, 3.0), (2.02, 2.05)])
def test_a_float32_run_times_out_at_the_first_step_at_or_after_t_max(t_max, expected):
    """In float32 (a study's or a caller's own precision; pfjax.parking.run itself runs float64) the
    accumulated time rounds by several ulps: the timeout is counted in steps (h = 0.05 s here), so
    a run stops at ``t_max`` (or the first step after it), never a step later, as in float64."""
    import jax

    from pfjax.parking.maps import PARALLEL, to_obstacle_map
    from pfjax.parking.schedules import CASES
    from pfjax.parking.simulate import ParkingConfig, run_jit, run_params

    with jax.enable_x64(False):
        p = run_params(CASES["A"]["x0"])
        r = run_jit(p, to_obstacle_map(list(PARALLEL.values())), ParkingConfig(t_max=t_max))
        status, t = int(r.status), float(r.time)
    assert status == 1 and t == pytest.approx(expected, abs=1e-5), (status, t)  # 1: timeout


def test_the_api_checks_the_start_as_the_command_does_in_float32_too(capsys):
    """A start 1e-10 m clear of the kerb: the command (float64) runs it, and so does the API in a
    float32 process (it checks and simulates in float64, whatever jax_enable_x64 says)."""
    import jax

    x0 = (-0.4, 0.3850000001, 0.0)
    assert main(["parking", "--x0", *map(str, x0), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    with jax.enable_x64(False):
        api = parking.run(x0=x0)
    assert api["status"] == cli["status"] and api["time_s"] == cli["time_s"]


def test_a_map_file_edited_in_place_is_another_run_and_a_spelling_is_not(tmp_path, monkeypatch, capsys):
    """The config hash covers the map's obstacles (map_sha256), not only its path; ./m.toml and
    m.toml are one run; -0 and 0 are one run."""
    monkeypatch.chdir(tmp_path)
    slot = "[[obstacles]]\nname = 'box'\nvertices = [[1.0, 1.0], [2.0, 1.0], [2.0, 2.0], [1.0, 2.0], [1.0, 1.0]]\n"
    (tmp_path / "m.toml").write_text(slot)

    def hashes(*args):
        assert main(["parking", "--x0", "-0.4", "0.5", "0", "--horizon", "1", "--json", *args]) == 0
        out = json.loads(capsys.readouterr().out)
        return out["config_sha256"], out["map_sha256"]

    first, spelt = hashes("--map", "m.toml"), hashes("--map", "./m.toml")
    assert first == spelt
    (tmp_path / "m.toml").write_text(slot.replace("[2.0, 2.0]", "[2.5, 2.0]"))
    edited = hashes("--map", "m.toml")
    assert edited[0] != first[0] and edited[1] != first[1]
    assert main(["parking", "--x0", "-0.4", "0.5", "-0", "--horizon", "1", "--json"]) == 0
    minus = json.loads(capsys.readouterr().out)["config_sha256"]
    assert main(["parking", "--x0", "-0.4", "0.5", "0", "--horizon", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["config_sha256"] == minus
