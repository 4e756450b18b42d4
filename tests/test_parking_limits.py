"""Limits of ``pfjax parking`` / ``parking-search`` and their Python API, checked before anything is
simulated or written: the search's total work (:data:`pfjax.parking.api.MAX_SEARCH_PERIODS`), a
map's obstacle count (:data:`pfjax.parking.maps.MAX_OBSTACLES`), one check of an alpha schedule for
the string and the sequence forms, mappings refused as sequences, the map's one-line messages, and
``run_study``'s arguments named as Python names them.

References: the limits' own constants and hand-computed totals (``n^3 x t_max / scan_period``,
``population x (generations + 1) x t_max / scan_period``); the messages as the project's one-line
rule spells them.
"""

from __future__ import annotations

import json

import pytest

from pfjax import parking
from pfjax.cli import main
from pfjax.errors import InputError
from pfjax.parking import api
from pfjax.parking.maps import MAX_OBSTACLES, MAX_VERTICES, MapError, load_map


@pytest.fixture
def no_search(monkeypatch):
    """Fail the test if a search reaches the simulator."""

    def refuse(*args, **kwargs):
        raise AssertionError("simulated")

    monkeypatch.setattr(api, "_search", refuse)


def cli(capsys, *args):
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def test_search_work_is_limited_before_simulating(no_search, capsys):
    limit = api.MAX_SEARCH_PERIODS
    with pytest.raises(InputError) as e:
        api.search("ga", population=1000, generations=1000)
    assert e.value.key == "population/generations" and str(e.value).endswith(
        f"1000 x 1001 = 1001000 runs x 2000 periods = {1001000 * 2000:.3g}"
    )
    assert f"at most {limit:.0e} scanner periods" in str(e.value)
    for kwargs, total in (({}, 64**3 * 2000), ({"t_max": 2000.0}, 64**3 * 20000)):
        with pytest.raises(InputError) as e:
            api.search("grid", n=64, **kwargs)
        assert e.value.key == "n" and str(e.value).endswith(f"= {total:.3g}") and total > limit
    rc, out, err = cli(capsys, "parking-search", "--method", "grid", "--n", "64")
    assert rc == 2 and out == "" and err.count("\n") == 1
    assert err.startswith("pfjax parking-search: error: --n: the search may simulate at most 1e+08 scanner periods")
    rc, out, err = cli(capsys, "parking-search", "--method", "ga", "--population", "1000", "--generations", "1000")
    assert rc == 2 and out == "" and err.startswith("pfjax parking-search: error: --population/--generations: ")
    assert "--population x (--generations + 1) = 1000 x 1001" in err


def test_search_limit_admits_the_documented_sizes(monkeypatch):
    """The default grid (n = 32), the default GA, n = 64 at a 38 s horizon and the tests' sizes pass
    the check (the search itself replaced by a stub)."""
    seen = []
    monkeypatch.setattr(api, "_search", lambda c, method, **kw: seen.append((method, kw)) or {})
    api.search("grid")  # 32^3 x 2000 = 6.6e7
    api.search("ga")  # 20 x 101 x 2000 = 4.0e6
    api.search("grid", n=64, t_max=38.0)  # 64^3 x 380 = 9.96e7
    api.search("ga", population=5, generations=2)
    assert api.MAX_SEARCH_PERIODS >= 32**3 * 2000 and len(seen) == 4


def test_alpha_schedule_string_and_sequence_share_one_check(capsys):
    for value in ("1e13", (1e13,), [1, 1e13]):
        with pytest.raises(InputError) as e:
            api.run(alpha_schedule=value)
        index = 1 if isinstance(value, list) else 0
        assert str(e.value) == f"alpha_schedule[{index}]: expected a magnitude <= 1e+12, got 1e+13"
    with pytest.raises(InputError) as e:
        api.run(alpha_schedule="1,-1")
    assert str(e.value) == "alpha_schedule[1]: must be > 0, got -1"
    with pytest.raises(InputError) as e:
        api.run(alpha_schedule="1,inf")
    assert str(e.value) == "alpha_schedule[1]: expected a finite number, got inf"
    rc, out, err = cli(capsys, "parking", "--alpha-schedule", "1e300", "--json")
    assert (rc, out) == (2, "")
    assert err == "pfjax parking: error: --alpha-schedule[0]: expected a magnitude <= 1e+12, got 1e+300\n"


def test_mappings_are_not_schedules():
    with pytest.raises(InputError) as e:
        api.run(alpha_schedule={1: 2})
    assert e.value.key == "alpha_schedule" and str(e.value).startswith("alpha_schedule: expected numbers")


def test_map_messages_are_one_clean_line(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for spec, msg in (
        ("nosuch", "--map: nosuch: not 'parallel', 'garage' or an existing TOML/JSON map file"),
        ("", "--map: expected 'parallel', 'garage' or a TOML/JSON map file, got ''"),
    ):
        rc, out, err = cli(capsys, "parking", "--map", spec)
        assert (rc, out, err) == (2, "", f"pfjax parking: error: {msg}\n")
        with pytest.raises(MapError) as e:
            api.run(spec, (0.0, 0.0, 0.0))
        assert e.value.key == "map" and str(e.value) == msg.replace("--map: ", "map: ", 1)
    with pytest.raises(SystemExit):
        main(["parking-search", "--help"])
    assert "garage (default), parallel (with --x0), or a TOML/JSON map file" in " ".join(capsys.readouterr()[0].split())


def test_map_obstacle_count_is_limited(tmp_path):
    box = [[10.0, 10.0], [11.0, 10.0], [11.0, 11.0], [10.0, 10.0]]
    p = tmp_path / "many.json"
    p.write_text(json.dumps({"obstacles": [{"vertices": box}] * (MAX_OBSTACLES + 1)}))
    with pytest.raises(MapError) as e:
        load_map(str(p))
    assert str(e.value) == f"obstacles: at most {MAX_OBSTACLES} obstacles per map, got {MAX_OBSTACLES + 1}"
    p.write_text(json.dumps({"obstacles": [{"vertices": box, "name": f"o{i}"} for i in range(MAX_OBSTACLES)]}))
    assert len(load_map(str(p))[1]) == MAX_OBSTACLES
    assert (MAX_OBSTACLES, MAX_VERTICES) == (1000, 128)


def test_run_study_names_its_python_arguments(tmp_path, monkeypatch):
    """Every bad argument of ``pfjax.parking.run_study`` is refused with its Python name, before
    anything is written."""
    from pfjax.parking import study

    monkeypatch.setattr(study, "run_study", lambda *a, **k: (_ for _ in ()).throw(AssertionError("ran")))
    busy = tmp_path / "busy.txt"
    busy.write_text("mine")
    for args, kwargs, key in (
        ((123, str(tmp_path / "x")), {}, "config"),
        ((None, 123), {}, "out"),
        ((None, str(tmp_path / "x3")), {"quick": "yes"}, "quick"),
        ((None, str(tmp_path / "x4")), {"overrides": "seed=1", "quick": True}, "overrides"),
        ((None, str(tmp_path / "x5")), {"overrides": ["seed"], "quick": True}, "overrides"),
        ((None, str(tmp_path / "x6")), {"overwrite": 1}, "overwrite"),
        ((None, busy), {"quick": True}, "out"),
    ):
        with pytest.raises(InputError) as e:
            parking.run_study(*args, **kwargs)
        assert e.value.key == key and str(e.value).startswith(f"{key}: "), (kwargs, str(e.value))
        assert "--" not in str(e.value).split(":")[0]
    assert sorted(x.name for x in tmp_path.iterdir()) == ["busy.txt"] and busy.read_text() == "mine"


def test_the_study_script_names_its_out_flag_in_the_whole_refusal(tmp_path):
    """``studies/parking.py --out DIR`` on a user's directory: one line naming ``--out`` (the advice
    too), exit 2, the directory untouched (the library told the flag's name, pfjax.outputs)."""
    import subprocess
    import sys
    from pathlib import Path

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    script = Path(__file__).resolve().parents[1] / "studies" / "parking.py"
    r = subprocess.run(
        [sys.executable, str(script), "--quick", "--out", str(mine)], capture_output=True, text=True, timeout=300
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("parking: error: --out: ") and "choose another --out" in r.stderr, r.stderr
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize(
    "override, key",
    [
        ("controller.k1=1e-300", "controller.k1"),
        ("sim.t_max=1e-300", "sim.t_max"),
        ("sim.front=1e-300", "sim.front"),
        ("sim.scan_period=100", "sim.scan_period"),
        ("montecarlo.scan_hi=100", "montecarlo.scan_hi"),
        ("montecarlo.speed_lo=1e-300", "montecarlo.speed_lo"),
        ("assumptions.fronts=[1e-300]", "assumptions.fronts[0]"),
    ],
)
def test_the_study_config_refuses_what_the_command_line_refuses(override, key):
    """Positive values at least 1e-12 and scanner periods at most MAX_SCAN_PERIOD, as pfjax parking
    takes them (docs/studies.md): one line naming the key."""
    from pfjax.config import ConfigError
    from pfjax.parking.study_config import load

    with pytest.raises(ConfigError) as e:
        load(None, [override], quick=True)
    assert str(e.value).startswith(f"{key}: ") and "\n" not in str(e.value), str(e.value)


def test_a_scanner_period_longer_than_the_run_is_refused_everywhere(capsys):
    """One RK4 step of a 10 s period would run a 0.01 s run to 5 s: refused, naming the period."""
    from pfjax.config import ConfigError
    from pfjax.parking.study_config import load

    rc, _, err = cli(capsys, "parking", "--horizon", "0.01", "--scan-period", "10", "--json")
    assert rc == 2 and err.strip().splitlines()[-1].startswith(
        "pfjax parking: error: --scan-period: must be <= --horizon"
    )
    with pytest.raises(InputError, match=r"^scan_period: must be <= t_max"):
        parking.run(t_max=0.01, scan_period=10.0)
    with pytest.raises(ConfigError, match=r"^sim.scan_period: must be <= sim.t_max \(one scanner period"):
        load(None, ["sim.t_max=0.05", "sim.scan_period=0.1"], quick=True)
    with pytest.raises(ConfigError, match=r"^sim.scan_period: sim.t_max / scan period may be at most 20000"):
        load(None, ["sim.t_max=1000", "sim.scan_period=0.01"], quick=True)
