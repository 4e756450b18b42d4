"""pfjax: path following in JAX.

Importing pfjax before JAX asks XLA for one CPU device per core, so batches are sharded over all
cores by default (:func:`default_host_devices`, :mod:`pfjax.sim.sharding`). The ``pfjax`` command,
the study scripts and the notebooks also turn on a persistent compilation cache (:mod:`pfjax.cache`).
"""

import os
import sys

__version__ = "0.1.0"

HOST_DEVICES_ENV = "PFJAX_HOST_DEVICES"
_FLAG = "--xla_force_host_platform_device_count"


def default_host_devices(environ=None, modules=None) -> bool:
    """Ask XLA for one CPU device per core, if that is still possible and wanted.

    Adds ``--xla_force_host_platform_device_count=<cores>`` to ``XLA_FLAGS`` unless JAX is already
    imported (too late: its backend may exist), ``XLA_FLAGS`` already sets the flag, or
    ``PFJAX_HOST_DEVICES`` says otherwise (a number: that many devices; ``1``: leave XLA alone).
    Cores = the CPUs this process may run on. Returns whether it changed ``XLA_FLAGS``.
    GPUs are unaffected (the flag only adds CPU devices; the default backend stays the GPU).
    """
    environ = os.environ if environ is None else environ
    modules = sys.modules if modules is None else modules
    flags = environ.get("XLA_FLAGS", "")
    if "jax" in modules or _FLAG in flags:
        return False
    want = environ.get(HOST_DEVICES_ENV, "").strip()
    if want.isdigit():
        n = int(want)
    else:
        n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if n <= 1:
        return False
    environ["XLA_FLAGS"] = f"{flags} {_FLAG}={n}".strip()
    return True


default_host_devices()
