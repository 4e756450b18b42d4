"""The paper reproduction's config and wiring: bad ``[model]`` and ``[source]`` values named at load
(one line, exit 2, nothing written), the direction of travel along the source's paths
(``model.direction``: the registered scenarios by default, the mirror image on the line the other
way) and the units of every number in ``summary.json``."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from units_check import numbers_without_units

from pfjax import controllers as C
from pfjax.config import ConfigError
from pfjax.reproduce import paper_runs
from pfjax.reproduce.paper_config import PaperStudy, load, sim_config
from pfjax.sim import unstack
from pfjax.sim.scenario import PAPER_TESTS, paper_scenario

ROOT = Path(__file__).resolve().parents[1]
STUDY = ROOT / "studies" / "paper_reproduction.py"


def _config(**model) -> dict:
    cfg = PaperStudy().model_dump(mode="json")
    cfg["model"].update(model)
    return cfg


# ------------------------------------------------------------ checks at load


@pytest.mark.parametrize(
    "setting, key",
    [
        ("source.line_ss_pi_mm=0", "source.line_ss_pi_mm"),  # the PI's claim divides by it
        ("source.line_ss_pi_mm=-8", "source.line_ss_pi_mm"),
        ("source.line_ss_mixed_mm_below=0", "source.line_ss_mixed_mm_below"),
        ("source.K=[0, 0]", "source.K"),  # no stabilising gain: the certificate of it is infeasible
        ("source.K=[1, 1]", "source.K"),
        ("source.K=[-1, 0.5]", "source.K"),
        ("source.K=[-1e-9, -1e-9]", "source.K"),  # stabilising, but no LMI certificate at this scale
        ("source.gamma_inf=0", "source.gamma_inf"),  # the relative differences divide by them
        ("source.gamma_2=-4.07", "source.gamma_2"),
        ("source.eig_max_re=[0, -5.193]", "source.eig_max_re"),
        ("source.line_delta_deg=90", "source.line_delta_deg"),
        ("model.delta_max_deg=0", "model.delta_max_deg"),  # make_scenario's range: (0, 90)
        ("model.delta_max_deg=-10", "model.delta_max_deg"),
        ("model.v=1e9", "synthesis"),  # no mixed design at this speed
        ("model.direction='sideways'", "model.direction"),
    ],
)
def test_bad_model_and_source_values_are_named_at_load(setting, key):
    with pytest.raises(ConfigError) as e:
        load(None, [setting])
    msg = str(e.value)
    assert len(msg.splitlines()) == 1 and msg.startswith(key + ":"), msg
    if key == "synthesis":
        assert "model.v = 1e+09 m/s" in msg and "model.L" in msg, msg


def test_a_bad_source_value_exits_2_before_any_work(tmp_path):
    """One line naming the key, exit code 2, and no results/ folder left in the working directory."""
    r = subprocess.run(
        [sys.executable, str(STUDY), "--quick", "--set", "source.line_ss_pi_mm=0"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert r.returncode == 2, r.stderr[-2000:]
    assert r.stderr.strip().splitlines() == ["paper_reproduction: error: source.line_ss_pi_mm: must be > 0 (got 0)"], (
        r.stderr
    )
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------ model.direction


def test_increasing_x_runs_the_registered_scenarios():
    """The default direction builds exactly the scenarios :func:`pfjax.sim.scenario.paper_scenario`
    builds: the study's numbers do not depend on the key being there."""
    cfg = _config()
    m = cfg["model"]
    gains = C.state_feedback_params(C.PAPER_K)
    for test in PAPER_TESTS:
        ours = paper_runs.source_scenario(paper_runs.source_test(test, "increasing_x"), gains, cfg)
        kw = {k: m[k] for k in ("beta_r_deg", "beta_f_deg", "v", "L", "delta_max_deg", "convention")}
        ref = paper_scenario(test, gains, **kw)
        a, b = jax.tree_util.tree_leaves(ours), jax.tree_util.tree_leaves(ref)
        assert jax.tree_util.tree_structure(ours) == jax.tree_util.tree_structure(ref)
        assert all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, b)), test


def _run(test: str, cfg: dict, horizon: float) -> dict:
    config = sim_config(cfg, horizon=horizon, dt=0.01)
    r = unstack(paper_runs.run_batch(C.state_feedback, [C.state_feedback_params(C.PAPER_K)], test, cfg, config), 0)
    assert int(r.status) == 0
    return paper_runs.to_world(paper_runs.traj_dict(r), paper_runs.source_test(test, cfg["model"]["direction"]))


def test_the_line_the_other_way_is_the_mirror_image():
    """Towards decreasing x under the opposite slip, the line test is the forward run mirrored in
    the path's normal through the start's closest point (0.5, 0.5): the same |d| at every step, d
    and theta_e of opposite sign, (x, y) -> (1 - y, 1 - x)."""
    fwd = _run("line", _config(beta_r_deg=5.0, beta_f_deg=5.0), 6.0)
    back = _run("line", _config(beta_r_deg=-5.0, beta_f_deg=-5.0, direction="decreasing_x"), 6.0)
    assert fwd["d"][0] == pytest.approx(-1 / math.sqrt(2))
    np.testing.assert_allclose(np.abs(back["d"]), np.abs(fwd["d"]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["d"], -fwd["d"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["theta_e"], -fwd["theta_e"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["delta"], -fwd["delta"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["x"], 1 - fwd["y"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back["y"], 1 - fwd["x"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.cos(back["theta"]), -np.sin(fwd["theta"]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("test", PAPER_TESTS)
def test_the_other_way_starts_at_the_same_point_mirrored(test):
    """Every source test towards decreasing x starts where the registered one starts, with its
    lateral and heading errors of opposite sign, and moves towards decreasing x."""
    fwd = _run(test, _config(), 1.0)
    back = _run(test, _config(direction="decreasing_x"), 1.0)
    assert (back["x"][0], back["y"][0]) == pytest.approx((fwd["x"][0], fwd["y"][0]), abs=1e-12)
    assert back["d"][0] == pytest.approx(-fwd["d"][0], abs=1e-9)
    assert back["theta_e"][0] == pytest.approx(-fwd["theta_e"][0], abs=1e-9)
    st = paper_runs.source_test(test, "decreasing_x")
    assert back["x"][-1] < back["x"][0] and st.path.u_min < back["x"][-1]
    # as much path ahead as towards increasing x
    ahead = paper_runs.fixed_path(test).u_max - st.u0
    assert float(st.u0 - st.path.u_min) == pytest.approx(float(ahead))


# ------------------------------------------------------------ the whole study, the other way


@pytest.fixture(scope="module")
def decreasing_run(tmp_path_factory) -> Path:
    """studies/paper_reproduction.py --quick towards decreasing x at tiny sizes, through the script's
    own ``main`` in this process."""
    import importlib.util

    out = tmp_path_factory.mktemp("paper") / "decreasing_x"
    sizes = ["ga.population=2", "ga.generations=1", "ga.seeds=1", "stability.eig_n=3", "stability.n=2"]
    args = ["--quick", "--out", str(out), "--set", "model.direction='decreasing_x'"]
    for s in sizes:
        args += ["--set", s]
    spec = importlib.util.spec_from_file_location("paper_reproduction_script", STUDY)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert script.main(args) == 0
    return out


def test_every_number_in_summary_json_has_a_unit(decreasing_run):
    summary = json.loads((decreasing_run / "summary.json").read_text())
    assert numbers_without_units(summary) == []
    units = summary["units"]
    assert units["steady_abs_d"] == "m" and units["steady_abs_d_mm"] == "mm" and units["max_re_slow"] == "1/s"


def test_the_study_runs_towards_decreasing_x(decreasing_run):
    summary = json.loads((decreasing_run / "summary.json").read_text())
    assert summary["config"]["model"]["direction"] == "decreasing_x"
    assert {r["status"] for r in summary["runs"]} == {"ok"}
    assert {p.stem for p in (decreasing_run / "figures").glob("tracking_*.png")} == {
        f"tracking_{t}" for t in PAPER_TESTS
    }
