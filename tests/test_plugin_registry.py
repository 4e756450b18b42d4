"""Who may register a name, and what a registered controller's functions must accept: a name
belongs to the module that registered it (pfjax's own controllers and paths to pfjax), which alone
may register it again; a controller's ``init``, ``output`` and ``rate`` and a path's ``build`` are
checked against the arguments pfjax calls them with when they are registered. Each refusal is one
line naming the argument, and the command line reports it as one line naming ``PFJAX_PLUGINS``."""

import functools
import importlib
import sys
import textwrap

import jax
import pytest

from pfjax import controllers as C
from pfjax import paths
from pfjax.controllers.base import Controller, no_rate, no_state
from pfjax.errors import InputError

#: A plugin controller: one gain k, delta = k d (``{output}`` is its output function).
CONTROLLER = """
from typing import NamedTuple
import jax.numpy as jnp
from pfjax import controllers as C
from pfjax.controllers.base import Controller, no_rate, no_state
class P(NamedTuple):
    k: jnp.ndarray
def make(k=0.0):
    return P(jnp.asarray(k, dtype=float))
C.register(Controller({name!r}, no_state, {output}, no_rate, P), make)
"""

#: A plugin path: a straight line.
PATH = """
from pfjax import paths
paths.register({name!r}, paths.line, start_pose=(0.0, 0.0, 0.0))
"""


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """``plugin(module, text)`` writes ``module.py`` in a folder on the path and imports it
    (``load=False``: only writes it); every entry the test adds to the registries and every module
    it writes are removed afterwards."""
    monkeypatch.syspath_prepend(str(tmp_path))
    before = dict(C.REGISTRY), dict(paths.PATHS)
    written = []

    def write_and_import(module: str, text: str, load: bool = True):
        (tmp_path / f"{module}.py").write_text(textwrap.dedent(text))
        written.append(module)
        importlib.invalidate_caches()
        return importlib.import_module(module) if load else None

    yield write_and_import
    for registry, saved in zip((C.REGISTRY, paths.PATHS), before):
        registry.clear()
        registry.update(saved)
    for module in written:
        sys.modules.pop(module, None)


def _one_line(err, key: str) -> str:
    message = str(err.value)
    assert err.value.key == key and message.startswith(f"{key}: ") and "\n" not in message, message
    return message


# ------------------------------------------------------------------ names and their owners


def test_a_plugin_cannot_replace_a_built_in_controller(plugin):
    pi = C.REGISTRY["pi"]
    with pytest.raises(InputError) as err:
        plugin("plug_clash_pi", CONTROLLER.format(name="pi", output="lambda p, c, obs: p.k * obs.d"))
    assert _one_line(err, "name") == "name: 'pi' is taken by pfjax's controller 'pi'; choose another"
    assert C.REGISTRY["pi"] is pi and pi.module == "pfjax.controllers.linear"


def test_a_plugin_cannot_replace_a_built_in_path(plugin):
    sine = paths.PATHS["sine"]
    with pytest.raises(InputError) as err:
        plugin("plug_clash_sine", PATH.format(name="sine"))
    assert _one_line(err, "name") == "name: 'sine' is taken by pfjax's path 'sine'; choose another"
    assert paths.PATHS["sine"] is sine and sine.module == "pfjax.paths.registry"


def test_a_plugin_cannot_take_another_plugins_names_and_its_own_module_replaces_them(plugin):
    output = "lambda p, c, obs: p.k * obs.d"
    first = plugin("plug_first", CONTROLLER.format(name="plug_ctrl", output=output) + PATH.format(name="plug_path"))
    entry, path = C.REGISTRY["plug_ctrl"], paths.PATHS["plug_path"]
    assert entry.module == path.module == "plug_first"
    with pytest.raises(InputError) as err:
        plugin("plug_second", CONTROLLER.format(name="plug_ctrl", output=output))
    assert "module 'plug_first'" in _one_line(err, "name")
    with pytest.raises(InputError) as err:
        plugin("plug_third", PATH.format(name="plug_path"))
    assert "module 'plug_first'" in _one_line(err, "name")
    assert C.REGISTRY["plug_ctrl"] is entry and paths.PATHS["plug_path"] is path
    importlib.reload(first)  # the same module again (a notebook cell run twice): its entries are replaced
    assert C.REGISTRY["plug_ctrl"] is not entry and paths.PATHS["plug_path"] is not path
    assert C.REGISTRY["plug_ctrl"].module == "plug_first"


def test_the_command_line_reports_a_refused_plugin_in_one_line(plugin, monkeypatch, capsys):
    """``PFJAX_PLUGINS=<a plugin registering pi> pfjax ...``: exit 2 before any work, one line
    naming PFJAX_PLUGINS, the plugin and the argument; the built-in PI is untouched."""
    from pfjax.cli import main

    pi = C.REGISTRY["pi"]
    plugin("plug_cli_pi", CONTROLLER.format(name="pi", output="lambda p, c, obs: p.k * obs.d"), load=False)
    monkeypatch.setenv("PFJAX_PLUGINS", "plug_cli_pi")
    code = main(["simulate", "--path", "sine", "--controller", "pi", "--horizon", "5", "--json"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "PFJAX_PLUGINS: cannot import 'plug_cli_pi': name: 'pi' is taken by pfjax's controller 'pi'" in err
    assert C.REGISTRY["pi"] is pi


# ------------------------------------------------------------------ signatures


@pytest.mark.parametrize(
    "field, fn, message",
    [
        ("output", lambda p, obs: 0.0, "controller.output: expected output(params, c, obs), got (p, obs)"),
        (
            "output",
            lambda p, c, obs, extra: 0.0,
            "controller.output: expected output(params, c, obs), got (p, c, obs, extra)",
        ),
        ("output", lambda p, *, c, obs: 0.0, "controller.output: expected output(params, c, obs), got (p, *, c, obs)"),
        ("init", lambda: None, "controller.init: expected init(params), got ()"),
        (
            "rate",
            lambda p, c, obs: c,
            "controller.rate: expected rate(params, c, obs, delta_cmd, delta_applied), got (p, c, obs)",
        ),
    ],
)
def test_a_controller_function_with_the_wrong_arguments_is_refused_when_registered(field, fn, message):
    e = C.entry("stanley")
    bad = e.controller._replace(name="plug_badsig", **{field: fn})
    with pytest.raises(InputError) as err:
        C.register(bad, e.make_params.factory, name="plug_badsig")
    assert _one_line(err, f"controller.{field}") == message
    assert "plug_badsig" not in C.REGISTRY


def test_partial_jitted_and_unreadable_functions_are_accepted():
    """What the signature check reads through (a partial, a jitted function, defaults, ``*args``)
    or cannot read (a built-in without a signature) passes."""
    e = C.entry("stanley")
    ctrl = Controller(
        "plug_sig_ok",
        jax.jit(no_state),
        functools.partial(lambda gain, p, c, obs, scale=1.0: gain * obs.d, 2.0),
        lambda *args: no_rate(*args),
        None,
    )
    try:
        C.register(ctrl, e.make_params.factory, name="plug_sig_ok")
        C.register(ctrl._replace(init=print), e.make_params.factory, name="plug_sig_ok")  # no signature
    finally:
        C.REGISTRY.pop("plug_sig_ok", None)


def test_a_path_builder_that_takes_arguments_is_refused_by_its_signature():
    with pytest.raises(InputError) as err:
        paths.register("plug_badbuild", lambda amplitude: paths.sine(amplitude=amplitude), start_pose=(0, 0, 0))
    assert _one_line(err, "build") == "build: expected build(), got (amplitude)"
    assert "plug_badbuild" not in paths.PATHS
