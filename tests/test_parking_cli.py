"""``pfjax parking`` / ``pfjax parking-search`` contract, the search against brute force, and the
study in quick mode.

References: the grid's best must be the arg-max of its own table and equal an independent single
run at that point; the GA's result must re-simulate to the fitness it reports, and its number of
simulations must be P + G (P − E) (MATLAB ga's count).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from html import unescape
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from units_check import numbers_without_units

from pfjax.cli import main
from pfjax.parking.maps import GARAGE, MAX_VERTICES, to_obstacle_map
from pfjax.parking.simulate import ParkingConfig, run_jit, run_params
from pfjax.parking.switch_search import SEARCH_CONFIG, fitness, lattice

ROOT = Path(__file__).resolve().parents[1]
GMAP = to_obstacle_map(list(GARAGE.values()))


def run_cli(capsys, *args):
    rc = main(list(args))
    out, err = capsys.readouterr()
    return rc, out, err


def strict(text):
    assert text.count("\n") == 1

    def bad(c):
        raise AssertionError(c)

    return json.loads(text, parse_constant=bad)


def test_parking_json_contract(capsys):
    rc, out, _ = run_cli(
        capsys,
        "parking",
        "--map",
        "parallel",
        "--x0",
        "0.1",
        "0.5",
        "0",
        "--direction",
        "backward",
        "--alpha-schedule",
        "1,0.5,8,1",
        "--json",
    )
    assert rc == 0
    o = strict(out)
    assert o["converged"] is True and o["status"] == "converged"
    assert isinstance(o["time_s"], float) and o["switches"] == len(o["switch_log"]) >= 1
    for e in o["switch_log"]:
        assert set(e) >= {"t", "x", "y", "theta_deg"}
    assert set(o["final"]) == {"x", "y", "theta_deg"}
    assert abs(o["final"]["x"]) + math.hypot(o["final"]["y"], math.tan(math.radians(o["final"]["theta_deg"]))) < 0.02
    # the same run through the library
    r = run_jit(
        run_params((0.1, 0.5, 0.0), -1, (1, 0.5, 8, 1)),
        to_obstacle_map(list(__import__("pfjax.parking.maps", fromlist=["x"]).PARALLEL.values())),
        ParkingConfig(),
    )
    assert o["time_s"] == pytest.approx(float(r.time)) and o["switches"] == int(r.n_switches)
    assert [e["t"] for e in o["switch_log"]] == pytest.approx(list(np.asarray(r.log_t)[: int(r.n_switches)]))


def test_parking_garage_user_map(capsys, tmp_path):
    m = tmp_path / "garage.json"
    m.write_text(
        json.dumps({"obstacles": [{"vertices": [list(v) for v in poly] + [list(poly[0])]} for poly in GARAGE.values()]})
    )
    rc, out, _ = run_cli(capsys, "parking", "--map", str(m), "--x0", "-0.9", "0.6", "-85", "--xs", "-1.2", "--json")
    rc2, out2, _ = run_cli(capsys, "parking", "--map", "garage", "--xs", "-1.2", "--json")
    assert rc == rc2 == 0
    a, b = strict(out), strict(out2)
    assert a["time_s"] == b["time_s"] and a["switch_log"] == b["switch_log"]
    assert [e["cause"] for e in a["switch_log"]][:2] == ["obstacle", "switch_point"]


@pytest.mark.parametrize(
    "args, flag",
    [
        (["parking", "--alpha-schedule", "1,-1"], "--alpha-schedule"),
        (["parking", "--x0", "0", "-0.5", "0"], "--x0"),  # inside the kerb
        (["parking", "--x0", "0", "0.5", "90"], "--x0"),
        (["parking", "--map", "nowhere.toml"], "--map"),
        (["parking", "--speed", "0"], "--speed"),
        (["parking", "--xs", "nan"], "--xs"),
        (["parking-search", "--method", "grid", "--n", "1"], "--n"),
        (["parking-search", "--method", "ga", "--population", "1"], "--population"),
        (["parking-search", "--method", "ga", "--population", "100000000"], "--population: must be <= 1000000"),
        (["parking-search", "--method", "grid", "--map", "parallel"], "--x0"),
        (["parking", "--scan-period", "0.001"], "--scan-period"),
        (["parking", "--horizon", "0"], "--horizon"),  # the timeout (once --t-max)
        (["parking-search", "--method", "grid", "--horizon", "nan"], "--horizon"),
        # too many scanner periods: the flag whose value makes it so (the timeout at the default period)
        (["parking", "--horizon", "1e9"], "--horizon: --horizon / scan period may be at most 20000"),
        (["parking-search", "--method", "grid", "--horizon", "1e9"], "--horizon: "),
        (["parking", "--scan-period", "0.00001"], "--scan-period: --horizon / scan period may be at most"),
    ],
)
def test_bad_values_exit_2_one_line(capsys, args, flag):
    rc, out, err = run_cli(capsys, *args, "--json")
    assert rc == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"pfjax {args[0]}: error: {flag}")


def test_bad_choice_exits_2(capsys):
    with pytest.raises(SystemExit) as e:
        main(["parking-search", "--method", "annealing"])
    assert e.value.code == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_bad_map_file_names_key(capsys, tmp_path):
    m = tmp_path / "bad.toml"
    m.write_text("[[obstacles]]\nvertices = [[0, 0], [1, 0], [1, 1]]\n")
    rc, out, err = run_cli(capsys, "parking", "--map", str(m), "--x0", "-1", "0", "0")
    assert (
        rc == 2
        and err.strip()
        == "pfjax parking: error: --map: obstacles[0].vertices: polygon not closed (the last vertex must repeat the first, [0.0, 0.0])"
    )


def _poly_file(path, polygons, names=None):
    obs = [{"vertices": [list(v) for v in poly] + [list(poly[0])]} for poly in polygons]
    for o, n in zip(obs, names or []):
        o["name"] = n
    path.write_text(json.dumps({"obstacles": obs}))
    return str(path)


def test_bad_maps_and_starts_exit_2_one_line(capsys, tmp_path):
    """Map contents and start poses refused before anything is simulated, one line naming the flag and key."""
    box = [(1.0, 1.0), (2.0, 1.0), (2.0, 2.0), (1.0, 2.0)]
    far = [(5.0, 1.0), (6.0, 1.0), (6.0, 2.0), (5.0, 2.0)]
    ring = [(30 * math.cos(a), 30 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 20_000, endpoint=False)]
    (tmp_path / "latin1.toml").write_bytes('name = "caf\xe9"\n'.encode("latin-1"))
    (tmp_path / "folder.json").mkdir()
    cases = [
        (
            [
                "parking",
                "--map",
                _poly_file(tmp_path / "dup.json", [box, far], ["kerb", "kerb"]),
                "--x0",
                "0",
                "0",
                "0",
            ],
            "--map: obstacles[1].name: duplicate obstacle name 'kerb' (also obstacles[0])",
        ),
        (
            ["parking", "--map", _poly_file(tmp_path / "dflt.json", [far, box], ["obstacle_1"]), "--x0", "0", "0", "0"],
            "--map: obstacles[1].name: missing, and the default name 'obstacle_1' is taken by obstacles[0]",
        ),
        (
            ["parking", "--map", str(tmp_path / "latin1.toml"), "--x0", "0", "0", "0"],
            f"--map: {tmp_path / 'latin1.toml'}: not UTF-8 text (byte 0xe9 at offset 11",
        ),
        (
            ["parking", "--map", str(tmp_path / "folder.json"), "--x0", "0", "0", "0"],
            f"--map: {tmp_path / 'folder.json'}: is a directory",
        ),
        (
            [
                "parking-search",
                "--method",
                "grid",
                "--map",
                _poly_file(tmp_path / "ring.json", [ring]),
                "--x0",
                "0",
                "0",
                "0",
            ],
            f"--map: obstacles[0].vertices: at most {MAX_VERTICES} vertices per polygon, got 20000",
        ),
        (["parking", "--x0", "0", "0", "60"], "--x0: the robot's body at the start pose overlaps obstacle 'kerb'"),
        (
            ["parking", "--x0", "0", "0.3", "0", "--front", "0.53"],
            "--x0: the robot's body at the start pose overlaps obstacle 'car_ahead'",
        ),
        (
            ["parking-search", "--method", "ga", "--x0", "-0.7", "0.6", "40"],
            "--x0: the robot's body at the start pose overlaps obstacle 'wall_left'",
        ),
    ]
    for args, msg in cases:
        rc, out, err = run_cli(capsys, *args, "--json")
        assert rc == 2 and out == "", (args, err)
        assert err.count("\n") == 1 and err.startswith(f"pfjax {args[0]}: error: {msg}"), (args, err)


def test_grid_search_against_brute_force(capsys):
    rc, out, _ = run_cli(capsys, "parking-search", "--method", "grid", "--n", "2", "--json")
    o = strict(out)
    assert rc == 0 and o["n_simulations"] == 8 and {"xs", "alpha1", "alpha2", "time_s"} <= set(o)
    xl, al = lattice(2)
    scores = {(x, a1, a2): _single_fitness(x, a1, a2) for x in xl for a1 in al for a2 in al}
    best = max(scores, key=scores.get)
    assert (o["xs"], o["alpha1"], o["alpha2"]) == pytest.approx(best)
    assert o["fitness"] == pytest.approx(scores[best], rel=1e-9)


def _single_fitness(xs, a1, a2):
    r = run_jit(run_params((-0.9, 0.6, -85.0), 1, (1.0, a1, a2), xs=xs), GMAP, SEARCH_CONFIG)
    return float(fitness(np.asarray(r.status), np.asarray(r.time), np.asarray(r.error)))


def test_ga_search_counts_and_resimulates(capsys):
    rc, out, _ = run_cli(
        capsys, "parking-search", "--method", "ga", "--population", "5", "--generations", "2", "--seed", "3", "--json"
    )
    o = strict(out)
    assert rc == 0 and o["n_simulations"] == 5 + 2 * (5 - 1)  # P + G (P - E)
    assert o["fitness"] == pytest.approx(_single_fitness(o["xs"], o["alpha1"], o["alpha2"]), rel=1e-9)
    h = o["history_best_fitness"]
    assert h[-1] == pytest.approx(o["fitness"]) and np.all(np.diff(h) >= 0)
    assert len(o["bits"]) == 24


@pytest.mark.slow
def test_study_quick(tmp_path):
    import runpy

    study = runpy.run_path(str(ROOT / "studies" / "parking.py"))  # in-process: reuses this process's compilations
    out = tmp_path / "parking"
    assert study["main"](["--quick", "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert len(s["config_sha256"]) == 64 and s["pfjax_version"] and s["seed"] == 0
    assert numbers_without_units(s) == []  # every number of summary.json has its unit
    u = s["units"]
    assert u["a_f"] == u["error"] == u["xs"] == "m" and u["time_s"] == "s" and u["fitness"] == "1/s"
    assert {"front", "scan_period", "pause"} <= set(u)  # all_four_reproduced's combinations (none in quick mode)
    cases = pd.read_parquet(out / "cases.parquet")
    assert list(cases["case"][:4]) == ["A", "B", "C", "D"] and len(cases) == 7
    assert {"status", "switches", "time_s"} <= set(cases.columns)
    mc = pd.read_parquet(out / "montecarlo.parquet")
    assert len(mc) == 3 * s["config"]["montecarlo"]["n_runs"]
    from pfjax.parking.study import TABLES
    from pfjax.tables import units

    for name in TABLES:  # every column of every table carries its unit and description
        path = out / f"{name}.parquet"
        described = units(path)
        assert set(described) == set(pd.read_parquet(path).columns), name
        assert all(d["description"] for d in described.values()), name
    for f in ("cases_parallel", "garage_xs", "search", "start_map", "montecarlo", "histories_D"):
        assert (out / "figures" / f"{f}.png").stat().st_size > 1000 and (out / "figures" / f"{f}.svg").exists()
    md, page = (out / "report.md").read_text(), (out / "report.html").read_text()
    html = unescape(page)  # the page's text, entities decoded (pfjax's, not pfjax&#x27;s)
    headline = [f"a_f = {s['calibration']['a_f']:.4f} m", f"{s['assumptions']['n_combinations']} combinations"]
    headline += [f"{100 * r['success_rate']:.1f} %" for r in s["montecarlo"].values()]
    headline += [v["claim"] for v in s["verdicts"]]
    for text in headline:  # the report's Markdown and HTML carry the summary's numbers
        assert text in md and text in html, text
    bad = subprocess.run(
        [
            sys.executable,
            str(ROOT / "studies" / "parking.py"),
            "--set",
            "sim.scan_perod=0.1",
            "--out",
            str(tmp_path / "bad"),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "sim.scan_perod" in bad.stderr
    assert not (tmp_path / "bad").exists()
