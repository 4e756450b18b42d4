"""XLA compiler options for pfjax's simulator programs: 512-bit vectors on CPUs with AVX-512.

XLA's CPU backend vectorises for 256-bit registers by default, also where the CPU has AVX-512
(its ``xla_cpu_prefer_vector_width`` option, default 256). pfjax's simulators are long chains of
elementwise arithmetic over the runs of a block, so twice the lanes per instruction pays:
measured with ``pfjax bench`` on a 2-core AMD EPYC (Zen 5, AVX-512), jax 0.10.2, the slip model
at B = 10^5, 118.6 -> 199-205 M rollout-steps/s in float32 and 49.5 -> 87.5-90.5 in float64
(README, Performance; docs/performance.md).

**Why per program, not in ``XLA_FLAGS``.** With 512-bit vectors XLA's own arctangent
(``jnp.arctan``, the ``atan`` primitive) is wrong: a maximum relative error of 2e8 in float32 and
5e9 in float64 on random arguments, measured with jax 0.10.2 (sin, cos, tan, atan2, exp, log,
tanh, sqrt and hypot stayed within 3.5 ulp, as without the option). A process-wide flag would
break a user's own programs in the same process. pfjax's simulators contain none of XLA's
trigonometric primitives (they use :mod:`pfjax.numerics.elementary`, plain ``jnp`` arithmetic;
``tests/test_elementary.py`` fails if one is left), so their entry points are compiled with the
option (:func:`jit`, ``jax.jit(..., compiler_options=OPTIONS)``) and nothing else is.
``tests/test_compiler.py`` checks every simulator against the same program compiled without it,
``tests/test_elementary.py`` pfjax's elementary functions under both widths.

``PFJAX_VECTOR_WIDTH`` overrides the choice: ``0`` leaves XLA's default, a positive number asks
for that width in bits (read when this module is first imported). The option is a CPU
code-generation option: where JAX's default backend is not the CPU (a GPU), the programs are
compiled without it, exactly as before this module existed.
"""

from __future__ import annotations

import functools
import os
import warnings
from functools import partial

import jax

from pfjax.numerics import calibration
from pfjax.numerics.cpu import CPUINFO, cpu_info, has_avx512

__all__ = [
    "OPTIONS",
    "PROGRAMS",
    "at_top_level",
    "cpu_info",
    "has_avx512",
    "jit",
    "options",
    "settings_source",
    "vector_width",
]

VECTOR_WIDTH_ENV = "PFJAX_VECTOR_WIDTH"
_OPTION = "xla_cpu_prefer_vector_width"


def vector_width(environ=None, cpuinfo: str = CPUINFO) -> int | None:
    """The vector width in bits pfjax asks XLA's CPU backend for, or ``None`` for XLA's default.

    ``PFJAX_VECTOR_WIDTH`` when set (``0``: XLA's default; a positive number: that width); else the
    width ``pfjax calibrate`` measured best on this CPU (:mod:`pfjax.numerics.calibration`); else
    512 on a CPU with AVX-512 (:func:`has_avx512`), else XLA's default. A value that is not a
    whole number >= 0 is ignored with a warning naming the variable."""
    environ = os.environ if environ is None else environ
    want = environ.get(VECTOR_WIDTH_ENV, "").strip()
    if want:
        if want.isdigit():
            return int(want) or None
        warnings.warn(f"{VECTOR_WIDTH_ENV}: value {want!r} ignored, expected a whole number of bits >= 0", stacklevel=2)
    if cpuinfo == CPUINFO:  # this machine's CPU: its calibration, where one was measured
        calibrated, width = calibration.vector_width()
        if calibrated:
            return width
    return 512 if has_avx512(cpuinfo) else None


def options(environ=None, cpuinfo: str = CPUINFO) -> dict:
    """The compiler options of pfjax's simulator programs (``{}`` where XLA's defaults stand)."""
    width = vector_width(environ, cpuinfo)
    return {} if width is None else {_OPTION: width}


#: The options every simulator entry point is compiled with (decided once, at import).
OPTIONS: dict = options()


def at_top_level() -> bool:
    """Whether no JAX transformation is tracing now, so a jitted function called now is the
    outermost program (JAX accepts compiler options only there). Reads JAX's trace state
    (``jax._src.core.trace_state_clean``; tests/test_compiler.py fails if a JAX release moves it);
    where it cannot be read, False: the options are then never used, and results are unchanged."""
    try:
        from jax._src.core import trace_state_clean
    except ImportError:  # pragma: no cover - a JAX release that moved it
        return False
    return trace_state_clean()


class _Jitted:
    """``fun`` jitted twice: with :data:`OPTIONS` for calls made outside any JAX transformation with
    the CPU as JAX's default backend; plain otherwise, i.e. on a GPU and for calls inside a
    transformation (another ``jit``, ``grad``, ``vmap``), which JAX compiles with the outermost
    program's options. Attributes (``lower``, ``trace``, ``_cache_size``, ...) are the first's."""

    def __init__(self, fun, options, kwargs):
        functools.update_wrapper(self, fun)
        self.top = jax.jit(fun, compiler_options=options, **kwargs)
        self.nested = jax.jit(fun, **kwargs)

    def __call__(self, *args, **kwargs):
        wide = at_top_level() and jax.default_backend() == "cpu"
        return (self.top if wide else self.nested)(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.top, name)


#: Every function compiled with :data:`OPTIONS` so far, by ``module.qualname``: each must be
#: checked against XLA's default width and an independent reference (``tests/test_compiler.py``).
PROGRAMS: set = set()


def jit(fun=None, **kwargs):
    """``jax.jit`` with :data:`OPTIONS` for programs free of XLA's trigonometric primitives (see the
    module docstring). Usable as ``jit(f, ...)`` or as a decorator ``@jit(...)``.

    Called from inside another ``jit`` (or ``grad``, ``vmap``), the function is traced into that
    program, which keeps its own compiler options: wrap the outer function in :func:`jit` too to
    give it these. Where :data:`OPTIONS` is empty this is plain ``jax.jit``."""
    if fun is None:
        return partial(jit, **kwargs)
    PROGRAMS.add(f"{getattr(fun, '__module__', '?')}.{getattr(fun, '__qualname__', type(fun).__name__)}")
    if not OPTIONS:
        return jax.jit(fun, **kwargs)
    return _Jitted(fun, dict(OPTIONS), kwargs)


def settings_source(environ=None) -> str:
    """Where the CPU settings of this process come from, in words: ``"calibrated"`` (this CPU's
    calibration, :mod:`pfjax.numerics.calibration`) or ``"rules"`` (the stated defaults), then
    ``"; vector width from PFJAX_VECTOR_WIDTH"`` where that variable sets the width (a whole number
    of bits, as :func:`vector_width` reads it) and ``"; sine-cosine sharing from PFJAX_SINCOS_SHARING"``
    where that one sets the sharing, or ``"; sine-cosine sharing from the rules"`` where a
    calibration written before the sharing was measured leaves it to the rule; the blocks come from
    the first."""
    environ = os.environ if environ is None else environ
    calibrated = calibration.vector_width()[0]
    base = "calibrated" if calibrated else "rules"
    if environ.get(VECTOR_WIDTH_ENV, "").strip().isdigit():
        base += f"; vector width from {VECTOR_WIDTH_ENV}"
    if calibration.sharing_from_env(environ, warn=False):
        base += f"; sine-cosine sharing from {calibration.SHARING_ENV}"
    elif calibrated and calibration.sincos_sharing("float32") is None:
        base += "; sine-cosine sharing from the rules"
    return base
