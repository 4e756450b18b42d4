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
"""

from __future__ import annotations

import importlib
import os

from pfjax.errors import InputError

ENV = "PFJAX_PLUGINS"
GROUP = "pfjax.plugins"


def load(environ=None) -> list[str]:
    """Import every plugin module (see the module docstring) and return their names.

    Raises:
        InputError: a module that cannot be imported, naming ``PFJAX_PLUGINS`` or the entry point.
    """
    environ = os.environ if environ is None else environ
    names = [n.strip() for n in environ.get(ENV, "").split(",") if n.strip()]
    loaded = []
    for name in names:
        try:
            importlib.import_module(name)
        except Exception as e:  # any failure of a user's module is bad input here
            hint = " (a plugin is installed or in a folder on PYTHONPATH)" if isinstance(e, ModuleNotFoundError) else ""
            raise InputError(f"{ENV}: cannot import {name!r}: {type(e).__name__}: {e}{hint}", ENV) from None
        loaded.append(name)
    from importlib.metadata import entry_points

    for ep in entry_points(group=GROUP):
        try:
            ep.load()
        except Exception as e:
            raise InputError(
                f"entry point {GROUP}:{ep.name}: cannot import {ep.value!r}: {type(e).__name__}: {e}", GROUP
            ) from None
        loaded.append(ep.value)
    return loaded
