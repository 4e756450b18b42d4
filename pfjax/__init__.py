"""pfjax: path following in JAX — batched Monte Carlo robustness studies of path-following
controllers for wheeled robots.

The public API (:data:`__all__`; :mod:`pfjax.api`)::

    pfjax.design_mixed(v, L, alpha=10, beta=1)        # mixed H2/H∞ state feedback by LMIs
    pfjax.scenarios(path, n, beta_r_deg=..., key=...)  # n runs: numbers, arrays or distributions
    pfjax.simulate(scenarios, controller, gains)       # per-run metrics and statuses
    pfjax.success_rate(simulation)                     # with its Clopper-Pearson interval
    pfjax.run_study(config, out) / pfjax.load_study(out)
    pfjax.rare_event(config, method="is")             # failure probabilities to 1e-6 and below
    pfjax.tune(...), pfjax.falsify(...), pfjax.parking.run(...), pfjax.tracking.run(...)

Importing pfjax sets the host up (:func:`setup`, :mod:`pfjax.host`): one CPU device per core, the
small-loop compiler threshold and a persistent compilation cache, each unless the user set their
own; pfjax warns once if JAX had already started. The names load on first use, so ``import pfjax``
itself is fast.
"""

import importlib as _importlib

from pfjax.host import (
    HOST_DEVICES_ENV,
    SMALL_LOOP_BYTES,
    SMALL_LOOP_ENV,
    HostWarning,
    default_host_devices,
    setup,
    small_loop_option,
)

__version__ = "0.1.0"

setup()

#: public name -> module that defines it (loaded on first use)
_LAZY = {
    **{
        name: "pfjax.api"
        for name in (
            "design_mixed",
            "scenarios",
            "simulate",
            "success_rate",
            "run_study",
            "load_study",
            "replay",
            "tune",
            "falsify",
            "rare_event",
            "uniform",
            "normal",
            "truncnormal",
            "choice",
            "Scenarios",
            "Simulation",
            "SuccessRate",
            "StudyResult",
        )
    },
    "InputError": "pfjax.errors",
    "SimConfig": "pfjax.sim.simulate",
    "register_controller": ("pfjax.controllers.registry", "register"),
    "register_path": ("pfjax.paths.registry", "register"),
}
__all__ = [
    *_LAZY,
    "parking",
    "tracking",
    "controllers",
    "paths",
    "setup",
    "HostWarning",
    "default_host_devices",
    "small_loop_option",
    "HOST_DEVICES_ENV",
    "SMALL_LOOP_BYTES",
    "SMALL_LOOP_ENV",
    "__version__",
]


def _submodules() -> set[str]:
    """Names of pfjax's public subpackages and modules (``parking``, ``api``, ``errors``, ``plugins``, ...),
    each reachable as an attribute and imported on first use (``pfjax.parking.run``)."""
    import pkgutil

    return {m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_")}


def __getattr__(name):
    if name in _LAZY:
        where = _LAZY[name]
        module, attr = where if isinstance(where, tuple) else (where, name)
        value = getattr(_importlib.import_module(module), attr)
        globals()[name] = value
        return value
    if name in _submodules():
        return _importlib.import_module(f"pfjax.{name}")
    raise AttributeError(f"module 'pfjax' has no attribute {name!r}")


def __dir__():
    public = {n for n in globals() if not n.startswith("_")}  # the module's machinery left out
    return sorted(public | set(__all__) | _submodules())
