"""Host set-up: what pfjax asks of XLA and JAX before they start (:func:`setup`, run on ``import pfjax``).

1. **One CPU device per core** (:func:`default_host_devices`): batches are sharded over all cores
   (:mod:`pfjax.sim.sharding`). XLA reads ``XLA_FLAGS`` when JAX starts its first backend, so
   this works as long as no JAX computation has run yet (importing JAX first is fine; running
   something first is not: pfjax then warns once, :class:`HostWarning`).
2. **Small loops compiled as one function** (:func:`small_loop_option`).
3. **A persistent compilation cache** (:mod:`pfjax.cache`): compiled programs are kept on disk
   and loaded by later processes.

Each step leaves the user's own settings alone (``XLA_FLAGS``, ``JAX_COMPILATION_CACHE_DIR``)
and has an opt-out: ``PFJAX_HOST_DEVICES=1``, ``PFJAX_SMALL_LOOP_BYTES=0``, ``PFJAX_CACHE_DIR=off``.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import NamedTuple

HOST_DEVICES_ENV = "PFJAX_HOST_DEVICES"
_FLAG = "--xla_force_host_platform_device_count"

SMALL_LOOP_ENV = "PFJAX_SMALL_LOOP_BYTES"
#: XLA's CPU backend runs a ``while`` loop (``lax.scan``) as a sequence of kernel launches per
#: iteration, about 0.3 us each, a few dozen per integrator step; a loop whose iteration touches
#: fewer bytes than this is instead compiled into one function (XLA's small-while-loop hoisting,
#: default threshold 1 kB). 4 MB covers about 2,000 float32 (1,000 float64) runs per device of the
#: slip model: measured 1.6 -> 3.1 M rollout-steps/s at 16 runs, 19.9 -> 25.0 at 256, 42 -> 48 at
#: 4,096; the cache-sized blocks of 10,000 runs stay above it (hoisting them was 40 -> 30 slower).
SMALL_LOOP_BYTES = 4_000_000
_EXTRA = "--xla_backend_extra_options"


class HostWarning(UserWarning):
    """pfjax could not set up the host as it wanted (JAX's backend had already started)."""


class HostSetup(NamedTuple):
    """What :func:`setup` did."""

    devices: bool  # asked XLA for one CPU device per core
    small_loops: bool  # set the small-loop threshold
    cache_dir: str | None  # the compilation cache directory in use (None: off or the user's own)
    too_late: bool  # JAX's backend had already started: XLA flags could not be set


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def backend_started(modules=None) -> bool:
    """Whether JAX has started a backend (then ``XLA_FLAGS`` is read already). Conservatively true
    when JAX is imported but its backend module cannot be inspected."""
    modules = sys.modules if modules is None else modules
    if "jax" not in modules:
        return False
    xb = modules.get("jax._src.xla_bridge")
    return True if xb is None or not hasattr(xb, "backends_are_initialized") else bool(xb.backends_are_initialized())


def whole_number(environ, name: str, unit: str, default: int) -> int:
    """The environment variable ``name`` as a whole number >= 0, else ``default``; a value that is set
    but not such a number is ignored with a warning naming the variable (a typo is not silent)."""
    want = environ.get(name, "").strip()
    if want.isdigit():
        return int(want)
    if want:
        warnings.warn(f"{name}: value {want!r} ignored, expected a whole number of {unit} >= 0", stacklevel=3)
    return default


def default_host_devices(environ=None, modules=None) -> bool:
    """Ask XLA for one CPU device per core, if that is still possible and wanted.

    Adds ``--xla_force_host_platform_device_count=<cores>`` to ``XLA_FLAGS`` unless JAX's backend
    has started (:func:`backend_started`: too late), ``XLA_FLAGS`` already sets the flag, or
    ``PFJAX_HOST_DEVICES`` says otherwise (a number: that many devices; ``1``: leave XLA alone).
    Cores = the CPUs this process may run on. Returns whether it changed ``XLA_FLAGS``.
    GPUs are unaffected (the flag only adds CPU devices; the default backend stays the GPU).
    """
    environ = os.environ if environ is None else environ
    flags = environ.get("XLA_FLAGS", "")
    if backend_started(modules) or _FLAG in flags:
        return False
    n = whole_number(environ, HOST_DEVICES_ENV, "devices", _cores())
    if n <= 1:
        return False
    environ["XLA_FLAGS"] = f"{flags} {_FLAG}={n}".strip()
    return True


def small_loop_option(environ=None, modules=None) -> bool:
    """Ask XLA's CPU backend to compile small loops into one function (:data:`SMALL_LOOP_BYTES`).

    Adds ``--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=<bytes>`` to
    ``XLA_FLAGS`` unless JAX's backend has started, ``XLA_FLAGS`` already sets backend extra
    options (the user's own), or ``PFJAX_SMALL_LOOP_BYTES`` says otherwise (bytes; ``0``: leave
    XLA's default). Other backends ignore the option (options starting with ``xla_`` are not
    passed to LLVM). Returns whether it changed ``XLA_FLAGS``.
    """
    environ = os.environ if environ is None else environ
    flags = environ.get("XLA_FLAGS", "")
    if backend_started(modules) or _EXTRA in flags:
        return False
    n = whole_number(environ, SMALL_LOOP_ENV, "bytes", SMALL_LOOP_BYTES)
    if n <= 0:
        return False
    environ["XLA_FLAGS"] = f"{flags} {_EXTRA}=xla_cpu_small_while_loop_byte_threshold={n}".strip()
    return True


def compilation_cache(environ=None, modules=None) -> str | None:
    """Point JAX's persistent compilation cache at :func:`pfjax.cache.default_dir`, unless the user
    configured one or turned it off. Before JAX is imported this sets ``JAX_COMPILATION_CACHE_DIR``
    (and a 0.5 s minimum compile time) for JAX to read; after, :func:`pfjax.cache.enable`.
    Returns the directory, or None."""
    from pfjax import cache

    environ = os.environ if environ is None else environ
    modules = sys.modules if modules is None else modules
    if "jax" in modules:
        found = cache.enable()
        return None if found is None else str(found)
    if environ.get("JAX_COMPILATION_CACHE_DIR"):
        return None
    target = cache.usable(cache.default_dir(environ))
    if target is None:
        return None
    environ["JAX_COMPILATION_CACHE_DIR"] = str(target)
    environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.5")
    return str(target)


_warned = False


def setup(environ=None, modules=None, *, cache: bool = True) -> HostSetup:
    """Set the host up for pfjax: one CPU device per core, the small-loop threshold and the
    compilation cache (module docstring). Runs on ``import pfjax``; calling it again is harmless.

    If JAX's backend had already started on a CPU with one device while more cores are free,
    warns once (:class:`HostWarning`) and says how to get all cores."""
    global _warned
    environ = os.environ if environ is None else environ
    loops = small_loop_option(environ, modules)
    devices = default_host_devices(environ, modules)
    late = backend_started(modules)
    cache_dir = compilation_cache(environ, modules) if cache else None
    if (
        late
        and not _warned
        and environ.get(HOST_DEVICES_ENV, "").strip() != "1"
        and _FLAG not in environ.get("XLA_FLAGS", "")
    ):
        import jax

        n = _cores()
        if n > 1 and jax.default_backend() == "cpu" and jax.local_device_count() == 1:
            _warned = True
            warnings.warn(
                f"JAX started before pfjax was imported, so XLA uses 1 CPU device of the {n} cores here; "
                f"import pfjax before running anything in JAX, or set XLA_FLAGS="
                f"{_FLAG}={n} before starting Python, to use all cores",
                HostWarning,
                stacklevel=3,
            )
    return HostSetup(devices, loops, cache_dir, late)
