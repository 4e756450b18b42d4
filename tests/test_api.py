"""The public API (pfjax.__all__, pfjax.api): vectorised scenarios against single scenarios built
by hand, gains in every accepted form, the success interval against SciPy, studies run, loaded and
replayed, tuning and falsification, one-line errors naming the argument, the README's script, and
host set-up (a cheap import; a warning when JAX started first)."""

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pytest

import pfjax
from pfjax.sim import STATUS_NAMES, SimConfig

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"horizon": 4.0, "dt": 0.01, "steady_window": 1.0}


def test_all_names_resolve():
    for name in pfjax.__all__:
        assert getattr(pfjax, name) is not None, name
    for name in ("design_mixed", "scenarios", "simulate", "run_study", "load_study", "tune", "falsify"):
        assert getattr(pfjax, name).__doc__, name
    assert callable(pfjax.parking.run) and callable(pfjax.tracking.run)


def test_scenarios_numbers_arrays_distributions():
    n = 40
    br = np.linspace(-6, 6, n)
    a = pfjax.scenarios(
        "sine",
        n,
        beta_r_deg=br,
        beta_f_deg=pfjax.uniform(-3, 3),
        lateral_offset=0.1,
        heading_error_deg=pfjax.normal(0, 2),
        key=7,
    )
    t = a.table
    assert a.n == n and np.allclose(t.beta_r_deg, br) and (t.lateral_offset == 0.1).all()
    assert t.beta_f_deg.between(-3, 3).all() and t.beta_f_deg.std() > 0.5
    # the first runs of a larger batch are the same runs; another key draws others
    b = pfjax.scenarios(
        "sine",
        2 * n,
        beta_r_deg=np.concatenate([br, br]),
        beta_f_deg=pfjax.uniform(-3, 3),
        lateral_offset=0.1,
        heading_error_deg=pfjax.normal(0, 2),
        key=7,
    )
    np.testing.assert_array_equal(b.table.beta_f_deg[:n], t.beta_f_deg)
    c = pfjax.scenarios("sine", n, beta_f_deg=pfjax.uniform(-3, 3), key=8)
    assert not np.allclose(c.table.beta_f_deg, t.beta_f_deg)
    # a JAX key is accepted too, and a study-config dict as a distribution
    d = pfjax.scenarios("line", 8, beta_r_deg={"dist": "choice", "values": [-2, 2]}, key=jax.random.PRNGKey(3))
    assert set(d.table.beta_r_deg) <= {-2.0, 2.0}


def test_an_int_seed_draws_a_studys_runs_and_a_key_folds_in_the_run():
    """scenarios(key=s) draws run i from fold_in(fold_in(seed_key(s), 0), i), the runs of a study with
    seed s on its first path; a key k draws run i from fold_in(k, i) (the docstring's contract)."""
    from pfjax.numerics.random import seed_key

    kw = dict(lateral_offset=pfjax.uniform(-0.1, 0.1), heading_error_deg=pfjax.normal(0, 2))
    by_seed = pfjax.scenarios("sine", 6, key=5, **kw).table
    by_key = pfjax.scenarios("sine", 6, key=jax.random.fold_in(seed_key(5), 0), **kw).table
    pd.testing.assert_frame_equal(by_seed, by_key)
    other = pfjax.scenarios("sine", 6, key=jax.random.key(5), **kw).table
    assert not np.allclose(other.lateral_offset, by_seed.lateral_offset)


def test_scenario_matches_one_built_by_hand():
    """Run i of pfjax.scenarios equals make_scenario with the start pose computed independently:
    offset along the path normal at the nominal start, heading = tangent + error."""
    from pfjax.paths import entry
    from pfjax.sim import simulate_batch, stack, unstack
    from pfjax.sim.scenario import make_scenario
    from pfjax.sim.slip_profiles import constant_slip

    a = pfjax.scenarios(
        "sine",
        3,
        beta_r_deg=[2.0, -4.0, 6.0],
        beta_f_deg=1.0,
        lateral_offset=[0.0, 0.1, -0.2],
        heading_error_deg=[0.0, 5.0, -10.0],
        speed=[1.0, 0.8, 1.2],
    )
    sim = pfjax.simulate(a, "pi", config=SHORT)
    path = entry("sine").build()
    for i, row in a.table.iterrows():
        th = math.atan(1.0)  # y = sin x at x = 0: slope cos 0 = 1
        pose = (
            -row.lateral_offset * math.sin(th),
            row.lateral_offset * math.cos(th),
            th + math.radians(row.heading_error_deg),
        )
        sc = make_scenario(
            path,
            pose,
            pfjax.controllers.entry("pi").make_params(),
            v=row.speed,
            slip=constant_slip(math.radians(row.beta_r_deg), math.radians(row.beta_f_deg)),
        )
        ref = unstack(
            simulate_batch(stack([sc]), controller=pfjax.controllers.pi, config=SimConfig(**SHORT, record=False)), 0
        )
        assert sim.table.iae[i] == pytest.approx(float(ref.metrics.iae), rel=1e-9), i


def test_gains_in_every_form_agree():
    design = pfjax.design_mixed(v=1.0, L=0.2)
    a = pfjax.scenarios("sine", 32, beta_r_deg=pfjax.uniform(-5, 5), beta_f_deg=pfjax.uniform(-5, 5), key=1)
    k = design.K.ravel()
    forms = [design, {"k_d": k[0], "k_theta": k[1]}, pfjax.controllers.state_feedback_params(k)]
    tables = [pfjax.simulate(a, "state_feedback", gains=g, config=SHORT).table for g in forms]
    lmi = pfjax.simulate(a, "lmi", config=SHORT)  # the design by name, at the runs' mean speed and wheelbase
    for t in tables[1:] + [lmi.table]:
        np.testing.assert_allclose(t.iae, tables[0].iae, rtol=1e-12)
    assert lmi.gains == pytest.approx({"k_d": k[0], "k_theta": k[1]}, rel=1e-6)


def test_success_rate_interval_is_clopper_pearson():
    from scipy import stats

    s = np.r_[np.ones(37, bool), np.zeros(13, bool)]
    r = pfjax.success_rate(s)
    assert (r.k, r.n, r.rate) == (37, 50, 0.74)
    assert r.lo == pytest.approx(stats.beta.ppf(0.025, 37, 14), rel=1e-9)
    assert r.hi == pytest.approx(stats.beta.ppf(0.975, 38, 13), rel=1e-9)
    assert "74.0 % of 50 runs" in str(r)


@pytest.mark.parametrize(
    "call, key",
    [
        (lambda: pfjax.scenarios("sine", 4, beta_r_deg=95.0), "beta_r_deg"),
        (lambda: pfjax.scenarios("sine", 4, beta_r_deg=[1.0, 2.0]), "beta_r_deg"),
        (lambda: pfjax.scenarios("sine", 4, speed=np.array([1.0, -1.0, 1.0, 1.0])), "speed"),
        (lambda: pfjax.scenarios("sine", 4, lateral_offset=float("nan")), "lateral_offset"),
        (lambda: pfjax.scenarios("nope", 4), "path"),
        (lambda: pfjax.scenarios("sine", 0), "n"),
        (lambda: pfjax.scenarios("sine", 4, key=-1), "key"),
        (lambda: pfjax.uniform(2, 1), "uniform"),
        (lambda: pfjax.simulate(pfjax.scenarios("sine", 2), "nope"), "controller"),
        (lambda: pfjax.simulate(pfjax.scenarios("sine", 2), "pi", gains={"kp": 1.0}), "gains"),
        (lambda: pfjax.simulate(pfjax.scenarios("sine", 2), "pi", config={"horizont": 3}), "config"),
        (lambda: pfjax.simulate(pfjax.scenarios("sine", 2), "pi", config={"dt": -1}), "config.dt"),
        (lambda: pfjax.success_rate([]), "success"),
        (lambda: pfjax.design_mixed(v=0.0), "v"),
        (lambda: pfjax.load_study("/nonexistent"), "out"),
        (
            lambda: pfjax.run_study(
                {
                    "name": "x",
                    "n_runs": 0,
                    "seed": 0,
                    "paths": [{"kind": "line"}],
                    "controllers": [{"name": "a", "type": "pi"}],
                }
            ),
            "n_runs",
        ),
    ],
)
def test_bad_arguments_are_one_line_errors_naming_them(call, key):
    with pytest.raises(pfjax.InputError) as e:
        call()
    msg = str(e.value)
    assert "\n" not in msg and re.match(rf"{re.escape(key)}\b", msg), msg


@pytest.mark.parametrize("name", [n for n in pfjax.api.__all__ if not isinstance(getattr(pfjax.api, n), type)])
def test_an_argument_a_function_does_not_take_is_named_with_the_closest_one(name):
    """As ``--set`` names an unknown key: an InputError (and a TypeError, as Python's own) naming
    the keyword, before anything runs."""
    import inspect

    f = getattr(pfjax, name)
    params = inspect.signature(f).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):  # its extra keywords are config keys
        return
    first = next(iter(params))
    with pytest.raises(pfjax.InputError) as e:
        f(**{first + "x": 1})
    assert isinstance(e.value, TypeError) and e.value.key == first + "x"
    assert str(e.value) == f"{first}x: pfjax.{name} takes no such argument (did you mean {first!r}?)"
    with pytest.raises(TypeError, match=rf"pfjax.{name}: too many positional arguments"):
        f(*range(len(params) + 1))


def test_run_load_and_replay_a_study(tmp_path):
    config = ROOT / "studies" / "robustness_default.toml"
    res = pfjax.run_study(
        config,
        tmp_path / "out",
        n_runs=24,
        chunk_size=24,
        f64_check_runs=0,
        margin__enabled=False,
        falsifier__enabled=False,  # a study's worst-case search: tests/test_study_configs.py
        # the horizon and windows of tests/test_study_configs.py's small runs of this config (runs
        # padded to 32 there and here): the same compiled simulators, loaded from the persistent cache
        sim__horizon=3.0,
        sim__steady_window=1.0,
        success__from_s=2.0,
        progress=False,
        report=False,
    )
    assert len(res.runs) == 24 * len(res.summary["config"]["paths"]) * len(res.summary["config"]["controllers"])
    # every column of the run table says its unit and meaning; angles in degrees say so in their names
    from pfjax.tables import units

    u = units(tmp_path / "out" / "runs.parquet")
    assert set(u) == set(res.runs.columns)
    assert (u["start_along_m"]["unit"], u["steady_abs_theta_e_rad"]["unit"], u["beta_r_deg"]["unit"]) == (
        "m",
        "rad",
        "deg",
    )
    assert all(v["description"] for v in u.values())
    again = pfjax.load_study(tmp_path / "out")
    assert again.summary == res.summary and list(again.headline.columns) == list(res.headline.columns)
    row = res.runs.iloc[5]
    rep = pfjax.replay(res, row.path, row.controller, [int(row.run)])
    assert rep.table.iae[0] == row.iae and rep.table.status[0] == row.status  # the same run, bit for bit
    traj = rep.result.trajectory
    assert traj is not None and traj.d.shape[-1] == round(3.0 / res.summary["config"]["sim"]["dt"]) + 1


def test_tune_and_falsify_small():
    cfg = SimConfig(dt=0.01, horizon=4.0, record=False)
    out = pfjax.tune("pi", "paper-line", "gradient", steps=3, config=cfg, key=0)
    assert set(out["gains"]) >= {"kp_d", "ki_d", "kp_theta", "ki_theta"} and np.isfinite(out["cost"])
    worst = pfjax.falsify("paper_k", "sine", slip_bound_deg=5.0, restarts=2, steps=3, config=cfg, key=0)
    assert np.isfinite(float(worst.objective))
    assert worst.status_name == STATUS_NAMES[int(worst.status)]  # the status by name


def test_readme_script_runs():
    """The README's script (between the markers) runs as written and prints a success rate."""
    text = (ROOT / "README.md").read_text()
    script = re.search(r"<!-- api-example -->\s*```python\n(.*?)```", text, re.S).group(1)
    assert len(script.strip().splitlines()) <= 20
    assert all(
        line.startswith(("import pfjax", "#", " "))
        or "pfjax." in line
        or "=" in line
        or line.startswith("print")
        or not line.strip()
        for line in script.splitlines()
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert re.search(r"% of 1000 runs succeed \(95 % interval", out.stdout), out.stdout


def _python(code: str, **env) -> subprocess.CompletedProcess:
    e = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "PFJAX_HOST_DEVICES")}
    e.update(env)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=e)


def test_import_is_cheap_and_sets_the_host_up():
    out = _python(
        "import sys, os, pfjax; print('jax' in sys.modules, 'cvxpy' in sys.modules); "
        "print(os.environ.get('XLA_FLAGS', ''))"
    )
    lines = out.stdout.splitlines()
    assert out.returncode == 0 and lines[0] == "False False", out.stderr
    cores = len(os.sched_getaffinity(0))
    if cores > 1:
        assert f"device_count={cores}" in lines[1]


def test_warns_once_when_jax_started_first():
    code = (
        "import warnings; warnings.simplefilter('always'); import jax; jax.numpy.zeros(1).block_until_ready(); "
        "import pfjax; pfjax.setup(); print(jax.local_device_count())"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    if len(os.sched_getaffinity(0)) > 1:
        assert out.stderr.count("HostWarning") == 1 and "import pfjax before" in out.stderr
    # importing JAX first is fine as long as nothing ran: all cores, no warning
    out = _python("import jax, pfjax; print(jax.local_device_count())")
    assert out.returncode == 0 and "HostWarning" not in out.stderr
    assert int(out.stdout.split()[-1]) == len(os.sched_getaffinity(0))


def test_scenarios_fields_and_table_columns_are_documented_with_units():
    """pfjax.Scenarios' docstring names each field and property in an ``Attributes:`` section, and
    every column of the kinematic and single-track tables with its unit."""
    doc = pfjax.Scenarios.__doc__ or ""
    attributes = doc.partition("Attributes:")[2]
    for name in (*pfjax.Scenarios._fields, "n"):
        assert re.search(rf"^\s+{name}: ", attributes, re.M), name
    for model in ("kinematic", "st"):
        for column in pfjax.scenarios("sine", 1, model=model).table.columns:
            assert f"``{column}``" in attributes, column
    for unit in ("(m/s)", "(m)", "(deg)", "(1)"):
        assert unit in attributes, unit


def test_dir_lists_the_public_names_and_submodules_only():
    import pfjax

    names = dir(pfjax)
    assert set(pfjax.__all__) <= set(names) and "sim" in names and "importlib" not in names
    assert [n for n in names if n.startswith("_")] == ["__version__"]
