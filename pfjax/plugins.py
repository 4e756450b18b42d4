"""Plugins: modules that register controllers and paths before pfjax's command line reads its
registries (:mod:`pfjax.controllers.registry`, :mod:`pfjax.paths.registry`).

A plugin is any importable module (installed, or in a folder on ``PYTHONPATH``: the ``pfjax``
command does not look in the current folder) that calls :func:`pfjax.controllers.register` or
:func:`pfjax.paths.register` when imported. The command line imports

- the modules named in the environment variable ``PFJAX_PLUGINS`` (comma-separated), and
- the entry points of the group ``pfjax.plugins`` of installed packages
  (``[project.entry-points."pfjax.plugins"] mine = "mypkg.pfjax_plugin"`` in their
  ``pyproject.toml``),

so ``PFJAX_PLUGINS=mypkg.controllers pfjax simulate --controller my-ctrl ...`` works without
editing pfjax (``PYTHONPATH=. PFJAX_PLUGINS=my_module pfjax ...`` for a ``my_module.py`` in the
current folder). A Python script simply imports its module before calling pfjax.

Who owns a name: each entry of a registry records the module that registered it, the
``__name__`` of the module whose code called ``register`` (:func:`registrant`; ``"__main__"`` for
a script or a notebook). A name can be registered again only by that module, which replaces its
entry (re-running a notebook cell, :func:`importlib.reload`); a name that pfjax registers itself
(its controllers and paths) or that another module registered is refused with a one-line
:class:`~pfjax.errors.InputError` naming ``name``, so no plugin can run its code under another's
label. The functions a registry stores are checked against the arguments pfjax calls them with
(:func:`check_call`) when they are registered.
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Callable
from types import FrameType

from pfjax.errors import InputError

ENV = "PFJAX_PLUGINS"
GROUP = "pfjax.plugins"


def registrant(*internal: str) -> str:
    """The ``__name__`` of the module whose code called a registry's ``register``: that of the first
    calling frame outside this module and the modules ``internal`` (the registry's own); ``"__main__"``
    for a frame without one (code run by :func:`exec` with bare globals)."""
    skip = {__name__, *internal}
    frame: FrameType | None = sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__") in skip:
        frame = frame.f_back
    name = None if frame is None else frame.f_globals.get("__name__")
    return name if isinstance(name, str) and name else "__main__"


def is_builtin(module: str) -> bool:
    """Whether ``module`` is one of pfjax's own (what registers the built-in controllers and paths)."""
    return module == "pfjax" or module.startswith("pfjax.")


def check_call(key: str, fn: Callable, args: tuple[str, ...]) -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` unless ``fn`` accepts the positional
    arguments ``args`` (their names are only for the message: ``key: expected output(params, c,
    obs), got (p, obs)``). A function whose signature Python cannot read (some built-ins) is not
    checked; :func:`functools.partial` and :func:`jax.jit` functions are read through."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # no signature to read: not checked
        return
    try:
        sig.bind(*args)
    except TypeError:
        what = key.rpartition(".")[2]
        raise InputError(f"{key}: expected {what}({', '.join(args)}), got {_names(sig)}", key) from None


def _names(sig: inspect.Signature) -> str:
    """``sig`` as its parameters' names, ``(p, obs, *, k)``: no annotations or defaults."""
    out, star = [], False
    for p in sig.parameters.values():
        if p.kind is p.VAR_POSITIONAL:
            out.append(f"*{p.name}")
            star = True
        elif p.kind is p.KEYWORD_ONLY and not star:
            out += ["*", p.name]
            star = True
        else:
            out.append(f"**{p.name}" if p.kind is p.VAR_KEYWORD else p.name)
    return f"({', '.join(out)})"


def load(environ=None) -> list[str]:
    """Import every plugin module (see the module docstring) and return their names.

    Raises:
        InputError: a module that cannot be imported, naming ``PFJAX_PLUGINS`` or the entry point,
            the module and what failed (bad input of a pfjax call it makes as that call's own
            message: ``PFJAX_PLUGINS: cannot import 'mine': name: 'pi' is taken by ...``).
    """
    environ = os.environ if environ is None else environ
    names = [n.strip() for n in environ.get(ENV, "").split(",") if n.strip()]
    loaded = []
    for name in names:
        try:
            importlib.import_module(name)
        except Exception as e:  # any failure of a user's module is bad input here
            hint = " (a plugin is installed or in a folder on PYTHONPATH)" if isinstance(e, ModuleNotFoundError) else ""
            raise InputError(f"{ENV}: cannot import {name!r}: {_why(e)}{hint}", ENV) from None
        loaded.append(name)
    from importlib.metadata import entry_points

    for ep in entry_points(group=GROUP):
        try:
            ep.load()
        except Exception as e:
            raise InputError(f"entry point {GROUP}:{ep.name}: cannot import {ep.value!r}: {_why(e)}", GROUP) from None
        loaded.append(ep.value)
    return loaded


def _why(e: Exception) -> str:
    """What went wrong in a plugin's import, one line: pfjax's own bad-input message as it is (it
    names the argument at fault), anything else after its type."""
    return str(e) if isinstance(e, InputError) else f"{type(e).__name__}: {e}"
