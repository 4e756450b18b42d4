"""One registry per concept: a controller and a path registered by a plugin module
(tests/plugins/dummy_plugin.py) run through single runs, a study, tuning and the command line,
with no other file edited; the registries are what config literals, command-line choices, tuning
boxes and plot styles are read from."""

import importlib
import json
import os
import re
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


@pytest.mark.parametrize("name", ["nope", "random", "spline"])
def test_a_single_run_names_only_the_paths_it_can_use(name):
    """pfjax.falsify and a paper scenario take a fixed path: an unknown name or a kind built only
    from a study config is refused listing the fixed paths, not the kinds it would then refuse."""
    import pfjax
    from pfjax.errors import InputError
    from pfjax.sim.scenario import paper_scenario

    fixed = ", ".join(paths.fixed_paths())
    assert "random" not in fixed and "spline" not in fixed
    why = "unknown path 'nope'" if name == "nope" else f"{name!r} is built only from a study config"
    for call in (lambda: pfjax.falsify("pi", path=name), lambda: paper_scenario(name, None)):
        with pytest.raises(InputError, match=f"^path: {re.escape(why)}; expected one of {re.escape(fixed)}$"):
            call()


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


def _sf_register(factory=None, **kw):
    """Register state feedback again under a test name, with ``kw`` changed, always removing it."""
    e = C.entry("state_feedback")
    try:
        return C.register(
            e.controller,
            factory or e.make_params.factory,
            **{"name": "sf_copy", "labels": e.labels, "box": e.box, **kw},
        )
    finally:
        C.REGISTRY.pop("sf_copy", None)


@pytest.mark.parametrize(
    "kw, key",
    [
        ({"box": (("k_x",), (0.0,), (1.0,))}, "box.fields"),  # not a gain field
        ({"box": (("K",), (0.0, -1.0), (-1.0, 0.0))}, "box.lower[0]"),  # lower > upper
        ({"box": (("K",), (-1.0, -1.0), (-1.0, 0.0))}, "box.lower[0]"),  # lower == upper
        ({"box": (("K",), (-1.0,), (0.0,))}, "box.lower"),  # K has two elements
        ({"box": (("K",), (-1.0, -1.0), (0.0, 0.0, 0.0))}, "box.upper"),
        ({"box": (("K",), (-1.0, float("nan")), (0.0, 0.0))}, "box.lower[1]"),
        ({"box": (("K", "K"), (-1.0,) * 4, (0.0,) * 4)}, "box.fields[1]"),  # the repeated field
        ({"box": ("K", -1.0, 0.0, 1.0)}, "box"),
        ({"name": ""}, "name"),
        ({"name": 5}, "name"),
        ({"factory": 5}, "factory"),
        ({"defaults": {"k_x": 1.0}}, "defaults"),
        ({"labels": {"K": "k_d"}}, "labels.K"),
        ({"gains": ("k_x",)}, "gains"),
        ({"name": "my ctrl"}, "name"),  # names are lower-case ASCII identifiers
        ({"name": "Sf"}, "name"),
        ({"name": "sf_copy", "cli_name": "sf copy"}, "cli_name"),
        ({"style": "red"}, "style"),  # a mapping of matplotlib keywords
        ({"cli_name": "pi"}, "cli_name"),  # another entry's command-line name: unreachable
        ({"cli_name": "pure_pursuit"}, "cli_name"),  # another entry's registry name
        ({"name": "stanley", "cli_name": "pi"}, "name"),  # pfjax's own stanley: not replaced by another module
    ],
)
def test_controller_register_checks_its_arguments(kw, key):
    """A bad argument of ``register`` is refused when it is given, naming it, not inside a later tune."""
    from pfjax.errors import InputError

    with pytest.raises(InputError) as err:
        _sf_register(**kw)
    assert err.value.key == key and str(err.value).startswith(key) and "\n" not in str(err.value)
    assert "sf_copy" not in C.REGISTRY


def test_controller_register_replaces_an_entry_of_the_same_name():
    """Registering a name again replaces its entry (its own names are not taken from it); the
    command-line name may change with it."""
    e = C.entry("state_feedback")
    try:
        C.register(e.controller, e.make_params.factory, name="sf_copy", labels=e.labels)
        again = C.register(e.controller, e.make_params.factory, name="sf_copy", labels=e.labels, cli_name="sf-again")
        assert C.entry("sf-again") is again and C.REGISTRY["sf_copy"] is again
    finally:
        C.REGISTRY.pop("sf_copy", None)


def test_controller_register_keeps_a_good_box():
    e = _sf_register(box=[("K",), np.array([-20, -10]), [0, 0]])
    assert e.box == (("K",), (-20.0, -10.0), (0.0, 0.0))


@pytest.mark.parametrize(
    "kw, key",
    [
        ({"name": 5}, "name"),
        ({"name": "Bad-Name"}, "name"),
        ({"build": 5}, "build"),
        ({"build": None}, "build"),  # a fixed path needs its builder
        ({"start_pose": (0.0, 0.0)}, "start_pose"),
        ({"start_pose": (float("nan"), 0.0, 0.0)}, "start_pose[0]"),
        ({"start_pose": None}, "start_pose"),
        ({"start_u": "0"}, "start_u"),
        ({"start_u": float("inf")}, "start_u"),
        ({"max_curvature": -1.0}, "max_curvature"),
        ({"parametric": True}, "parametric"),  # only pfjax's own kinds are built from a path config
        ({"source": "yes"}, "source"),
        ({"description": 5}, "description"),
        ({"name": "1gentle"}, "name"),  # a lower-case ASCII identifier
        ({"name": "g\u00e9ntle"}, "name"),
        ({"name": "my path"}, "name"),
        ({"build": lambda: 3}, "build"),  # built once when registered: not a path
        ({"build": lambda: 1 / 0}, "build"),  # a builder that raises
        ({"build": lambda: paths.sine(u_min=5.0, u_max=1.0)}, "build"),  # an empty range of u
    ],
)
def test_path_register_checks_its_arguments(kw, key):
    from pfjax.errors import InputError

    args = {"start_pose": (0.0, 0.0, 0.0), "max_curvature": 0.0, **kw}
    try:
        with pytest.raises(InputError) as err:
            paths.register(args.pop("name", "test_path"), args.pop("build", paths.line), **args)
    finally:
        paths.PATHS.pop("test_path", None)
    assert err.value.key == key and str(err.value).startswith(key) and "\n" not in str(err.value)


def test_the_sampler_builds_a_registered_path_once_and_again_when_it_is_registered_again():
    """A study's sampler builds a parameterless path once per build function (and precision), not
    at every batch; registering the name again from its module (a re-run notebook cell) gives the
    new path to the next batch."""
    from pfjax.montecarlo.config import load_study
    from pfjax.montecarlo.sampling import sample_runs

    built = []

    def slope(a):
        def build():
            built.append(a)
            return paths.line(heading=a)

        return build

    data = {
        "name": "x",
        "n_runs": 4,
        "seed": 0,
        "paths": [{"kind": "test_path"}],
        "controllers": [{"name": "a", "type": "pi"}],
        "initial": {
            "lateral_offset": {"dist": "constant", "value": 0.0},
            "heading_error_deg": {"dist": "constant", "value": 0.0},
        },
    }
    try:
        paths.register("test_path", slope(0.5), start_pose=(0.0, 0.0, 0.0))
        spec, _ = load_study(data=data)
        first = [sample_runs(spec, 0, np.arange(4)) for _ in range(3)]
        assert built == [0.5, 0.5]  # by register (its check), then by the first batch only
        paths.register("test_path", slope(-0.5), start_pose=(0.0, 0.0, 0.0))
        again = sample_runs(spec, 0, np.arange(4))
    finally:
        paths.PATHS.pop("test_path", None)
    assert built == [0.5, 0.5, -0.5, -0.5]
    # a start on the line with no heading error has the line's heading: the new path's, not the cached one
    theta = lambda sampled: np.asarray(sampled.scenarios.pose0.theta)
    np.testing.assert_array_equal(theta(first[0]), theta(first[2]))
    np.testing.assert_allclose(theta(first[0]), 0.5, rtol=1e-6)
    np.testing.assert_allclose(theta(again), -0.5, rtol=1e-6)


def test_path_register_keeps_good_arguments():
    try:
        e = paths.register("test_path", paths.line, start_pose=np.array([1, 0, 0.5]), start_u=np.float32(2.0))
    finally:
        paths.PATHS.pop("test_path", None)
    assert e.start_pose == (1.0, 0.0, 0.5) and e.start_u == 2.0 and e.max_curvature is None


def test_per_run_gain_is_named_by_its_flat_name():
    """A per-run array for one scalar gain is refused by the gain's own name (``k_d``), not the
    vector field it belongs to (``K``); NumPy and JAX scalars and 0-d arrays are gains."""
    import jax.numpy as jnp

    from pfjax.errors import InputError

    e = C.entry("state_feedback")
    with pytest.raises(
        InputError, match=r"^gains\.k_d: expected a number \(one gain for all runs\), got an array of shape \(2,\)$"
    ):
        C.params_from_flat(e, {"k_d": np.array([-1.0, -2.0])})
    with pytest.raises(InputError, match=r"^gains\.k_theta: expected a number"):
        C.params_from_flat(e, {"k_theta": "x"})
    p = C.params_from_flat(e, {"k_d": np.float32(-1.0), "k_theta": np.asarray(-2.0), "feedforward": jnp.asarray(0.0)})
    assert np.allclose(p.K, [-1.0, -2.0])


def test_import_exposes_the_public_modules():
    """``pfjax.api``, ``pfjax.errors`` and ``pfjax.plugins`` are attributes right after ``import pfjax``."""
    code = "import pfjax; print(pfjax.api.__name__, pfjax.errors.__name__, pfjax.plugins.__name__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["pfjax.api", "pfjax.errors", "pfjax.plugins"]
