"""Fast elementary functions (pfjax.numerics.elementary) against NumPy in extended precision.

Inputs cover each function's whole float range: uniform on the reduced range, on the stated
reduction range, and log-uniform magnitudes from 1e-30 to 1e30 (atan, atan2), plus the special
values. Errors are in ulp of the correctly rounded result in the working dtype (NumPy longdouble
as the reference; errors below the smallest normal number count as 1 ulp, XLA flushes subnormals),
with bounds a little above the measured maxima (the README states them).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.numerics import elementary as E

# max ulp error allowed: (float32, float64)
ULP = {"sin": (3, 3), "cos": (3, 3), "tan": (4, 5), "atan": (3, 3), "atan2": (3, 3)}
DTYPES = (np.float32, np.float64)
RNG = np.random.default_rng(8)
# XLA's CPU vector widths the functions are compiled with: its default, and the 512 bits pfjax's
# simulators ask for on AVX-512 CPUs (pfjax.numerics.compiler; with 512, XLA's own atan is wrong,
# so pfjax's must be checked under it). On a CPU without AVX-512 LLVM splits the wide vectors.
WIDTHS = (None, 512)


def _jit(f, width):
    return jax.jit(f, compiler_options=None if width is None else {"xla_cpu_prefer_vector_width": width})


def _ulp_err(got, ref, dtype):
    ref_d = ref.astype(dtype)
    ok = np.isfinite(ref_d)
    # XLA's CPU kernels flush subnormals to zero: an error below the smallest normal number counts as 1 ulp.
    ulp = np.maximum(np.spacing(np.abs(ref_d)), np.finfo(dtype).tiny).astype(np.longdouble)
    return float(np.max(np.abs(np.asarray(got, np.longdouble) - ref)[ok] / ulp[ok]))


def _trig_inputs(dtype):
    """Random arguments over the reduction range, plus the floats nearest to k pi/2 and their next
    three neighbours (where sin or cos is tiny and the reduction's own accuracy shows), the same
    set whatever order the tests run in."""
    rng = np.random.default_rng(8)
    lim = E.REDUCTION_LIMIT[np.dtype(dtype)]
    x = np.concatenate(
        [
            rng.uniform(-np.pi, np.pi, 60000),
            rng.uniform(-lim, lim, 60000),
            np.sign(rng.standard_normal(20000)) * np.exp(rng.uniform(np.log(1e-30), np.log(lim), 20000)),
        ]
    )
    k = np.unique(np.geomspace(1, 2 * lim / np.pi - 1, 5000).astype(np.int64))
    near = [(k * (np.longdouble(np.pi) / 2)).astype(dtype)]
    for _ in range(3):
        near.append(np.nextafter(near[-1], dtype(np.inf)))
    near = np.concatenate(near)
    return np.concatenate([x.astype(dtype), near, -near])


def _wide_inputs(dtype):
    hi = 30 if dtype == np.float32 else 300
    x = np.sign(RNG.standard_normal(100000)) * np.exp(RNG.uniform(-hi * np.log(10), hi * np.log(10), 100000))
    return np.concatenate([x, RNG.uniform(-3, 3, 50000)]).astype(dtype)


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ["sin", "cos", "tan"])
def test_trig_accuracy(name, dtype, width):
    x = _trig_inputs(dtype)
    got = np.asarray(_jit(getattr(E, name), width)(x))
    assert got.dtype == dtype
    ref = getattr(np, name)(x.astype(np.longdouble))
    assert _ulp_err(got, ref, dtype) <= ULP[name][dtype == np.float64]


@pytest.mark.parametrize("dtype", DTYPES)
def test_sincos_is_sin_and_cos(dtype):
    x = _trig_inputs(dtype)[:5000]
    s, c = jax.jit(E.sincos)(x)
    # both jitted: XLA may contract a*b+c into an FMA inside a fused kernel, not op by op
    np.testing.assert_array_equal(np.asarray(s), np.asarray(jax.jit(E.sin)(x)))
    np.testing.assert_array_equal(np.asarray(c), np.asarray(jax.jit(E.cos)(x)))


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("dtype", DTYPES)
def test_atan_accuracy(dtype, width):
    x = _wide_inputs(dtype)
    got = np.asarray(_jit(E.atan, width)(x))
    assert _ulp_err(got, np.arctan(x.astype(np.longdouble)), dtype) <= ULP["atan"][dtype == np.float64]


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("dtype", DTYPES)
def test_atan2_accuracy_all_quadrants(dtype, width):
    y, x = _wide_inputs(dtype), RNG.permutation(_wide_inputs(dtype))
    got = np.asarray(_jit(E.atan2, width)(y, x))
    ref = np.arctan2(y.astype(np.longdouble), x.astype(np.longdouble))
    assert _ulp_err(got, ref, dtype) <= ULP["atan2"][dtype == np.float64]


@pytest.mark.parametrize("dtype", DTYPES)
def test_special_values_match_numpy(dtype):
    v = np.array([0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, 1e-30, -1e-30], dtype)
    with np.errstate(invalid="ignore"):
        for name, ref in (("sin", np.sin), ("cos", np.cos), ("tan", np.tan), ("atan", np.arctan)):
            np.testing.assert_allclose(
                np.asarray(getattr(E, name)(v)),
                ref(v),
                rtol=4e-7 if dtype == np.float32 else 1e-15,
                equal_nan=True,
                err_msg=name,
            )
        np.testing.assert_array_equal(np.signbit(np.asarray(E.atan(v))), np.signbit(np.arctan(v)))
        a, b = np.meshgrid(v, v)
        got, ref = np.asarray(E.atan2(a, b)), np.arctan2(a, b)
        np.testing.assert_allclose(got, ref, rtol=4e-7 if dtype == np.float32 else 1e-15, equal_nan=True)
        num = ~np.isnan(ref)
        assert np.all(np.signbit(got[num]) == np.signbit(ref[num]))  # signed zeros and -pi vs pi as NumPy


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("dtype", DTYPES)
def test_wrap_angle(dtype, width):
    """Same angle (sin and cos to rounding), in (-pi, pi], and the identity inside it."""
    x = np.concatenate([_trig_inputs(dtype), np.array([np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0], dtype)])
    w = np.asarray(_jit(E.wrap_angle, width)(x)).astype(np.longdouble)
    assert np.all(w > -np.pi) and np.all(w <= np.float64(np.pi) + 1e-6 * (dtype == np.float32))
    xl = x.astype(np.longdouble)
    eps = np.finfo(dtype).eps
    tol = 4 * eps * np.maximum(1.0, np.abs(xl))  # the input's own rounding bounds what can be recovered
    assert np.all(np.abs(np.sin(w) - np.sin(xl)) <= tol) and np.all(np.abs(np.cos(w) - np.cos(xl)) <= tol)
    inside = np.abs(x) < 3.0
    np.testing.assert_array_equal(w[inside], xl[inside])


@pytest.mark.parametrize("name", ["sin", "cos", "tan", "atan"])
def test_gradients_match_xla(name):
    x = jnp.asarray(np.concatenate([RNG.uniform(-1.4, 1.4, 400), RNG.uniform(-50, 50, 400)]))
    mine = jax.vmap(jax.grad(getattr(E, name)))(x)
    ref = jax.vmap(jax.grad(getattr(jnp, {"atan": "arctan"}.get(name, name))))(x)
    np.testing.assert_allclose(mine, ref, rtol=1e-13, atol=1e-13)


def test_atan2_gradient_matches_xla():
    y, x = (jnp.asarray(RNG.uniform(-5, 5, 500)) for _ in range(2))
    mine = jax.vmap(jax.grad(E.atan2, argnums=(0, 1)))(y, x)
    ref = jax.vmap(jax.grad(jnp.arctan2, argnums=(0, 1)))(y, x)
    for m, r in zip(mine, ref):
        np.testing.assert_allclose(m, r, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("dtype", DTYPES)
def test_clip_is_jnp_clip_with_a_derivative_that_selects(dtype):
    """Values bit for bit ``jnp.clip``'s (NaN, infinities, ties, bounds that are arrays); the
    derivative ``dx`` on ``[lo, hi]`` (ties included), ``dlo`` below, ``dhi`` above, in forward and
    reverse mode, and no division in the forward-mode program (JAX's own max/min rule divides)."""
    x = np.concatenate([RNG.uniform(-3, 3, 200), [np.nan, np.inf, -np.inf, -1.0, 1.0, 0.0, -0.0]]).astype(dtype)
    lo = np.full_like(x, -1.0)
    hi = np.concatenate([RNG.uniform(0.5, 2.0, 200), np.full(7, 1.0)]).astype(dtype)
    got = np.asarray(E.clip(x, lo, hi))
    np.testing.assert_array_equal(got, np.asarray(jnp.clip(x, lo, hi)))
    assert got.dtype == dtype
    np.testing.assert_array_equal(np.asarray(E.clip(x, -1.0, 1.0)), np.clip(x, dtype(-1.0), dtype(1.0)))
    dx, dlo, dhi = (np.full_like(x, v) for v in (1.0, 10.0, 100.0))
    _, tangent = jax.jvp(E.clip, (x, lo, hi), (dx, dlo, dhi))
    want = np.where(x < lo, 10.0, np.where(x > hi, 100.0, 1.0))
    ok = ~np.isnan(x)
    np.testing.assert_array_equal(np.asarray(tangent)[ok], want[ok])
    g = jax.vmap(jax.grad(E.clip, argnums=(0, 1, 2)))(x[ok], lo[ok], hi[ok])
    for got_g, arg in zip(g, (1.0, 10.0, 100.0)):
        np.testing.assert_array_equal(np.asarray(got_g) * arg, np.where(want[ok] == arg, arg, 0.0))
    hlo = jax.jit(lambda a: jax.jvp(lambda v: E.clip(v, lo, hi), (a,), (dx,))).lower(x).as_text()
    assert "divide" not in hlo


@pytest.mark.parametrize("dtype", DTYPES)
def test_divide_is_the_quotient_with_one_division_per_tangent(dtype):
    """Values bit for bit ``x / y``'s; derivatives ``dx / y - x dy / y^2`` to rounding, with either
    argument constant, in forward and reverse mode and under vmap; one division per tangent where
    JAX's quotient rule takes two."""
    x, y = RNG.uniform(-3, 3, 300).astype(dtype), RNG.uniform(0.5, 3, 300).astype(dtype)
    np.testing.assert_array_equal(np.asarray(E.divide(x, y)), x / y)
    np.testing.assert_array_equal(np.asarray(E.divide(x, 2.0)), x / dtype(2.0))
    rtol = 1e-6 if dtype == np.float32 else 1e-14
    dx, dy = RNG.standard_normal(300).astype(dtype), RNG.standard_normal(300).astype(dtype)
    for tx, ty in ((dx, dy), (dx, np.zeros_like(dy)), (np.zeros_like(dx), dy)):
        _, t = jax.jvp(E.divide, (x, y), (tx, ty))
        np.testing.assert_allclose(np.asarray(t), tx / y - x * ty / y**2, rtol=rtol, atol=rtol)
    _, t = jax.jvp(lambda a: E.divide(a, y), (x,), (dx,))  # y constant: a symbolic zero
    np.testing.assert_allclose(np.asarray(t), dx / y, rtol=rtol)
    _, t = jax.jvp(lambda b: E.divide(x, b), (y,), (dy,))
    np.testing.assert_allclose(np.asarray(t), -x * dy / y**2, rtol=rtol, atol=rtol)
    gx, gy = jax.vmap(jax.grad(E.divide, argnums=(0, 1)))(x, y)
    np.testing.assert_allclose(np.asarray(gx), 1.0 / y, rtol=rtol)
    np.testing.assert_allclose(np.asarray(gy), -x / y**2, rtol=rtol, atol=rtol)

    def divisions(f):
        return jax.jit(lambda a, b: jax.jvp(f, (a, b), (dx, dy))).lower(x, y).compile().as_text().count(" divide(")

    assert divisions(E.divide) == 2 and divisions(lambda a, b: a / b) == 3  # value + tangent(s)


@pytest.mark.parametrize("dtype", DTYPES)
def test_computed_once_pair_is_an_exact_identity_and_cpu_only(dtype):
    """The (sin, cos) pair's division by 1 + 0i changes no value (NaN stays NaN, a sine of -0 stays -0), and
    only the CPU lowering carries it (XLA's GPU backend fuses several outputs by itself)."""
    x = np.concatenate([RNG.uniform(-1e3, 1e3, 500), [0.0, -0.0, np.inf, -np.inf, np.nan, 1e-30, -1e-30]]).astype(dtype)
    with np.errstate(invalid="ignore"):
        s, c = np.sin(x), np.cos(x)
    for divided in (E._divided_by_one, E._each_divided_by_one):  # the "complex" and the "real" sharing
        for got, want in zip(jax.jit(divided)(s, c, x), (s, c)):
            got = np.asarray(got)
            assert got.dtype == dtype
            np.testing.assert_array_equal(got, want)
            np.testing.assert_array_equal(np.signbit(got), np.signbit(want))
    zero = np.array([0.0, -0.0], dtype)
    for fn in (E.sin, E.tan):  # odd functions keep the sign of a zero, as NumPy
        np.testing.assert_array_equal(np.signbit(np.asarray(jax.jit(fn)(zero))), [False, True])
    for sharing in E.SINCOS_SHARING:
        with E.sharing_mode(sharing):
            f = jax.jit(lambda x: E.sincos(x))  # a new function (JAX caches traces per function)
            lowered = {p: f.trace(x).lower(lowering_platforms=(p,)).as_text() for p in ("cpu", "cuda")}
        assert ("complex" in lowered["cpu"]) == (sharing == "complex"), sharing
        assert ("divide" in lowered["cpu"]) == (sharing != "none"), sharing
        assert "complex" not in lowered["cuda"] and "divide" not in lowered["cuda"], sharing


def test_derivatives_follow_the_sincos_sharing():
    """The forward-mode and reverse-mode derivatives of sin, cos and tan are lowered with the sharing
    in force: complex numbers only where it is "complex", more divisions where it is "real" than where
    it is "none"."""
    x = np.linspace(-3.0, 3.0, 64, dtype=np.float32)

    def f(x):
        s, ds = jax.jvp(lambda x: E.sin(x) * E.tan(x), (x,), (jnp.ones_like(x),))
        return s, ds, jax.grad(lambda x: jnp.sum(E.cos(x) * E.tan(x)))(x)

    texts = {}
    for sharing in E.SINCOS_SHARING:
        with E.sharing_mode(sharing):
            texts[sharing] = jax.jit(lambda x: f(x)).trace(x).lower(lowering_platforms=("cpu",)).as_text()
    assert "complex" in texts["complex"] and "complex" not in texts["real"] and "complex" not in texts["none"]
    assert texts["real"].count("divide") > texts["none"].count("divide")


@pytest.mark.parametrize("dtype", DTYPES)
def test_every_sincos_sharing_gives_the_same_values_and_derivatives(dtype):
    """The three ways of sharing the sine-cosine pair between kernels (a CPU-dependent setting) change
    no value of sin, cos, tan or their derivatives, in one program or under vmap."""
    x = np.concatenate([RNG.uniform(-1e3, 1e3, 500), [0.0, -0.0, 1e-30, -1e-30, np.pi / 2]]).astype(dtype)
    dx = RNG.uniform(-2, 2, x.size).astype(dtype)

    def f(x, dx):
        (s, c), (ds, dc) = jax.jvp(E.sincos, (x,), (dx,))
        t, dt = jax.jvp(E.tan, (x,), (dx,))
        return s, c, ds, dc, t, dt, jax.grad(lambda x: jnp.sum(E.sin(x) * E.cos(x)))(x)

    outs = {}
    for sharing in E.SINCOS_SHARING:
        with E.sharing_mode(sharing):
            outs[sharing] = [np.asarray(a) for a in jax.jit(lambda x, dx: f(x, dx))(x, dx)]
    for sharing, got in outs.items():
        for a, b in zip(got, outs["complex"]):
            np.testing.assert_array_equal(a, b, err_msg=sharing)


def test_the_sincos_sharing_setting_rule_environment_and_calibration(tmp_path, monkeypatch):
    """The rule (Intel: two reals; others: one complex number), PFJAX_SINCOS_SHARING over a calibration
    over the rule, a bad value warned about and ignored, and sharing_mode over all of them."""
    from pfjax.numerics import calibration

    info = tmp_path / "cpuinfo"
    for vendor, want in (("GenuineIntel", "real"), ("AuthenticAMD", "complex"), ("", "complex")):
        info.write_text(f"vendor_id\t: {vendor}\nflags\t: avx2\n\n")
        E.sincos_sharing_rule.cache_clear()  # read once per file
        assert E.sincos_sharing_rule(str(info)) == want
    E.sincos_sharing_rule.cache_clear()
    rule = E.sincos_sharing_rule()
    cal = dict(sincos_sharing={"float32": "none", "float64": "real"})
    monkeypatch.setattr(calibration, "load", lambda path=None: cal)
    E._sharing_from_env.cache_clear()
    try:
        monkeypatch.delenv(E.SINCOS_SHARING_ENV, raising=False)
        assert E.sincos_sharing(np.float32) == "none" and E.sincos_sharing(np.float64) == "real"
        monkeypatch.setattr(calibration, "load", lambda path=None: {"sincos_sharing": None})
        assert E.sincos_sharing(np.float32) == rule  # a calibration that did not measure it: the rule
        E._sharing_from_env.cache_clear()
        monkeypatch.setenv(E.SINCOS_SHARING_ENV, "Complex")
        monkeypatch.setattr(calibration, "load", lambda path=None: cal)
        assert E.sincos_sharing(np.float32) == "complex"  # the variable over the calibration
        E._sharing_from_env.cache_clear()
        monkeypatch.setenv(E.SINCOS_SHARING_ENV, "fast")
        with pytest.warns(UserWarning, match="PFJAX_SINCOS_SHARING: value 'fast' ignored"):
            assert E.sincos_sharing(np.float64) == "real"
        with E.sharing_mode("complex", dtypes=("float64",)):  # float32 keeps the calibration's
            assert E.sincos_sharing(np.float64) == "complex" and E.sincos_sharing(np.float32) == "none"
        assert E.sincos_sharing(np.float64) == "real"
        with pytest.raises(ValueError, match="sharing mode 'fast'"):
            with E.sharing_mode("fast"):
                pass
    finally:
        E._sharing_from_env.cache_clear()


def test_one_parser_reads_the_sharing_variable_for_the_programs_and_the_settings_label():
    """``calibration.sharing_from_env`` is the one reading of ``PFJAX_SINCOS_SHARING``: the
    simulator's programs take it (with a warning for a value it ignores) and the settings label
    names it only where it set the sharing (silently: the warning is the programs')."""
    import warnings

    from pfjax.numerics import calibration, compiler

    env = lambda value: {calibration.SHARING_ENV: value}
    assert calibration.sharing_from_env({}) is None and calibration.sharing_from_env(env(" ")) is None
    assert calibration.sharing_from_env(env("  REAL ")) == "real"
    with pytest.warns(UserWarning, match="^PFJAX_SINCOS_SHARING: value 'fast' ignored, expected one of complex, real"):
        assert calibration.sharing_from_env(env("fast")) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert calibration.sharing_from_env(env("fast"), warn=False) is None
        assert compiler.settings_source(env(" None ")).endswith("; sine-cosine sharing from PFJAX_SINCOS_SHARING")
        assert "PFJAX_SINCOS_SHARING" not in compiler.settings_source(env("fast"))


@pytest.mark.parametrize("dtype", DTYPES)
def test_computed_once_is_an_exact_identity_with_exact_derivatives_and_cpu_only(dtype):
    """computed_once changes no value (signed zeros, infinities, NaN, tiny values included), its
    tangent and cotangent are exactly the incoming ones, and only the CPU lowering divides."""
    x = np.concatenate([RNG.uniform(-1e3, 1e3, 500), [0.0, -0.0, np.inf, -np.inf, np.nan, 1e-30, -1e-30]]).astype(dtype)
    got = np.asarray(jax.jit(E.computed_once)(x))
    assert got.dtype == dtype
    np.testing.assert_array_equal(got, x)
    np.testing.assert_array_equal(np.signbit(got), np.signbit(x))
    w = RNG.uniform(-2, 2, x.size).astype(dtype)
    _, tangent = jax.jvp(E.computed_once, (x,), (w,))
    np.testing.assert_array_equal(np.asarray(tangent)[np.isfinite(x)], w[np.isfinite(x)])
    cot = jax.vjp(E.computed_once, x)[1](w)[0]
    np.testing.assert_array_equal(np.asarray(cot)[np.isfinite(x)], w[np.isfinite(x)])
    # the simulator's gradient goes through it: K's gradient as before (test_autodiff), values bit-identical (test_sim)
    f = jax.jit(E.computed_once)
    lowered = {p: f.trace(x).lower(lowering_platforms=(p,)).as_text() for p in ("cpu", "cuda")}
    assert "divide" in lowered["cpu"] and "divide" not in lowered["cuda"]


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("dtype", DTYPES)
def test_rsqrt_accuracy_and_special_values(dtype, width):
    """1/sqrt(x) over the whole normal range (log-uniform 1e-300..1e300 in float64, 1e-37..1e38 in
    float32, and near 1) and at the exponent extremes where the float64 path rescales by 2^+-1000."""
    lo, hi = (-37.5, 38.2) if dtype == np.float32 else (-307.5, 308.2)
    x = np.concatenate(
        [
            10.0 ** RNG.uniform(lo, hi, 100000),
            RNG.uniform(0.5, 2.0, 50000),
            [2.0**1000, 2.0**-1000, np.nextafter(2.0**1000, 0), np.nextafter(2.0**-1000, 1)]
            if dtype == np.float64
            else [],
            [np.finfo(dtype).max, np.finfo(dtype).tiny],
        ]
    ).astype(dtype)
    got = np.asarray(_jit(E.rsqrt, width)(x))
    assert got.dtype == dtype
    ref = 1.0 / np.sqrt(x.astype(np.longdouble))
    # measured: 0.85 ulp in float64 (sqrt(1/x)); 1.64 in float32, XLA's own rsqrt
    assert _ulp_err(got, ref, dtype) <= (2.0 if dtype == np.float32 else 1.0)
    special = np.array([0.0, np.inf, -1.0, -np.inf, np.nan], dtype)
    np.testing.assert_array_equal(np.asarray(E.rsqrt(special)), np.array([np.inf, 0.0, np.nan, np.nan, np.nan], dtype))


def test_rsqrt_derivative_and_lowering():
    x = np.array([0.25, 1.0, 7.0, 1e200, 1e-200])
    np.testing.assert_allclose(np.asarray(jax.vmap(jax.grad(E.rsqrt))(x)), -0.5 * x**-1.5, rtol=1e-15)
    f = jax.jit(E.rsqrt)
    lowered = {p: f.trace(x).lower(lowering_platforms=(p,)).as_text() for p in ("cpu", "cuda")}
    op = "stablehlo.rsqrt"
    assert op not in lowered["cpu"] and op in lowered["cuda"]  # float64 on CPU: sqrt(1/x)
    assert op in f.trace(x[:3].astype(np.float32)).lower(lowering_platforms=("cpu",)).as_text()


# XLA's own trigonometric primitives; pfjax's simulators must not contain any (their CPU versions
# cost several times the polynomial chains above, per element and per fused kernel that uses them)
XLA_TRIG = ("sin", "cos", "tan", "atan", "atan2", "asin", "acos")


def _xla_trig(jaxpr) -> set[str]:
    """The XLA trigonometric primitives in a closed jaxpr, nested jaxprs (scan, while, pjit) included."""
    found = set()

    def walk(j):
        for eqn in j.eqns:
            if eqn.primitive.name in XLA_TRIG:
                found.add(eqn.primitive.name)
            for sub in _subjaxprs(eqn.params):
                walk(sub)

    walk(jaxpr.jaxpr)
    return found


def _subjaxprs(params):
    """The jaxprs in an equation's parameters (scan/while/cond/pjit/custom_jvp/checkpoint bodies)."""
    for v in params.values():
        for x in v if isinstance(v, (tuple, list)) else (v,):
            if hasattr(x, "jaxpr") and hasattr(x.jaxpr, "eqns"):
                yield x.jaxpr
            elif hasattr(x, "eqns"):
                yield x


def test_the_trace_walker_finds_xla_trigonometry():
    assert _xla_trig(jax.make_jaxpr(lambda x: jax.lax.scan(lambda c, _: (jnp.arctan(c), None), x, None, 3))(0.5)) == {
        "atan"
    }
    assert _xla_trig(jax.make_jaxpr(lambda x: E.atan2(E.sin(x), E.cos(x)) + E.tan(x) + E.atan(x))(0.5)) == set()


SLIP_CONTROLLERS = ["state_feedback", "pi", "stanley", "pure_pursuit", "rear_wheel", "integral", "linear"]


def _slip_run(name):
    """``(run, scenario)``: a short path-following run of controller ``name`` on the paper's sine
    scenario (``run(scenario)`` simulates it; the scenario in the tests' default float64)."""
    from pfjax import controllers as C
    from pfjax.sim import SimConfig
    from pfjax.sim.scenario import paper_scenario
    from pfjax.sim.simulate import simulate

    ctrl, gains = (
        (C.linear, C.linear_params(C.state_feedback_params()))
        if name == "linear"
        else (C.REGISTRY[name][0], C.REGISTRY[name][1]())
    )
    return (lambda s: simulate(ctrl, s, SimConfig(dt=0.01, horizon=0.1))), paper_scenario("sine", gains)


@pytest.mark.parametrize("name", SLIP_CONTROLLERS)
def test_slip_simulator_uses_no_xla_trigonometry(name):
    """Every controller in the path-following simulator (the whole traced run: model, projection,
    controller, metrics) computes its sines, cosines and arctangents with pfjax's functions."""
    run, sc = _slip_run(name)
    assert _xla_trig(jax.make_jaxpr(run)(sc)) == set()


@pytest.mark.parametrize("name", SLIP_CONTROLLERS)
def test_float64_slip_simulator_compiles_without_rsqrt(name):
    """No float64 ``rsqrt`` in the compiled CPU program of any controller's run. XLA evaluates it
    element by element (4x a division and a square root) and rewrites every ``a / sqrt(b)`` into
    one, so a stray ``/ jnp.sqrt`` in the model, projection or a controller shows up here
    (:func:`pfjax.numerics.elementary.rsqrt` is the vectorised form)."""
    import re

    if jax.default_backend() != "cpu":
        pytest.skip("a CPU code-generation check")
    run, sc = _slip_run(name)
    assert jnp.asarray(sc.pose0.x).dtype == jnp.float64
    hlo = jax.jit(run).lower(sc).compile().as_text()
    assert " sqrt(" in hlo and not re.search(r"= f64\S* rsqrt\(", hlo)


def test_parking_and_tracking_simulators_use_no_xla_trigonometry():
    from pfjax import tracking as T
    from pfjax.parking.maps import PARALLEL, to_obstacle_map
    from pfjax.parking.simulate import ParkingConfig, run, run_params
    from pfjax.tracking import leader as L

    omap = to_obstacle_map(list(PARALLEL.values()))
    assert (
        _xla_trig(jax.make_jaxpr(lambda p: run(p, omap, ParkingConfig()))(run_params((-0.4, 0.5, 0.0), 1, (1.0,))))
        == set()
    )
    params = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
    sc = T.scenario(params, L.sine(), init=T.initial_state(L.sine(), params))
    cfg = T.TrackConfig(dt=0.02, horizon=0.2, window=0.1)
    assert _xla_trig(jax.make_jaxpr(lambda s: T.simulate(s, cfg))(sc)) == set()
