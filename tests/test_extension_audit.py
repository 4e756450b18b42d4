"""Extending pfjax, checked at its edges: a design's ``K`` of another size, a path builder that
returns no path, names another controller or a design already answers to, a plugin the ``pfjax``
command cannot find, and ``pfjax synth``'s flags, errors and units."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import pfjax
from pfjax import controllers as C
from pfjax import paths
from pfjax.cli import main
from pfjax.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ simulate: a design's K


@pytest.mark.parametrize(
    "controller, K, message",
    [
        (
            "state_feedback",
            [[-1.0, -2.0, -0.5]],
            r"^gains: the state_feedback controller takes 2 gains K \(k_d, k_theta\), got 3$",
        ),
        ("integral", [[-1.0, -2.0]], r"^gains: the integral controller takes 3 gains K \(k_d, k_theta, k_i\), got 2$"),
    ],
)
def test_simulate_refuses_a_design_whose_K_has_another_size(controller, K, message):
    """An integral design (3 gains) given to state feedback, or a state-feedback design (2) to the
    integral controller, is refused naming ``gains``, not cut or padded with a default."""
    sc = pfjax.scenarios("line", 2)
    with pytest.raises(InputError, match=message) as err:
        pfjax.simulate(sc, controller, gains=SimpleNamespace(K=np.asarray(K)))
    assert err.value.key == "gains"


def test_simulate_refuses_a_parameter_pytree_whose_K_has_another_size():
    """A ``StateFeedbackParams`` with three gains K is refused as bad input naming ``gains``."""
    e = C.entry("state_feedback")
    params = e.make_params()._replace(K=np.array([-1.0, -2.0, -0.5]))
    with pytest.raises(
        InputError, match=r"^gains: the state_feedback controller's K takes 2 values \(k_d, k_theta\), got 3$"
    ) as err:
        pfjax.simulate(pfjax.scenarios("line", 2), "state_feedback", gains=params)
    assert err.value.key == "gains"


def test_a_design_K_of_the_right_size_gives_every_gain():
    from pfjax.api.simulation import resolve_gains

    _, flat = resolve_gains(C.entry("integral"), None, SimpleNamespace(K=np.array([[-1.0, -2.0, -0.5]])), 1.0, 0.2)
    assert (flat["k_d"], flat["k_theta"], flat["k_i"]) == (-1.0, -2.0, -0.5)


# ------------------------------------------------------------------ paths: the builder


def test_every_built_in_path_builds_a_path():
    """pfjax's own builders are not called on import (that would start JAX's runtime); each passes
    the check :func:`pfjax.paths.register` makes of a user's builder."""
    from pfjax.paths.registry import _check_build

    built = [n for n, e in paths.PATHS.items() if e.build is not None]
    assert {"line", "parabola", "sine", "circle"} <= set(built)
    for name in built:
        _check_build(name, paths.PATHS[name].build)


def test_a_path_builder_that_returns_no_path_is_refused_when_registered():
    with pytest.raises(InputError, match=r"^build: the builder of path 'junk' returned int 3, not a path") as err:
        paths.register("junk", lambda: 3, start_pose=(0.0, 0.0, 0.0))
    with pytest.raises(InputError, match=r"^build: the builder of path 'boom' raised ZeroDivisionError"):
        paths.register("boom", lambda: 1 / 0, start_pose=(0.0, 0.0, 0.0))
    assert err.value.key == "build" and "junk" not in paths.PATHS and "boom" not in paths.PATHS
    try:  # a spline built from waypoints is a path
        paths.register("test_spline", lambda: paths.spline_through([[0, 0], [1, 1], [2, 0]]), start_pose=(0, 0, 0))
    finally:
        paths.PATHS.pop("test_spline", None)


# ------------------------------------------------------------------ controllers: names


@pytest.mark.parametrize(
    "kw, key", [({"name": "lmi"}, "name"), ({"name": "fake_mixed", "cli_name": "mixed"}, "cli_name")]
)
def test_controller_names_of_a_design_are_refused(kw, key):
    """A design (``lmi``, command-line ``mixed``) is resolved before the registry, so a controller
    registered under its name could never be reached."""
    e = C.entry("state_feedback")
    try:
        with pytest.raises(InputError) as err:
            C.register(e.controller, e.make_params.factory, labels=e.labels, **kw)
    finally:
        C.REGISTRY.pop(kw["name"], None)
    assert err.value.key == key and "lmi design" in str(err.value)


def test_reserved_names_are_refused():
    from pfjax.controllers import registry

    e = C.entry("state_feedback")
    registry.reserve(("test_taken", "test-taken"), "a test")
    try:
        with pytest.raises(InputError, match=r"^cli_name: 'test-taken' is taken by a test; choose another$"):
            C.register(e.controller, e.make_params.factory, name="test_other", labels=e.labels, cli_name="test-taken")
        assert "test_other" not in C.REGISTRY
    finally:
        registry.RESERVED.pop("test_taken", None)
        registry.RESERVED.pop("test-taken", None)


# ------------------------------------------------------------------ plugins


def _doc_module() -> str:
    """The controller module of docs/extending.md (its first Python block)."""
    text = (ROOT / "docs" / "extending.md").read_text()
    return re.search(r"```python\n(.*?)```", text, re.S).group(1)


def test_the_plugin_command_of_extending_md_runs_as_written(tmp_path):
    """``PYTHONPATH=. PFJAX_PLUGINS=my_module pfjax ...`` in the folder of ``my_module.py`` (the page's
    module) finds it; without ``PYTHONPATH`` the ``pfjax`` command does not, and says where to put it."""
    text = (ROOT / "docs" / "extending.md").read_text()
    assert "$ PYTHONPATH=. PFJAX_PLUGINS=my_module pfjax simulate" in text
    (tmp_path / "my_module.py").write_text(_doc_module())
    script = Path(sys.executable).parent / "pfjax"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    ok = subprocess.run(
        [str(script), "simulate", "--help"],
        cwd=tmp_path,
        env={**env, "PYTHONPATH": ".", "PFJAX_PLUGINS": "my_module"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert ok.returncode == 0 and "dummy-heading" in ok.stdout, ok.stderr
    bad = subprocess.run(
        [str(script), "simulate", "--help"],
        cwd=tmp_path,
        env={**env, "PFJAX_PLUGINS": "my_module"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "PYTHONPATH" in bad.stderr, bad.stderr


# ------------------------------------------------------------------ pfjax synth


@pytest.mark.parametrize("method, flag", [("hinf", "--alpha"), ("h2", "--beta")])
def test_synth_refuses_a_weight_the_method_does_not_read(capsys, method, flag):
    assert main(["synth", "--method", method, flag, "3", "--json"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == f"pfjax synth: error: {flag}: only the mixed design reads it, not --method '{method}'\n"


def test_synth_records_only_the_arguments_it_reads_and_their_units(capsys):
    """``--method h2`` records no weights; the norms are from all of the plant's inputs
    ``w = [beta_r, beta_f, kappa]`` (the kappa column of B_w changes them); poles and the pole
    region are in 1/s."""
    assert main(["synth", "--method", "h2", "--max-real", "-1", "--json"]) == 0

    out = json.loads(capsys.readouterr().out)
    assert "alpha" not in out["arguments"] and "beta" not in out["arguments"]
    for key in ("hinf_norm", "h2_norm", "gamma_2"):
        assert "w = [beta_r rad, beta_f rad, kappa 1/m]" in out["units"][key], key
    assert out["units"]["closed_loop_poles"] == "1/s (real, imaginary)"
    assert out["region"]["max_real"] == -1.0 and out["units"]["region.max_real"] == "1/s"
    # the norm includes the kappa channel: the same loop without it has another H2 norm
    from pfjax.synthesis import h2_norm, slip_design_plant

    p = slip_design_plant(1.0, 0.2)
    K = np.asarray(out["K"], float)
    Acl, C2 = p.A + p.Bu @ K, p.C2 + p.D2u @ K
    assert h2_norm(Acl, p.Bw, C2) == pytest.approx(out["h2_norm"], rel=1e-9)
    assert abs(h2_norm(Acl, p.Bw[:, :2], C2) - out["h2_norm"]) > 1e-3 * out["h2_norm"]


def test_synth_names_the_plant_flags_when_no_design_exists(capsys):
    assert main(["synth", "--speed", "1e12"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(
        "pfjax synth: error: --speed/--wheelbase: the solver found no mixed design at speed 1e+12 m/s"
    )
    assert err.count("\n") == 1
