"""pfjax: path following in JAX.

Importing pfjax before JAX asks XLA for one CPU device per core, so batches are sharded over all
cores by default (:func:`default_host_devices`, :mod:`pfjax.sim.sharding`), and for small CPU
loops compiled as one function (:func:`small_loop_option`). The ``pfjax`` command,
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


SMALL_LOOP_ENV = "PFJAX_SMALL_LOOP_BYTES"
#: XLA's CPU backend runs a ``while`` loop (``lax.scan``) as a sequence of kernel launches per
#: iteration, about 0.3 us each, a few dozen per integrator step; a loop whose iteration touches
#: fewer bytes than this is instead compiled into one function (XLA's small-while-loop hoisting,
#: default threshold 1 kB). 4 MB covers about 2,000 float32 (1,000 float64) runs per device of the
#: slip model: measured 1.6 -> 3.1 M rollout-steps/s at 16 runs, 19.9 -> 25.0 at 256, 42 -> 48 at
#: 4,096; the cache-sized blocks of 10,000 runs stay above it (hoisting them was 40 -> 30 slower).
SMALL_LOOP_BYTES = 4_000_000
_EXTRA = "--xla_backend_extra_options"


def small_loop_option(environ=None, modules=None) -> bool:
    """Ask XLA's CPU backend to compile small loops into one function (:data:`SMALL_LOOP_BYTES`).

    Adds ``--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=<bytes>`` to
    ``XLA_FLAGS`` unless JAX is already imported, ``XLA_FLAGS`` already sets backend extra options
    (the user's own), or ``PFJAX_SMALL_LOOP_BYTES`` says otherwise (bytes; ``0``: leave XLA's
    default). Other backends ignore the option (options starting with ``xla_`` are not passed to
    LLVM). Returns whether it changed ``XLA_FLAGS``.
    """
    environ = os.environ if environ is None else environ
    modules = sys.modules if modules is None else modules
    flags = environ.get("XLA_FLAGS", "")
    if "jax" in modules or _EXTRA in flags:
        return False
    want = environ.get(SMALL_LOOP_ENV, "").strip()
    n = int(want) if want.isdigit() else SMALL_LOOP_BYTES
    if n <= 0:
        return False
    environ["XLA_FLAGS"] = f"{flags} {_EXTRA}=xla_cpu_small_while_loop_byte_threshold={n}".strip()
    return True


small_loop_option()
default_host_devices()
