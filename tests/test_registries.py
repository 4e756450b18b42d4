"""One registry per concept: a controller and a path registered by a plugin module
(tests/plugins/dummy_plugin.py) run through single runs, a study, tuning and the command line,
with no other file edited; the registries are what config literals, command-line choices, tuning
boxes and plot styles are read from."""

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pfjax import controllers as C
from pfjax import paths

PLUGINS = Path(__file__).parent / "plugins"


@pytest.fixture(scope="module")
def dummy():
    """Register the plugin's entries for this module's tests, and remove them afterwards."""
    sys.path.insert(0, str(PLUGINS))
    try:
        mod = importlib.reload(importlib.import_module("dummy_plugin"))
        yield mod
    finally:
        C.REGISTRY.pop("dummy_heading", None)
        paths.PATHS.pop("gentle", None)
        sys.path.remove(str(PLUGINS))


def test_registries_drive_names():
    """Config types, command-line choices and tuning boxes come from the registries."""
    from pfjax.cli import build_parser
    from pfjax.tuning.problem import scenario_sets

    assert set(C.controller_types()) == set(C.REGISTRY) | set(C.DESIGNS)
    assert {"lmi", "paper_k", "integral_lmi", "pi", "integral", "stanley"} <= set(C.controller_types())
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    sim = {a.dest: a for a in sub["simulate"]._actions}
    assert list(sim["controller"].choices) == C.cli_names()
    assert list(sim["path"].choices) == paths.fixed_paths()
    assert paths.source_tests() == ("line", "parabola", "sine")
    assert {"paper-line", "paper-all", "circle"} <= set(scenario_sets())
    for name, e in C.REGISTRY.items():
        flat = C.flat_gains(e)
        assert set(e.gains) <= set(flat), name
        again = C.flat_gains(e, C.params_from_flat(e, flat))
        assert again.keys() == flat.keys() and np.allclose(list(again.values()), list(flat.values()), rtol=1e-6), name


def test_unknown_names_are_one_line_errors():
    from pfjax.errors import InputError
    from pfjax.montecarlo.config import load_study

    with pytest.raises(InputError, match="controller: unknown controller 'nope'"):
        C.resolve("nope")
    with pytest.raises(InputError, match="path: unknown path 'nope'"):
        paths.entry("nope")
    base = {
        "name": "x",
        "n_runs": 1,
        "seed": 0,
        "paths": [{"kind": "line"}],
        "controllers": [{"name": "a", "type": "pi"}],
    }
    with pytest.raises(InputError, match=r"controllers\[0\]\.type.*unknown controller type 'nope'"):
        load_study(data={**base, "controllers": [{"name": "a", "type": "nope"}]})
    with pytest.raises(InputError, match=r"paths\[0\]\.kind.*unknown path kind 'nope'"):
        load_study(data={**base, "paths": [{"kind": "nope"}]})
    with pytest.raises(InputError, match=r"K is only for types with a vector gain"):
        load_study(data={**base, "controllers": [{"name": "a", "type": "pi", "K": [1, 2]}]})


def test_dummy_single_run(dummy):
    from pfjax.sim import SimConfig, simulate_batch, stack, unstack
    from pfjax.sim.scenario import paper_scenario

    e = C.entry("dummy_heading")
    assert e.cli_name == "dummy-heading" and e.gains == ("k_d", "k_h")
    sc = paper_scenario("gentle", e.make_params(), beta_r_deg=2.0, beta_f_deg=2.0)
    r = unstack(simulate_batch(stack([sc]), controller=e.controller, config=SimConfig(horizon=15.0, record=False)), 0)
    assert int(r.status) == 0 and abs(float(r.final.d)) < 0.05  # converges onto the gentle sine
    with pytest.raises(ValueError, match="gains.k_x: unknown gain"):
        e.make_params(k_x=1.0)


def test_dummy_study(dummy, tmp_path):
    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.study import run

    data = {
        "name": "dummy",
        "n_runs": 16,
        "seed": 3,
        "chunk_size": 16,
        "f64_check_runs": 0,
        "sim": {"horizon": 6.0, "steady_window": 2.0},
        "success": {"from_s": 4.0, "band": 0.2},
        "margin": {"enabled": False},
        "initial": {"lateral_offset": {"dist": "uniform", "low": -0.1, "high": 0.1}},
        "paths": [{"kind": "gentle"}, {"kind": "sine"}],
        "controllers": [
            {"name": "dummy", "type": "dummy_heading", "gains": {"k_h": -2.0}},
            {"name": "sf", "type": "paper_k"},
        ],
    }
    spec, _ = load_study(data=data)
    summary = run(spec, tmp_path / "out", progress=False, report=True)
    runs = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    assert len(runs) == 16 * 2 * 2 and set(runs.path) == {"gentle", "sine"}
    assert summary["controllers"]["dummy"]["gains"] == {"k_d": -1.5, "k_h": -2.0}
    assert summary["controllers"]["sf"]["gains"] == {"k_d": C.PAPER_K[0], "k_theta": C.PAPER_K[1]}
    assert (runs[runs.controller == "dummy"].status == "ok").all()
    html = (tmp_path / "out" / "report.html").read_text()
    assert "a gentle sine (test plugin)" in html and "dummy heading" in html


def test_dummy_tune(dummy):
    import jax

    from pfjax.sim import SimConfig
    from pfjax.tuning.problem import make_problem, tune

    pr = make_problem("dummy_heading", "gentle", config=SimConfig(dt=0.01, horizon=5.0, record=False))
    assert pr.lower.tolist() == [-6.0, -6.0] and pr.upper.tolist() == [0.0, 0.0]
    res = tune(pr, "gradient", key=jax.random.PRNGKey(0), steps=5)
    assert np.isfinite(res.cost) and np.all((res.theta >= -6.0) & (res.theta <= 0.0))


def test_dummy_through_the_command_line(tmp_path):
    """A subprocess: ``PFJAX_PLUGINS`` imports the plugin before the command line reads its registries."""
    env = {
        **os.environ,
        "PFJAX_PLUGINS": "dummy_plugin",
        "PYTHONPATH": os.pathsep.join([str(PLUGINS), os.environ.get("PYTHONPATH", "")]),
    }
    cli = [sys.executable, "-m", "pfjax.cli"]
    out = subprocess.run(
        cli
        + [
            "simulate",
            "--path",
            "gentle",
            "--controller",
            "dummy-heading",
            "--gains",
            "k_h=-2",
            "--horizon",
            "5",
            "--json",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["gains"] == {"k_d": -1.5, "k_h": -2.0} and r["metrics"]["status"] == "ok"
    out = subprocess.run(
        cli
        + [
            "tune",
            "--method",
            "gradient",
            "--controller",
            "dummy-heading",
            "--scenario",
            "gentle",
            "--steps",
            "3",
            "--horizon",
            "4",
            "--json",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert set(json.loads(out.stdout)["gains"]) >= {"k_d", "k_h"}
    bad = subprocess.run(
        cli + ["simulate", "--help"],
        env={**env, "PFJAX_PLUGINS": "no_such_plugin"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "PFJAX_PLUGINS" in bad.stderr


def test_study_names_the_polytopic_integral_design():
    """A study's controller ``type = "polytopic_integral_lmi"`` (``polytopic-integral`` on the command
    line) runs the integral controller with the gain of pfjax.synthesis.polytopic_mixed over the
    polytope v in [0.8, 1.2] m/s, |beta_r| <= 10 deg at L = 0.2 m (the same LMI solve: 1e-9)."""
    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.runner import controller_of
    from pfjax.synthesis import polytopic_mixed

    spec, _ = load_study(
        studies_rare_events(), overrides=["controllers=[{name='poly', type='polytopic_integral_lmi'}]"]
    )
    _, _, flat = controller_of(spec.controllers[0], spec, 0)
    K = polytopic_mixed((0.8, 1.2), 10.0, 0.2, integral=True).K.ravel()
    assert [flat[k] for k in ("k_d", "k_theta", "k_i")] == pytest.approx(list(K), rel=1e-9)
    assert C.resolve("polytopic-integral")[1] is C.resolve("polytopic_integral_lmi")[1]
    assert C.resolve("polytopic-integral")[0].name == "integral"
    names = [c.type for c in load_study(studies_rare_events())[0].controllers]
    assert "polytopic_integral_lmi" in names


def studies_rare_events() -> Path:
    return Path(__file__).resolve().parents[1] / "studies" / "rare_events.toml"
