"""Path geometry and closest-point projection against independent NumPy/SciPy references.

The references share no code with :mod:`pfjax.paths`: each curve is written from its closed
form (the spline is evaluated by ``scipy.interpolate.CubicSpline``), the closest point is found
by brute force on >= 200k samples of the curve, refined by a bounded scalar minimisation, and
arc lengths are closed forms or ``scipy.integrate.quad``.

Tolerances: the brute-force refinement is converged to ~1e-12 in the parameter, and pfjax's
Newton projection to machine precision, so closest points, ``d``, ``theta_e``, ``kappa`` and
``s`` are compared at 1e-8 (a wrong branch or an unconverged Newton iterate is off by >= 1e-4).
Exception: the spline's arc length, whose speed ``|p'|`` is only C1 at the knots, so pfjax's fixed
Gauss-Legendre panels (which straddle knots) are accurate to ~4e-7 m over the 11 m spline; it is
compared at 1e-6 m.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from pfjax.paths import arc_length, circle, curvature, line, parabola, project, sine, spline_through, wrap_angle

WAYPOINTS = np.array([[0.0, 0.0], [1.5, 0.4], [3.0, 1.5], [4.0, 1.2], [5.5, 0.0], [7.0, -0.5], [8.2, 0.5], [9.0, 2.0]])
N_DENSE = 250_001  # brute-force samples of each curve


def wrap_ref(a):
    """Reference wrap to (-pi, pi] by complex argument (independent of pfjax's formula)."""
    a = np.asarray(a, dtype=float)
    w = np.angle(np.exp(1j * a))
    return np.where(w <= -np.pi, w + 2 * np.pi, w)


# ------------------------------------------------------------------ independent reference curves


class RefCurve:
    """A curve in pfjax's parameter ``u``: point, first derivative, arc length from u_ref, curvature."""

    def __init__(self, name, point, d1, arc, kappa, u_lo, u_hi, period=None):
        self.name, self.point, self.d1, self.arc, self.kappa = name, point, d1, arc, kappa
        self.u_lo, self.u_hi, self.period = u_lo, u_hi, period  # brute-force domain; period in s (circle)

    def closest(self, qx, qy):
        """Brute-force closest parameter and the gap to the second-best local minimum of the distance."""
        us = np.linspace(self.u_lo, self.u_hi, N_DENSE)
        px, py = self.point(us)
        d2 = (px - qx) ** 2 + (py - qy) ** 2
        if self.period is not None:  # one closed lap: the sample sequence is periodic
            loc = (d2 <= np.roll(d2, 1)) & (d2 <= np.roll(d2, -1))
        else:
            loc = np.r_[d2[0] <= d2[1], (d2[1:-1] <= d2[:-2]) & (d2[1:-1] <= d2[2:]), d2[-1] <= d2[-2]]
        mins = np.sort(np.sqrt(d2[loc]))
        gap = mins[1] - mins[0] if mins.size > 1 else np.inf
        i = int(np.argmin(d2))
        # Refine: root of g(u) = (p(u) - q) . p'(u) in the bracket around the best sample (brentq
        # converges to machine precision; minimising |p - q|^2 itself would stop at ~sqrt(eps)).
        h = us[1] - us[0]

        def g(u):
            (px_, py_), (tx, ty) = self.point(u), self.d1(u)
            return float((px_ - qx) * tx + (py_ - qy) * ty)

        a, b = us[i] - h, us[i] + h
        if self.period is None:
            a, b = max(a, self.u_lo), min(b, self.u_hi)
        if g(a) * g(b) > 0:  # the minimum is at an end of the domain
            return float(us[i]), gap
        return float(brentq(g, a, b, xtol=1e-15, rtol=4 * np.finfo(float).eps)), gap

    def measure(self, qx, qy, theta, u):
        """(d, theta_e, kappa, s, px, py) of the pose against the point u (d by the cross product)."""
        px, py = (float(a) for a in self.point(u))
        tx, ty = (float(a) for a in self.d1(u))
        d = (tx * (qy - py) - ty * (qx - px)) / math.hypot(tx, ty)
        return d, float(wrap_ref(theta - math.atan2(ty, tx))), float(self.kappa(u)), self.arc(u), px, py


def _quad_arc(d1, u, points=None):
    speed = lambda w: math.hypot(*(float(a) for a in d1(w)))
    if points is not None:
        points = [p for p in points if min(0.0, u) < p < max(0.0, u)] or None
    val, _ = quad(speed, 0.0, u, epsabs=1e-13, epsrel=1e-13, limit=500, points=points)
    return val


def ref_line():  # y = b x with b = tan(pi/4), u = x (a graph); the domain is arc length [-20, 80] m
    h = math.pi / 4
    b = math.tan(h)
    return RefCurve(
        "line",
        lambda u: (u + 0 * u, b * u + 0 * u),
        lambda u: (1.0 + 0 * u, b + 0 * u),
        lambda u: u * math.sqrt(1 + b * b),
        lambda u: 0.0 * u,
        -20.0 * math.cos(h),
        80.0 * math.cos(h),
    )


def ref_parabola():  # y = x^2, u = x
    return RefCurve(
        "parabola",
        lambda u: (u, u**2),
        lambda u: (1.0 + 0 * u, 2 * u),
        lambda x: x / 2 * math.sqrt(1 + 4 * x * x) + math.asinh(2 * x) / 4,
        lambda x: 2.0 / (1 + 4 * x * x) ** 1.5,
        -10.0,
        10.0,
    )


def ref_sine(A=1.0):  # y = A sin x, u = x
    d1 = lambda u: (1.0 + 0 * u, A * np.cos(u))
    return RefCurve(
        "sine",
        lambda u: (u, A * np.sin(u)),
        d1,
        lambda u: _quad_arc(d1, u, points=list(np.arange(-3, 20) * np.pi / 2)),
        lambda u: -A * np.sin(u) / (1 + (A * np.cos(u)) ** 2) ** 1.5,
        -10.0,
        60.0,
    )


def ref_circle(R=2.0, cx=0.5, cy=1.0, direction=1.0, phi0=-math.pi / 2):
    # u is arc length; the reference samples one lap and compares s modulo the circumference.
    phi = lambda u: phi0 + direction * u / R
    return RefCurve(
        "circle",
        lambda u: (cx + R * np.cos(phi(u)), cy + R * np.sin(phi(u))),
        lambda u: (-direction * np.sin(phi(u)), direction * np.cos(phi(u))),
        lambda u: u,
        lambda u: direction / R + 0 * u,
        0.0,
        2 * math.pi * R,
        period=2 * math.pi * R,
    )


def ref_spline():
    chord = np.linalg.norm(np.diff(WAYPOINTS, axis=0), axis=1)
    knots = np.r_[0.0, np.cumsum(chord)]
    cs = CubicSpline(knots, WAYPOINTS, bc_type="natural")
    c1, c2 = cs.derivative(1), cs.derivative(2)

    def kappa(u):
        (dx, dy), (ddx, ddy) = c1(u), c2(u)
        return (dx * ddy - dy * ddx) / (dx * dx + dy * dy) ** 1.5

    d1 = lambda u: tuple(np.moveaxis(c1(u), -1, 0))
    return RefCurve(
        "spline",
        lambda u: tuple(np.moveaxis(cs(u), -1, 0)),
        d1,
        lambda u: _quad_arc(d1, u, points=list(knots)),
        kappa,
        0.0,
        float(knots[-1]),
    )


CASES = {
    "line": (line, ref_line),
    "parabola": (parabola, ref_parabola),
    "sine": (sine, ref_sine),
    "circle": (lambda: circle(radius=2.0, cx=0.5, cy=1.0), ref_circle),
    "spline": (lambda: spline_through(WAYPOINTS), ref_spline),
}


def query_points(name, ref, n=14, seed=0):
    """Random poses near and far (up to 5 m) from the middle of the curve, kept only where the
    closest point is interior and unambiguous (second-best local minimum >= 5 cm farther)."""
    rng = np.random.default_rng(seed + sum(map(ord, name)))
    lo, hi = {"line": (-5, 20), "parabola": (-2.5, 2.5), "sine": (0, 12), "circle": (0, 12.5), "spline": (1, 10)}[name]
    out = []
    while len(out) < n:
        u0 = rng.uniform(lo, hi)
        px, py = ref.point(u0)
        r = rng.choice([0.05, 0.5, 2.0, 5.0]) * rng.uniform(0.2, 1.0)
        a = rng.uniform(-np.pi, np.pi)
        qx, qy, th = float(px + r * np.cos(a)), float(py + r * np.sin(a)), float(rng.uniform(-4, 4))
        u, gap = ref.closest(qx, qy)
        margin = 1e-3 * (ref.u_hi - ref.u_lo)
        if gap > 0.05 and (ref.period is not None or ref.u_lo + margin < u < ref.u_hi - margin):
            out.append((qx, qy, th, u))
    return out


FD_H = 1e-6  # central finite-difference step, m


def _all_outputs(path, xs, ys, ths, u_warm):
    """Everything the per-path tests check, in one jitted function (one compile per path type):
    the cold projection vmapped over the query points; the warm projection of the query points and
    of their four finite-difference neighbours; and grad of the warm-started d."""
    n = xs.shape[0]
    warm_project = lambda x, y, th, u0: project(path, x, y, th, u_guess=u0, iters=6)
    shifts = FD_H * jnp.asarray([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    ax = jnp.concatenate([xs, (xs[:, None] + shifts[None, :, 0]).ravel()])
    ay = jnp.concatenate([ys, (ys[:, None] + shifts[None, :, 1]).ravel()])
    cold = jax.vmap(lambda x, y, th: project(path, x, y, th))(xs, ys, ths)
    warm_all = jax.vmap(warm_project)(
        ax,
        ay,
        jnp.concatenate([ths, jnp.repeat(ths, 4)]),
        jnp.tile(u_warm, 5)[jnp.concatenate([jnp.arange(n), jnp.repeat(jnp.arange(n), 4)])],
    )
    warm = jax.tree_util.tree_map(lambda a: a[:n], warm_all)
    d_shift = warm_all.d[n:].reshape(n, 4)
    grad = jax.vmap(jax.grad(lambda x, y, th, u0: warm_project(x, y, th, u0).d, argnums=(0, 1)))(xs, ys, ths, u_warm)
    return cold, warm, jnp.stack(grad, axis=-1), d_shift


@pytest.fixture(scope="module", params=list(CASES))
def case(request):
    """(name, path, reference, query points, outputs of :func:`_all_outputs`)."""
    make, make_ref = CASES[request.param]
    ref, path = make_ref(), make()
    qs = query_points(request.param, ref)
    rng = np.random.default_rng(1)
    # Appended for the spline: two queries beyond its ends (checked by _check_ends).
    extra = [(12.0, 4.0, 0.0, 11.0), (-1.0, -0.5, 0.0, 0.0)] if request.param == "spline" else []
    xs, ys, ths, us = (jnp.asarray([q[i] for q in qs + extra]) for i in range(4))
    u_warm = us + jnp.asarray(rng.choice([-0.05, 0.05], size=len(us)))  # warm start 5 cm off
    out = jax.jit(_all_outputs)(path, xs, ys, ths, u_warm)
    return request.param, path, ref, qs, out


def _check_projection(name, ref, proj, q):
    qx, qy, th, u_ref = q
    d, te, kappa, s, px, py = ref.measure(qx, qy, th, u_ref)
    gx, gy = (float(a) for a in ref.point(float(proj.u)))  # pfjax's closest point, reference evaluation
    assert math.hypot(gx - px, gy - py) < 1e-8, (name, q, gx, gy, px, py)
    assert abs(float(proj.d) - d) < 1e-9, (name, q, float(proj.d), d)
    assert abs(wrap_ref(float(proj.theta_e) - te)) < 1e-8
    assert abs(float(proj.kappa) - kappa) < 1e-8
    ds = float(proj.s) - s
    if ref.period is not None:
        ds = (ds + ref.period / 2) % ref.period - ref.period / 2
    assert abs(ds) < (1e-6 if name == "spline" else 1e-8), (name, q, float(proj.s), s)
    assert not bool(proj.at_end)


def _row(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)


def _check_ends(name, path, proj, n):
    """The spline's extra queries beyond either end project onto that end and are flagged."""
    if name == "spline":
        np.testing.assert_array_equal(np.asarray(proj.at_end)[n:], [True, True])
        np.testing.assert_allclose(np.asarray(proj.u)[n:], [float(path.u_max), 0.0], atol=1e-12)


def test_projection_cold_start_matches_brute_force(case):
    """Cold start (global dense search + Newton), jitted and vmapped over query points near and
    far (<= 5 m) from the path, vs brute force; beyond the ends: the end point, flagged."""
    name, path, ref, qs, (cold, *_) = case
    for i, q in enumerate(qs):
        _check_projection(name, ref, _row(cold, i), q)
    _check_ends(name, path, cold, len(qs))


def test_projection_warm_start_matches_brute_force(case):
    """Warm start 5 cm (in u) off the closest point, converged by Newton (6 steps), jitted and
    vmapped."""
    name, path, ref, qs, (_, warm, *_) = case
    for i, q in enumerate(qs):
        _check_projection(name, ref, _row(warm, i), q)
    _check_ends(name, path, warm, len(qs))


def test_grad_of_d_is_the_left_normal(case):
    """d(d)/d(x, y) = (-sin theta_p, cos theta_p) (the closest point moves along the tangent, which
    is orthogonal to q - p) through the warm-started Newton iterations, and matches central finite
    differences (h = 1e-6 m: truncation ~h^2 kappa, rounding ~1e-16/h, so 1e-7 is ample). The
    cold start's gradient is checked on the sines in :func:`test_vmap_over_a_batch_of_paths`."""
    name, path, ref, qs, (_, _, grad, d_shift) = case
    for i, (qx, qy, _, u) in enumerate(qs):
        tx, ty = (float(a) for a in ref.d1(u))
        tp = math.atan2(ty, tx)
        ds = np.asarray(d_shift[i])
        fd = [(ds[0] - ds[1]) / (2 * FD_H), (ds[2] - ds[3]) / (2 * FD_H)]
        np.testing.assert_allclose(np.asarray(grad[i]), [-math.sin(tp), math.cos(tp)], atol=1e-8)
        np.testing.assert_allclose(np.asarray(grad[i]), fd, atol=1e-7)


def test_curvature_closed_forms():
    """kappa against closed forms: parabola 2a/(1+4a^2x^2)^1.5, circle +-1/R, sine, line 0."""
    xs = jnp.linspace(-3.0, 3.0, 61)
    for a in (1.0, -0.4):
        k = np.asarray(curvature(parabola(a=a), xs))
        np.testing.assert_allclose(k, 2 * a / (1 + 4 * a * a * np.asarray(xs) ** 2) ** 1.5, rtol=1e-13, atol=1e-14)
    A, w = 1.7, 0.8
    k = np.asarray(curvature(sine(amplitude=A, omega=w, phase=0.3), xs))
    arg = w * np.asarray(xs) + 0.3
    np.testing.assert_allclose(k, -A * w * w * np.sin(arg) / (1 + (A * w * np.cos(arg)) ** 2) ** 1.5, atol=1e-13)
    us = jnp.linspace(-2.0, 20.0, 23)
    np.testing.assert_allclose(np.asarray(curvature(circle(radius=2.5), us)), 1 / 2.5, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(curvature(circle(radius=2.5, direction=-1.0), us)), -1 / 2.5, rtol=1e-13)
    np.testing.assert_array_equal(np.asarray(curvature(line(), us)), 0.0)


def test_arc_length_closed_forms_and_quad():
    """s(u) from u_ref = 0: parabola x/2 sqrt(1+4x^2) + asinh(2x)/4, line s = sqrt(2) x, circle s = u, sine
    and spline by scipy quad (spline split at its knots). Gauss-Legendre on 64 panels is exact for
    polynomials of degree 15 per panel, so smooth integrands agree to ~1e-12; the spline's speed is
    only C1 at the knots, so Gauss-Legendre panels straddling a knot lose accuracy: ~4e-7 m
    over the 11 m spline, compared at 1e-6 m."""
    arc = jax.jit(jax.vmap(arc_length, in_axes=(None, 0)))
    xs = np.array([-9.5, -3.0, -0.7, 0.0, 0.4, 2.0, 7.5, 10.0])
    par = ref_parabola()
    np.testing.assert_allclose(
        np.asarray(arc(parabola(), jnp.asarray(xs))), [par.arc(x) for x in xs], rtol=1e-12, atol=1e-12
    )
    us = np.array([-20.0, -3.3, 0.0, 1.0, 55.5, 80.0])
    xl = us * math.cos(math.pi / 4)  # the line's u is x: these are arc lengths us from the origin
    np.testing.assert_allclose(np.asarray(arc(line(), jnp.asarray(xl))), us, rtol=1e-14, atol=1e-12)
    np.testing.assert_allclose(np.asarray(arc(circle(radius=1.5), jnp.asarray(us[1:4]))), us[1:4], atol=1e-12)
    sx = np.array([-10.0, -2.0, 0.5, 3.0, 17.0, 60.0])
    sref = ref_sine()
    np.testing.assert_allclose(
        np.asarray(arc(sine(), jnp.asarray(sx))), [sref.arc(x) for x in sx], rtol=1e-12, atol=1e-12
    )
    spl, rsp = spline_through(WAYPOINTS), ref_spline()
    su = np.linspace(0.0, float(spl.u_max), 9)
    np.testing.assert_allclose(np.asarray(arc(spl, jnp.asarray(su))), [rsp.arc(u) for u in su], atol=1e-6)


def test_spline_interpolates_is_c2_and_natural():
    """The three conditions that define a natural cubic spline, checked on pfjax's evaluation:
    through the waypoints at the chord-length knots, p, p', p'' continuous at interior knots
    (one-sided limits at +-1e-9 m agree to O(1e-9) x |p'''|), and p'' = 0 at both ends."""
    spl = spline_through(WAYPOINTS)
    knots = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(WAYPOINTS, axis=0), axis=1))]
    np.testing.assert_allclose(np.asarray(spl.knots), knots, rtol=1e-15)
    px, py = spl.point(jnp.asarray(knots))
    np.testing.assert_allclose(np.c_[px, py], WAYPOINTS, atol=1e-13)
    eps = 1e-9
    inner = jnp.asarray(knots[1:-1])
    for fn, tol in ((spl.point, 1e-8), (spl.d1, 1e-8), (spl.d2, 1e-7)):
        left, right = np.asarray(fn(inner - eps)), np.asarray(fn(inner + eps))
        assert np.abs(left - right).max() < tol, (fn, np.abs(left - right).max())
    # A cubic spline is not C3: the third derivative jumps (checks the one-sided evaluation works).
    d2l, d2r = np.asarray(spl.d2(inner - 1e-3)), np.asarray(spl.d2(inner + 1e-3))
    assert np.abs(d2l - d2r).max() > 1e-4
    np.testing.assert_allclose(np.asarray(spl.d2(jnp.asarray([knots[0], knots[-1]]))), 0.0, atol=1e-12)


def test_vmap_over_a_batch_of_paths():
    """Nested vmap: over sines of different amplitude and over query points, vs brute force; with
    the gradient of the cold-start d (through the stop-gradient grid search and Newton)."""
    amps = np.array([0.3, 1.0, 1.6])
    paths = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *[sine(amplitude=A) for A in amps])
    qs = [(1.3, 0.9, 0.2), (4.0, -1.2, -1.0), (7.9, 2.6, 2.5), (10.2, -0.1, 0.0)]
    xs, ys, ths = (jnp.asarray([q[i] for q in qs]) for i in range(3))

    def one(p, x, y, th):
        grad = jax.grad(lambda x, y: project(p, x, y, th).d, argnums=(0, 1))(x, y)
        return project(p, x, y, th), jnp.stack(grad)

    proj, grad = jax.jit(jax.vmap(jax.vmap(one, (None, 0, 0, 0)), (0, None, None, None)))(paths, xs, ys, ths)
    assert proj.d.shape == (3, 4) and grad.shape == (3, 4, 2)
    for i, A in enumerate(amps):
        ref = ref_sine(A)
        for j, (qx, qy, th) in enumerate(qs):
            u, gap = ref.closest(qx, qy)
            assert gap > 0.05
            d, te, kappa, s, *_ = ref.measure(qx, qy, th, u)
            assert abs(float(proj.u[i, j]) - u) < 1e-8
            assert abs(float(proj.d[i, j]) - d) < 1e-9
            assert abs(float(proj.kappa[i, j]) - kappa) < 1e-8
            assert abs(float(proj.s[i, j]) - s) < 1e-8
            tp = math.atan2(*reversed(ref.d1(u)))  # cold start's gradient: the left normal
            np.testing.assert_allclose(np.asarray(grad[i, j]), [-math.sin(tp), math.cos(tp)], atol=1e-8)


def test_warm_start_tracks_a_moving_query_point():
    """The simulator's use: 3 Newton steps per sample from the previous closest point, for a query
    moving ~2 cm per sample along a wavy curve within 0.75 m of the sine (vertically).

    Within the radius of curvature the closest point moves continuously, so the tracked point must
    be the brute-force one at every sample. (Near a centre of curvature the closest point jumps
    along the path and a 3-step warm start lags for a few samples; that is not tested here.)"""
    path, ref = sine(), ref_sine()
    t = np.linspace(0.0, 12.0, 601)
    qx, qy = t, np.sin(t) + 0.75 * np.sin(0.45 * t)  # offset within the radius of curvature (>= 1 m)

    def body(u, q):
        p = project(path, q[0], q[1], 0.0, u_guess=u)
        return p.u, p.u

    u0 = project(path, qx[0], qy[0], 0.0).u
    _, us = jax.jit(lambda q: jax.lax.scan(body, u0, q))(jnp.asarray(np.c_[qx, qy]))
    us = np.asarray(us)
    for i in range(0, t.size, 6):
        u_ref, _ = ref.closest(qx[i], qy[i])
        assert abs(us[i] - u_ref) < 1e-8, (i, us[i], u_ref)


def test_wrap_angle_range():
    """(-pi, pi], including the float edge cases next to +-pi and odd multiples of pi."""
    a = np.r_[
        np.linspace(-50, 50, 2001),
        [np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0, -0.0],
        [np.nextafter(np.pi, 4), np.nextafter(np.pi, 0), np.nextafter(-np.pi, -4), np.nextafter(-np.pi, 0)],
        [np.nextafter(3 * np.pi, 10), np.nextafter(-3 * np.pi, -10)],
    ]
    w = np.asarray(wrap_angle(jnp.asarray(a)))
    assert np.all(w > -np.pi) and np.all(w <= np.pi)
    k = (a - w) / (2 * np.pi)
    np.testing.assert_allclose(k, np.round(k), atol=1e-12)
    assert float(wrap_angle(jnp.asarray(-np.pi))) == np.pi
    inner = np.abs(wrap_ref(a)) < np.pi - 1e-9  # away from the branch cut, compare the values
    np.testing.assert_allclose(w[inner], wrap_ref(a)[inner], atol=1e-12)


_SINE, _SINE_REF = sine(), ref_sine()
_project_sine = jax.jit(lambda x, y: project(_SINE, x, y, 0.0))


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-4.0, 30.0), off=st.floats(-0.8, 0.8))
def test_abs_d_is_the_distance_near_a_sine(x, off):
    """Property: for any point within 0.8 m (vertically) of y = sin x, |d| is the brute-force distance.

    0.8 m is inside the radius of curvature (>= 1 m), so the distance has a unique minimiser."""
    qx, qy = x, math.sin(x) + off
    u, _ = _SINE_REF.closest(qx, qy)
    px, py = _SINE_REF.point(u)
    p = _project_sine(qx, qy)
    assert abs(abs(float(p.d)) - math.hypot(qx - px, qy - py)) < 1e-10
    assert np.sign(float(p.d)) == np.sign(off) or abs(off) < 1e-12


@pytest.mark.parametrize("dtype", [jnp.float32, jnp.float64])
def test_derivatives_are_finite_with_the_robot_exactly_on_the_path(dtype):
    """Regression: a run whose pose lands exactly on the path (p(u) = q in floating point) had a
    NaN derivative, from d sqrt(|p - q|^2)/dq = inf times a zero tangent in the Newton step limit
    (found by ``pfjax bench``: one float32 run in 2000 gave a NaN gradient of the batch IAE). Jitted,
    forward and reverse mode, at poses exactly on a sine, a parabola and a circle; the derivative of
    d with respect to (x, y) must be the left normal (the projection's gradient, as in
    :func:`test_grad_of_d_is_the_left_normal`)."""
    with jax.enable_x64(dtype == jnp.float64):
        cast = lambda p: jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), p)
        for path in (cast(sine()), cast(parabola()), cast(circle())):

            def d_of(q, u):
                return project(path, q[0], q[1], jnp.asarray(0.1, dtype), u, 3).d

            grad_rev, grad_fwd = jax.jit(jax.grad(d_of)), jax.jit(jax.jacfwd(d_of))
            for u in (0.3, 1.7, 7.945819854736328):
                u = jnp.asarray(u, dtype)
                q = jnp.stack(path.point(u))  # exactly on the path
                tx, ty = (float(a) for a in path.d1(u))
                normal = np.array([-ty, tx]) / math.hypot(tx, ty)
                tol = 1e-5 if dtype == jnp.float32 else 1e-12
                np.testing.assert_allclose(np.asarray(grad_rev(q, u)), normal, atol=tol)
                np.testing.assert_allclose(np.asarray(grad_fwd(q, u)), normal, atol=tol)
