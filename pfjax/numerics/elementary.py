"""Fast, vectorisable elementary functions in plain ``jnp`` (sin, cos, tan, atan, atan2, angle wrap,
reciprocal square root), and a clip and a quotient whose derivatives cost no extra division.

XLA's CPU ``sin``/``cos``/``tan``/``atan2`` cost several times a multiply-add chain per element and
each call repeats its own range reduction. These versions are short polynomial chains that XLA
fuses with their neighbours, and ``sin``, ``cos`` and ``tan`` of one argument share one reduction
(:func:`sincos`), so a fused kernel that needs both pays once. On CPU the pair is computed once per
fused program and read by the kernels that need it, as a CPU-dependent setting says
(:func:`sincos_sharing`: divided by an exact 1 as one complex number or as two reals, or
recomputed; ``pfjax calibrate`` measures which is fastest). They work under ``jit``, ``vmap``
and ``grad`` (the derivative of the polynomial approximates the true derivative to a few ulp).

Method (classic Cody-Waite / Cephes scheme):

* ``sin``, ``cos``: ``k = round(x 2/pi)``, ``r = x - k pi/2`` with ``pi/2`` split into four parts
  so that ``k * part_i`` is exact for the first three (``|r| <= pi/4``, accurate relative to ``r``
  also near the zeros, where ``r`` is tiny); ``sin r = r + r z P(z)``, ``cos r = 1 + z Q(z)``
  with ``z = r^2``; the quadrant ``k mod 4`` picks and signs them. ``tan = sin / cos``.
* ``atan``: ``|x|`` reduced to ``|t| <= tan(pi/8)`` by ``t = -1/|x|`` (``|x| > tan(3pi/8)``) or
  ``t = (|x|-1)/(|x|+1)`` (one division), then ``atan t = t + t z R(z)``. ``atan2`` does the same on
  ``min(|x|,|y|) / max(|x|,|y|)`` and fixes the octant.
* ``wrap_angle``: ``a - 2 pi round(a / 2 pi)`` with a split ``2 pi``, mapped into ``(-pi, pi]``.
* ``rsqrt``: ``1 / sqrt(x)``; in float64 on CPU as ``sqrt(1 / x)`` (see :func:`rsqrt`).

Derivatives are exact formulas on the primal outputs (``jax.custom_jvp``): ``d sin = cos dx``,
``d cos = -sin dx``, ``d atan = dx / (1 + x^2)``, ``d atan2 = (x dy - y dx) / (x^2 + y^2)``,
``d wrap = da``, ``d tan = (1 + tan^2) dx``, so reverse mode through a simulator costs two multiplies
per call instead of the polynomial chain's derivative. :func:`clip` and :func:`divide` keep
``jnp.clip``'s and ``/``'s values but not JAX's derivative rules, which divide: ``max`` and ``min``
split a tie's derivative by a division per operand, and a quotient's rule takes two divisions per
tangent. A vector division costs several multiplies, and a forward-mode tangent pays for each
(docs/performance.md, Gradients). Each function is jitted: a simulator calls them hundreds of times
per step, and tracing each call op by op made tracing the slowest part of compiling a simulation.

The polynomial coefficients are least-squares fits on Chebyshev nodes in NumPy float64, computed
once at import (deterministic); degrees are the smallest whose fit error is below the working
precision's rounding. Accuracy against NumPy (measured by ``tests/test_elementary.py`` over the
whole float range and near every multiple of pi/2; the README states the numbers): within a few
ulp for ``|x| <= REDUCTION_LIMIT``
(``sin``/``cos``/``tan``; beyond it the reduction loses accuracy gradually), everywhere for
``atan``/``atan2``/``wrap_angle``. Special values follow IEEE/NumPy: NaN in, NaN out;
``sin(+-inf) = NaN``; ``atan(+-inf) = +-pi/2``; ``atan2`` of zeros and infinities as NumPy.
"""

from __future__ import annotations

import contextlib
import functools
from decimal import Decimal, getcontext
from functools import cache, partial

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.custom_derivatives import SymbolicZero

from pfjax.numerics import calibration
from pfjax.numerics.cpu import CPUINFO, is_intel

_PI_DIGITS = "3.14159265358979323846264338327950288419716939937510582097494459230781640628620899863"

#: Largest |x| for which sin/cos/tan keep their stated accuracy (the reduction's ``k * part_1`` is exact).
REDUCTION_LIMIT = {np.dtype(np.float32): 2.0**12, np.dtype(np.float64): 2.0**27}


def _split(value: Decimal, bits: tuple[int, ...], dtype) -> tuple:
    """``value`` as a sum of ``len(bits)`` floats of ``dtype``, part ``i`` with ``bits[i]`` significant bits
    (the last part rounded to full precision)."""
    parts, rest = [], value
    for i, b in enumerate(bits):
        if i == len(bits) - 1:
            p = float(rest)
        else:
            m, e = np.frexp(float(rest))
            p = float(np.ldexp(np.floor(np.ldexp(m, b)), e - b))
        p = float(np.dtype(dtype).type(p))
        parts.append(p)
        rest = rest - Decimal(p)
    return tuple(parts)


def _fit(f, hi: float, deg: int) -> tuple[float, ...]:
    """Coefficients (lowest power first) of the degree-``deg`` least-squares polynomial in ``z`` on ``[0, hi]``
    fitted to ``f(z)`` at 4 ``deg`` Chebyshev nodes."""
    n = 4 * (deg + 1)
    z = hi * 0.5 * (1.0 - np.cos(np.pi * (np.arange(n) + 0.5) / n))
    z = np.concatenate([[0.0], z])
    return tuple(float(c) for c in np.polynomial.Polynomial.fit(z, f(z).astype(np.float64), deg).convert().coef)


def _sin_core(z):  # (sin r - r) / (r z), r = sqrt(z)
    z = np.longdouble(z)  # extended precision: sin r - r cancels
    r = np.sqrt(z)
    out = np.empty_like(z)
    small = r < 1e-3
    out[~small] = (np.sin(r[~small]) - r[~small]) / (r[~small] * z[~small])
    zs = z[small]
    out[small] = -1 / 6 + zs / 120 - zs * zs / 5040
    return out


def _cos_core(z):  # (cos r - 1) / z
    z = np.longdouble(z)
    r = np.sqrt(z)
    out = np.empty_like(z)
    small = r < 1e-3
    out[~small] = (np.cos(r[~small]) - 1.0) / z[~small]
    zs = z[small]
    out[small] = -0.5 + zs / 24 - zs * zs / 720
    return out


def _atan_core(z):  # (atan t - t) / (t z), t = sqrt(z)
    z = np.longdouble(z)
    t = np.sqrt(z)
    out = np.empty_like(z)
    small = t < 1e-3
    out[~small] = (np.arctan(t[~small]) - t[~small]) / (t[~small] * z[~small])
    zs = z[small]
    out[small] = -1 / 3 + zs / 5 - zs * zs / 7
    return out


_Z_SIN = (np.pi / 4) ** 2
_Z_ATAN = float(np.tan(np.pi / 8)) ** 2
#: polynomial degrees in z = r^2 per dtype (the smallest with fit error below the dtype's rounding)
_DEGREES = {
    np.dtype(np.float32): dict(sin=3, cos=4, atan=5),
    np.dtype(np.float64): dict(sin=6, cos=7, atan=10),
}


@cache
def _constants(dtype: np.dtype) -> dict:
    getcontext().prec = 60
    pi = Decimal(_PI_DIGITS)
    deg = _DEGREES[dtype]
    bits = (12, 12, 24) if dtype == np.float32 else (26, 26, 53)
    return dict(
        pio2=_split(pi / 2, bits[:2] + bits[:1] + bits[2:], dtype),  # four parts: see _sincos
        twopi=_split(2 * pi, bits, dtype),
        sin=_fit(_sin_core, _Z_SIN, deg["sin"]),
        cos=_fit(_cos_core, _Z_SIN, deg["cos"]),
        atan=_fit(_atan_core, _Z_ATAN, deg["atan"]),
    )


def _float(x) -> Array:
    x = jnp.asarray(x)
    return x if jnp.issubdtype(x.dtype, jnp.floating) else x.astype(jnp.result_type(float))


def _horner(coef, z):
    acc = jnp.asarray(coef[-1], z.dtype)
    for c in coef[-2::-1]:
        acc = acc * z + c
    return acc


def _const(x: Array) -> dict:
    return _constants(np.dtype(x.dtype))


def sincos(x) -> tuple[Array, Array]:
    """``(sin x, cos x)`` with one shared range reduction (x in rad); on CPU computed once per fused
    program as :func:`sincos_sharing` says."""
    x = _float(x)
    return _sincos_jit(x, sincos_sharing(x.dtype))


#: How :func:`sincos` hands its pair to the kernels that read it on CPU (:func:`sincos_sharing`):
#: ``"complex"``: divided as one complex number by an exact ``1 + 0i`` (:func:`computed_once_pair`),
#: ``"real"``: each divided by an exact 1 (:func:`computed_once`'s division), ``"none"``: no
#: division, each kernel recomputes the pair. Values and derivatives are the same in all three.
SINCOS_SHARING = calibration.SHARINGS
SINCOS_SHARING_ENV = calibration.SHARING_ENV
_SHARING_OVERRIDE: dict[str, str] = {}


@functools.cache  # read once per file: every sincos a simulator traces asks
def sincos_sharing_rule(cpuinfo: str = CPUINFO) -> str:
    """The sharing :func:`sincos` uses without a calibration or ``PFJAX_SINCOS_SHARING``: ``"real"``
    on Intel CPUs, ``"complex"`` on others. Measured with the benchmark's simulator program
    (``pfjax.bench``'s problem, 10^4 runs, million rollout-steps/s, float32 / float64; the minimal
    implementation in parentheses): on a 2-core Intel Xeon (family 6, model 207, AVX-512) complex
    101.7 / 42.4 (131.7 / 54.8), real 111.0 / 45.9 (149.3 / 58.1), none 110.7 / 43.1 (158.1 / 56.5);
    on AMD EPYCs (Zen 3, AVX2) the complex division took float64 from 12.0 to 17.4 and two real ones
    gained nothing in float32 and lost a little in float64 (docs/performance.md)."""
    return "real" if is_intel(cpuinfo) else "complex"


@functools.cache  # read once per process, as it is asked at every trace
def _sharing_from_env() -> str | None:
    return calibration.sharing_from_env()


def sincos_sharing(dtype) -> str:
    """How :func:`sincos` shares its pair in programs of ``dtype`` traced now (one of
    :data:`SINCOS_SHARING`): :func:`sharing_mode`'s where one is active, else ``PFJAX_SINCOS_SHARING``,
    else this CPU's calibration (:mod:`pfjax.numerics.calibration`, ``pfjax calibrate``), else
    :func:`sincos_sharing_rule`. Read when a program is traced: a compiled program keeps its own.
    Only CPU programs divide; elsewhere the pair is never divided."""
    name = np.dtype(dtype).name
    if name in _SHARING_OVERRIDE:
        return _SHARING_OVERRIDE[name]
    return _sharing_from_env() or calibration.sincos_sharing(name) or sincos_sharing_rule()


@contextlib.contextmanager
def sharing_mode(mode: str, dtypes=("float32", "float64")):
    """Trace programs with ``mode`` (one of :data:`SINCOS_SHARING`) as :func:`sincos`'s sharing for
    ``dtypes`` inside the ``with`` block (``pfjax calibrate`` measures each this way). JAX keeps one
    trace per function whatever the jit wrapping it, and also caches the traces of loop bodies
    (``lax.scan``, ``fori_loop``) and ``jax.checkpoint`` targets by their function: a program
    traced before keeps its sharing, so trace new function objects inside (``jax.jit(lambda x:
    f(x))``, whose loop bodies are closures made at trace time, as the simulators' are), or call
    ``jax.clear_caches()``. The setting is the process's, not a thread's: use it where no other
    thread traces."""
    if mode not in SINCOS_SHARING:
        raise ValueError(f"sharing mode {mode!r}: expected one of {', '.join(SINCOS_SHARING)}")
    before = dict(_SHARING_OVERRIDE)
    _SHARING_OVERRIDE.update(dict.fromkeys((np.dtype(d).name for d in dtypes), mode))
    try:
        yield
    finally:
        _SHARING_OVERRIDE.clear()
        _SHARING_OVERRIDE.update(before)


@partial(jax.custom_jvp, nondiff_argnums=(1,))
def _sincos(x, sharing):
    c = _const(x)
    p1, p2, p3, p4 = c["pio2"]
    k = jnp.round(x * (2.0 / np.pi))
    # pi/2 to about 2.5x the working precision (parts of 12, 12, 12, 24 bits in float32; 26, 26, 26,
    # 53 in float64; k * part exact for the first three): near a zero of sin or cos, r is tiny and
    # its relative accuracy is that of the split (three parts gave up to 622 / 4431 ulp there).
    r = (((x - k * p1) - k * p2) - k * p3) - k * p4
    z = r * r
    s = r + r * z * _horner(c["sin"], z)
    co = 1.0 + z * _horner(c["cos"], z)
    q = jnp.where(jnp.isfinite(k), k, 0.0).astype(jnp.int32) & 3
    swap = (q & 1) == 1
    sin = jnp.where(swap, co, s)
    cos = jnp.where(swap, s, co)
    sin = jnp.where(q >= 2, -sin, sin)
    sin = jnp.where(x == 0.0, x, sin)  # sin(+-0) = +-0 (the reduction and the polynomial give +0)
    cos = jnp.where((q == 1) | (q == 2), -cos, cos)
    if sharing == "complex":
        return computed_once_pair(sin, cos, x)
    if sharing == "real":
        return jax.lax.platform_dependent(sin, cos, x, cpu=_each_divided_by_one, default=lambda a, b, x: (a, b))
    return sin, cos


def computed_once_pair(a, b, x):
    """``(a, b)`` unchanged, but computed once per fused program (``a`` and ``b`` of one shape and
    float dtype; exact where both are finite or both NaN, since an infinite one makes the other
    ``inf * 0 = NaN``). Used for the sine-cosine pair where its sharing is ``"complex"``
    (:func:`sincos_sharing`), the simulators' random draws and the ST model's branch-selected rates
    (:func:`pfjax.models.single_track.vector_field`).

    XLA's CPU backend never shares work between two fused kernels: every kernel that uses a cheap
    elementwise value (a polynomial sine) recomputes it from the last values held in memory, and a
    simulator step reads the sine and cosine of one angle in up to eight kernels. An *expensive*
    operation used more than once is computed in a kernel of its own instead. So the pair is
    divided, as one complex number ``b + ia``, by exactly ``1 + 0i``, written from ``x`` so that XLA
    cannot fold it away (``x == x`` is false only for NaN, and then ``a`` and ``b`` are NaN anyway):
    one kernel computes both, the others read them. The division is exact (``r = 0/1``), so values
    and derivatives are unchanged; it costs one complex division. Measured on the benchmark (B = 10^5,
    blocks of 10^4, an AMD EPYC): float64 12.0 -> 17.4 M rollout-steps/s, float32 47.0 -> 49.8; on an
    Intel Xeon two real divisions cost less (:func:`sincos_sharing_rule`). CPU only: XLA's
    GPU backend fuses several outputs into one kernel by itself, and there the complex division
    cost 14-19 % of the float64 throughput (H100; docs/performance.md, *On a GPU*).
    """
    return jax.lax.platform_dependent(a, b, x, cpu=_divided_by_one, default=lambda a, b, x: (a, b))


def computed_once(x):
    """``x`` unchanged, but computed once per fused program on CPU, and so is its cotangent.

    ``x`` is divided by an exact 1 written from ``x`` (as in :func:`computed_once_pair`), so XLA's CPU
    backend computes it in a kernel of its own instead of again in every kernel that reads it. Its
    tangent is divided by the same 1, so the transpose of that division puts reverse mode's cotangent
    of ``x`` in a kernel of its own too: the backward step then sums the cotangent's contributions
    once instead of recomputing them in each kernel that needs it. Values and derivatives are exact
    (the division by 1 is). Used for the ST model's yaw rate ``psi'``, and for the slip simulator's
    closest-point parameter, steering command and applied steering. Measured on the benchmark (README, Performance): the reverse-mode gradient
    about 30 % less CPU time; forward-mode gradients (whose tangents the same division puts in
    kernels of their own) about 13 % more; the forward pass 1-2.5 % slower. Identity off CPU."""
    return jax.lax.platform_dependent(x, cpu=lambda x: x / _one_from(x), default=lambda x: x)


def _one_from(x):
    """An exact 1 that XLA cannot fold: ``x == x`` is false only for NaN (then 2, and the quotient is
    NaN anyway)."""
    return jnp.where(x == x, 1.0, 2.0).astype(x.dtype)


def _divided_by_one(sin, cos, x):
    """``(sin, cos)`` as ``(cos + i sin) / (1 + 0i)``: real ``cos + sin * 0``, imaginary ``sin - cos * 0``
    (exactly ``sin`` and ``cos``; a zero sine keeps its sign since then ``x = +-0`` and ``cos = 1``)."""
    one = _one_from(x).astype(sin.dtype)
    z = jax.lax.complex(cos, sin) / jax.lax.complex(one, jnp.zeros_like(one))
    return jnp.imag(z), jnp.real(z)


def _each_divided_by_one(sin, cos, x):
    """``(sin, cos)``, each divided by an exact 1 written from ``x`` (:func:`_one_from`)."""
    one = _one_from(x).astype(sin.dtype)
    return sin / one, cos / one


@_sincos.defjvp
def _sincos_jvp(sharing, primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = _sincos(x, sharing)
    return (s, c), (c * dx, -s * dx)


_sincos_jit = jax.jit(_sincos, static_argnums=1)


def sin(x) -> Array:
    """``sin x`` (x in rad)."""
    return sincos(x)[0]


def cos(x) -> Array:
    """``cos x`` (x in rad)."""
    return sincos(x)[1]


def tan(x) -> Array:
    """``tan x = sin x / cos x`` (x in rad; one reduction, one division). Derivative
    ``d tan = (1 + tan^2 x) dx`` on the output: no division per tangent (the quotient's own rule
    takes two)."""
    x = _float(x)
    return _tan_jit(x, sincos_sharing(x.dtype))


@partial(jax.custom_jvp, nondiff_argnums=(1,))
def _tan(x, sharing):
    s, c = _sincos(x, sharing)
    return s / c


@_tan.defjvp
def _tan_jvp(sharing, primals, tangents):
    (x,), (dx,) = primals, tangents
    t = _tan(x, sharing)
    return t, (1.0 + t * t) * dx


_tan_jit = jax.jit(_tan, static_argnums=1)


def _atan_reduced(num, den, base):
    """``base + atan(num / den)`` for ``|num / den| <= tan(pi/8)``."""
    t = num / den
    z = t * t
    return base + (t + t * z * _horner(_const(t)["atan"], z))


def atan(x) -> Array:
    """``arctan x`` in ``[-pi/2, pi/2]`` rad."""
    return _atan_jit(_float(x))


@jax.custom_jvp
def _atan(x):
    a = jnp.abs(x)
    big = a > 2.414213562373095  # tan(3 pi / 8)
    mid = a > 0.41421356237309503  # tan(pi / 8)
    num = jnp.where(big, -1.0, jnp.where(mid, a - 1.0, a))
    den = jnp.where(big, jnp.where(jnp.isinf(a), 1.0, a), jnp.where(mid, a + 1.0, 1.0))
    num = jnp.where(jnp.isinf(a), 0.0, num)  # atan(inf) = pi/2 exactly
    base = jnp.where(big, np.pi / 2, jnp.where(mid, np.pi / 4, 0.0)).astype(x.dtype)
    r = _atan_reduced(num, den, base)
    return jnp.where(jnp.signbit(x), -r, r)


@_atan.defjvp
def _atan_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    return _atan(x), dx / (1.0 + x * x)


_atan_jit = jax.jit(_atan)


def atan2(y, x) -> Array:
    """``arctan2(y, x)`` in ``[-pi, pi]`` rad, NumPy's conventions for zeros and infinities."""
    y, x = _float(y), _float(x)
    dtype = jnp.result_type(y, x)
    y, x = jnp.broadcast_arrays(y.astype(dtype), x.astype(dtype))
    return _atan2_jit(y, x)


@jax.custom_jvp
def _atan2(y, x):
    ax, ay = jnp.abs(x), jnp.abs(y)
    both_inf = jnp.isinf(ax) & jnp.isinf(ay)
    ax1 = jnp.where(both_inf, 1.0, ax)
    ay1 = jnp.where(both_inf, 1.0, ay)
    mn, mx = jnp.minimum(ax1, ay1), jnp.maximum(ax1, ay1)
    mid = mn > 0.41421356237309503 * mx  # ratio beyond tan(pi/8): reduce by pi/4
    zero = mx == 0.0
    num = jnp.where(mid, mn - mx, mn)
    den = jnp.where(mid, mn + mx, jnp.where(zero, 1.0, mx))
    num = jnp.where(jnp.isinf(mx), 0.0, num)  # finite / inf: ratio 0 (den = inf already)
    den = jnp.where(jnp.isinf(mx) & mid, 1.0, den)
    a = _atan_reduced(num, den, jnp.where(mid, np.pi / 4, 0.0).astype(x.dtype))  # angle in [0, pi/4]
    a = jnp.where(ay1 > ax1, np.pi / 2 - a, a)
    a = jnp.where(jnp.signbit(x), np.pi - a, a)
    return jnp.where(jnp.signbit(y), -a, a)


@_atan2.defjvp
def _atan2_jvp(primals, tangents):
    (y, x), (dy, dx) = primals, tangents
    return _atan2(y, x), (x * dy - y * dx) / (x * x + y * y)


_atan2_jit = jax.jit(_atan2)


def wrap_angle(a) -> Array:
    """Wrap an angle to ``(-pi, pi]`` rad: ``a - 2 pi round(a / 2 pi)``."""
    return _wrap_jit(_float(a))


@jax.custom_jvp
def _wrap(a):
    p1, p2, p3 = _const(a)["twopi"]
    k = jnp.round(a * (0.5 / np.pi))
    w = ((a - k * p1) - k * p2) - k * p3
    w = jnp.where(w <= -np.pi, w + 2.0 * np.pi, w)
    return jnp.where(w > np.pi, w - 2.0 * np.pi, w)


@_wrap.defjvp
def _wrap_jvp(primals, tangents):
    (a,), (da,) = primals, tangents
    return _wrap(a), da


_wrap_jit = jax.jit(_wrap)


_RSQRT_SCALE = 2.0**1000  # |log2 x| beyond 1000: scale x by 2^-+1000 so that 1 / x stays a normal number


def rsqrt(x) -> Array:
    """``1 / sqrt(x)`` (``inf`` at 0, 0 at ``inf``, NaN below 0).

    XLA's CPU backend evaluates a float64 ``rsqrt`` one element at a time, and its simplifier
    rewrites every ``a / sqrt(x)`` into ``a * rsqrt(x)``: 4.2 ns per element on this machine against
    1.1 ns for ``sqrt(1 / x)``, one vector division and one vector square root (the closest-point
    Newton step, which bounds its step by such a ratio, cost 8.7 ns against 1.5 ns; README,
    Performance). So on CPU a float64 ``x`` is computed as ``sqrt(1 / x)``, with ``x`` scaled by an
    exact power of 2 beyond ``2^+-1000`` so that ``1 / x`` neither overflows nor loses bits as a
    subnormal: within 1 ulp of the correctly rounded value over the whole range (two roundings, the
    first halved by the square root; 0.85 ulp measured by ``tests/test_elementary.py``, against 1.5
    for ``lax.rsqrt``). Float32, and every dtype on other platforms, use ``lax.rsqrt`` (float32 on
    CPU: within 1.64 ulp, as fast as ``sqrt(1 / x)``, and float32 results stay as they were).
    Derivative: ``d rsqrt = -r^3 dx / 2`` on the output ``r``.
    """
    return _rsqrt_jit(_float(x))


@jax.custom_jvp
def _rsqrt(x):
    if x.dtype != np.float64:
        return jax.lax.rsqrt(x)
    return jax.lax.platform_dependent(x, cpu=_rsqrt_by_division, default=jax.lax.rsqrt)


def _rsqrt_by_division(x):
    big, small = x > _RSQRT_SCALE, x < 1.0 / _RSQRT_SCALE
    xs = jnp.where(big, x * (1.0 / _RSQRT_SCALE), jnp.where(small, x * _RSQRT_SCALE, x))
    r = jnp.sqrt(1.0 / xs)  # -inf gives sqrt(-0) = -0: NaN, as every x < 0
    scale = jnp.where(big, 2.0**-500, jnp.where(small, 2.0**500, 1.0)).astype(x.dtype)
    return jnp.where(x < 0.0, np.nan, r * scale)


@_rsqrt.defjvp
def _rsqrt_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    r = _rsqrt(x)
    return r, -0.5 * r * r * r * dx


_rsqrt_jit = jax.jit(_rsqrt)


def clip(x, lo, hi) -> Array:
    """``min(max(x, lo), hi)``, as ``jnp.clip(x, lo, hi)``, with a derivative that selects.

    JAX differentiates ``max`` and ``min`` by a balanced rule that splits a tie's derivative
    ``1/2 : 1/2`` and costs a division per operand and tangent: two vector divisions per clip in a
    forward-mode tangent, in the simulator's step and its Newton projection. Here the derivative is
    ``dx`` on ``lo <= x <= hi`` (ties included), ``dlo`` below and ``dhi`` above, with no division.
    Values are ``jnp.clip``'s (NaN in, NaN out).
    """
    dtype = jnp.result_type(x, lo, hi)
    x, lo, hi = jnp.broadcast_arrays(*(jnp.asarray(a, dtype) for a in (x, lo, hi)))
    return _clip_jit(x, lo, hi)


@jax.custom_jvp
def _clip(x, lo, hi):
    return jnp.minimum(jnp.maximum(x, lo), hi)


@_clip.defjvp
def _clip_jvp(primals, tangents):
    (x, lo, hi), (dx, dlo, dhi) = primals, tangents
    return _clip(x, lo, hi), jnp.where(x < lo, dlo, jnp.where(x > hi, dhi, dx))


_clip_jit = jax.jit(_clip)


def divide(x, y) -> Array:
    """``x / y`` with a derivative of one division per tangent.

    JAX differentiates a quotient as ``dx / y - x dy / y^2``: two vector divisions per tangent
    where both ``x`` and ``y`` carry one. Here ``dq = (dx - q dy) / y`` on the output ``q``: one
    division (``dx / y`` where ``y`` carries none). Values are ``x / y``'s.
    """
    dtype = jnp.result_type(x, y)
    x, y = jnp.broadcast_arrays(jnp.asarray(x, dtype), jnp.asarray(y, dtype))
    return _divide_jit(x, y)


@jax.custom_jvp
def _divide(x, y):
    return x / y


def _divide_jvp(primals, tangents):
    (x, y), (dx, dy) = primals, tangents
    q = _divide(x, y)
    if isinstance(dy, SymbolicZero):
        return q, (jnp.zeros_like(q) if isinstance(dx, SymbolicZero) else dx / y)
    return q, ((-q * dy) if isinstance(dx, SymbolicZero) else (dx - q * dy)) / y


_divide.defjvp(_divide_jvp, symbolic_zeros=True)
_divide_jit = jax.jit(_divide)
