"""Each parking default has one home, :mod:`pfjax.parking.defaults`: the simulator, the searches, the
entry points' signatures, the study's schema and shipped config, and the command line's flags and
help all read it, and its literal is written nowhere else in pfjax/parking or pfjax/cli/parking.py."""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import tokenize
from pathlib import Path

import pytest

from pfjax.cli import main
from pfjax.cli import parking as cli_parking
from pfjax.parking import api
from pfjax.parking import defaults as D
from pfjax.parking.study_config import ParkingStudy, load

ROOT = Path(__file__).resolve().parents[1]
FILES = sorted(p for p in (ROOT / "pfjax" / "parking").glob("*.py") if p.name != "defaults.py") + [
    ROOT / "pfjax" / "cli" / "parking.py"
]

#: the argument, field or flag names that carry each default, with its value
NAMED = {
    "k1": D.K1,
    "k2": D.K2,
    "speed": D.SPEED,
    "kp": D.KP,
    "ki": D.KI,
    "width": D.L1_WIDTH,
    "length": D.L2_LENGTH,
    "scan_period": D.SCAN_PERIOD,
    "t_max": D.T_MAX,
    "horizon": D.T_MAX,
    "tol": D.TOL,
    "n_sub": D.N_SUB,
    "stuck_switches": D.STUCK_SWITCHES,
    "stuck_travel": D.STUCK_TRAVEL,
    "chunk": D.CHUNK,
    "xs": D.GARAGE_XS,
    "weight": D.WEIGHT,
    "n": D.GRID_N,
    "grid_n": D.GRID_N,
    "population": D.POPULATION,
    "generations": D.GENERATIONS,
    "max_switches": D.SEARCH_MAX_SWITCHES,
    "pause": D.EXPERIMENT_PAUSE,
}
#: defaults whose literal is distinctive enough to appear in the code only in their home
DISTINCT = {
    "K1": D.K1,
    "K2": D.K2,
    "SPEED": D.SPEED,
    "KI": D.KI,
    "L1_WIDTH": D.L1_WIDTH,
    "L2_LENGTH": D.L2_LENGTH,
    "T_MAX": D.T_MAX,
    "TOL": D.TOL,
    "WEIGHT": D.WEIGHT,
    "CHUNK": D.CHUNK,
}
#: the same number with another meaning: case D's gain factor alpha = 8 (pfjax.parking.schedules.CASES)
OTHER_MEANING = {("schedules.py", 8.0)}


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="pfjax")
    cli_parking.register(ap.add_subparsers(dest="command"))
    return ap


def _defaults(fn) -> dict:
    return {k: p.default for k, p in inspect.signature(fn).parameters.items()}


def test_the_api_the_simulator_the_schema_and_the_cli_read_the_one_default():
    from pfjax.parking.calibrate import case_a_pose
    from pfjax.parking.geometry import robot_shape
    from pfjax.parking.model import control_params
    from pfjax.parking.montecarlo import Scatter
    from pfjax.parking.runs import ParkingConfig, run_params
    from pfjax.parking.schedules import CASES
    from pfjax.parking.switch_search import search_ga, search_grid

    controller = {"k1": D.K1, "k2": D.K2, "speed": D.SPEED}
    run_settings = {**controller, "scan_period": D.SCAN_PERIOD, "t_max": D.T_MAX}
    for fn in (api.run, api.search):
        got = _defaults(fn)
        assert {k: got[k] for k in run_settings} == run_settings, fn.__name__
    assert _defaults(api.search)["weight"] == D.WEIGHT
    assert api.SEARCH_DEFAULTS == {"n": D.GRID_N, "generations": D.GENERATIONS, "population": D.POPULATION, "seed": 0}
    assert (api.DEFAULT_SCAN_PERIOD, api.GARAGE_XS) == (D.SCAN_PERIOD, D.GARAGE_XS)

    c = control_params()
    assert [float(v) for v in (c.k1, c.k2, c.speed, c.kp, c.ki)] == [D.K1, D.K2, D.SPEED, D.KP, D.KI]
    pc = ParkingConfig()
    assert (pc.t_max, pc.tol, pc.n_sub, pc.stuck_switches, pc.stuck_travel) == (
        D.T_MAX,
        D.TOL,
        D.N_SUB,
        D.STUCK_SWITCHES,
        D.STUCK_TRAVEL,
    )
    p = run_params(CASES["A"]["x0"])
    assert float(p.scan_period) == D.SCAN_PERIOD
    assert (float(p.shape.width), float(p.shape.length)) == (D.L1_WIDTH, D.L2_LENGTH)
    assert _defaults(robot_shape)["width"] == D.L1_WIDTH and _defaults(robot_shape)["length"] == D.L2_LENGTH
    a = _defaults(case_a_pose)
    assert (a["x0"], a["y0"], 0.0) == CASES["A"]["x0"] and (a["k1"], a["k2"]) == (D.K1, D.K2)
    assert _defaults(search_grid)["n"] == D.GRID_N and _defaults(search_grid)["weight"] == D.WEIGHT
    assert _defaults(search_ga)["weight"] == D.WEIGHT

    s = ParkingStudy()
    assert s.controller.model_dump() == controller
    assert (s.sim.scan_period, s.sim.t_max, s.sim.tol, s.sim.n_sub, s.sim.chunk) == (
        D.SCAN_PERIOD,
        D.T_MAX,
        D.TOL,
        D.N_SUB,
        D.CHUNK,
    )
    assert (s.sim.stuck_switches, s.sim.stuck_travel) == (D.STUCK_SWITCHES, D.STUCK_TRAVEL)
    se = s.search
    assert (se.weight, se.population, se.generations, se.grid_n, se.max_switches) == (
        D.WEIGHT,
        D.POPULATION,
        D.GENERATIONS,
        D.GRID_N,
        D.SEARCH_MAX_SWITCHES,
    )
    assert s.montecarlo.model_dump(exclude={"n_runs"}) == dataclasses.asdict(Scatter())
    keys = {"fronts": "front", "zones": "zone", "scan_periods": "scan_period"}
    keys |= {"decision_delays": "decision_delay", "lags": "lag", "pauses": "pause"}
    assert {k: tuple(v) for k, v in s.assumptions.model_dump().items()} == {
        k: D.ASSUMPTION_GRID[g] for k, g in keys.items()
    }
    assert tuple(s.garage.xs_values) == D.GARAGE_TRIES and s.experiment.pause == D.EXPERIMENT_PAUSE
    # the shipped config is the schema's defaults
    assert load(ROOT / "studies" / "parking.toml") == s

    ap = _parser()
    for command in (["parking"], ["parking-search", "--method", "grid"]):
        args = vars(ap.parse_args(command))
        assert {k: args[k] for k in controller} == controller
        assert (args["scan_period"], args["horizon"]) == (D.SCAN_PERIOD, D.T_MAX)
    assert ap.parse_args(["parking-search", "--method", "ga"]).weight == D.WEIGHT


def test_zones_of_the_sweep_are_the_simulated_ones():
    from pfjax.parking.assumptions import DEFAULT_GRID, ZONES

    assert tuple(DEFAULT_GRID["zone"]) == D.ASSUMPTION_GRID["zone"] == tuple(ZONES)


@pytest.mark.parametrize("command", ["parking", "parking-search"])
def test_help_prints_the_defaults(capsys, command):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr()[0].split())
    for flag, value in (("k1", D.K1), ("k2", D.K2), ("speed", D.SPEED), ("scan-period", D.SCAN_PERIOD)):
        assert f"(default {value:g})" in text.split(f"--{flag} ")[-1].split(" --")[0], flag
    assert f"timeout, s (default {D.T_MAX:g})" in text
    assert f"(kP {D.KP:g}, kI {D.KI:g} 1/s)" in text
    if command == "parking-search":
        assert f"(default {D.WEIGHT:g})" in text and f"levels per parameter (default {D.GRID_N})" in text


def _numbers(path: Path):
    """(line, value) of every number in the code of ``path`` (strings and comments left out), a
    unary minus applied."""
    toks = list(tokenize.generate_tokens(io.StringIO(path.read_text()).readline))
    for i, t in enumerate(toks):
        if t.type == tokenize.NUMBER:
            v = ast.literal_eval(t.string)
            yield t.start[0], -v if i and toks[i - 1].string == "-" else v


def test_a_distinctive_default_literal_is_written_only_in_its_home():
    for name, value in DISTINCT.items():
        assert sum(1 for _, v in _numbers(ROOT / "pfjax" / "parking" / "defaults.py") if v == value) >= 1, name
    found = [
        f"{path.name}:{line}: {v!r} ({name})"
        for path in FILES
        for line, v in _numbers(path)
        for name, value in DISTINCT.items()
        if v == value and type(v) is type(value) and (path.name, v) not in OTHER_MEANING
    ]
    assert not found, "defaults written again instead of read from pfjax.parking.defaults:\n" + "\n".join(found)


def _literal(node) -> float | int | None:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        v = _literal(node.operand)
        return None if v is None else -v
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return node.value
    return None


def _named_defaults(tree):
    """(name, literal) of each default written as a number: a parameter's default, a class field's
    value (or its ``Field(...)``'s first argument) and an ``add_argument(..., default=...)``."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            a = node.args
            pos = a.posonlyargs + a.args
            for arg, d in zip(pos[len(pos) - len(a.defaults) :], a.defaults):
                yield arg.arg, _literal(d)
            for arg, kd in zip(a.kwonlyargs, a.kw_defaults):
                if kd is not None:
                    yield arg.arg, _literal(kd)
        elif isinstance(node, ast.ClassDef):
            for stmt in node.body:
                if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name) and stmt.value is not None:
                    v = stmt.value
                    if isinstance(v, ast.Call) and getattr(v.func, "id", "") == "Field" and v.args:
                        v = v.args[0]
                    yield stmt.target.id, _literal(v)
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument":
            flag = next((a.value for a in node.args if isinstance(a, ast.Constant)), "")
            for kw in node.keywords:
                if kw.arg == "default":
                    yield flag.lstrip("-").replace("-", "_"), _literal(kw.value)


def test_no_argument_field_or_flag_writes_its_default_as_a_literal():
    found = [
        f"{path.name}: {name} = {v!r}"
        for path in FILES
        for name, v in _named_defaults(ast.parse(path.read_text()))
        if v is not None and name in NAMED and v == NAMED[name]
    ]
    assert not found, "defaults written again instead of read from pfjax.parking.defaults:\n" + "\n".join(found)
