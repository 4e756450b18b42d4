"""Generic path geometry and closest-point projection for any shape in :mod:`pfjax.paths.shapes`.

For a regular curve ``p(u)`` with derivatives ``p'``, ``p''``:

* tangent angle ``theta_p = atan2(p'_y, p'_x)``;
* signed curvature ``kappa = (p'_x p''_y - p'_y p''_x) / |p'|^3`` (1/m, left turn positive);
* arc length ``s(u) = int_{u_ref}^{u} |p'(w)| dw`` (m), with ``u_ref = 0`` clipped into the
  domain, by a fixed 8-point Gauss-Legendre rule on each of ``ARC_PANELS`` panels
  (exact for lines and circles, ~1e-12 m on the paper's paths);
* the closest point to ``q``: a root of ``g(u) = (p(u) - q) . p'(u)``, found by a
  safeguarded Newton iteration (below), warm-started from the previous step's ``u``.

All functions are pure, scalar in ``u`` and work under ``jit``, ``vmap`` and ``grad``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array
from jax.ad_checkpoint import checkpoint_name

from pfjax.numerics import elementary as E

ARC_PANELS = 64  # Gauss-Legendre panels between u_ref and u for the arc length
GLOBAL_SAMPLES = 4096  # dense samples for the cold-start (global) projection
END_TOL = 1e-4  # m: how far past an end of the path's domain counts as having left it
#: ``jax.checkpoint`` name of the projection's last-but-one Newton iterate, the point its
#: differentiated last step starts from (a checkpoint policy may save it; see pfjax.sim.simulate)
NEWTON_START = "pfjax_closest_parameter_newton_start"
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)  # NumPy: cast to the working dtype at use


class Projection(NamedTuple):
    """The robot's pose measured against its closest path point (docs/reproductions/path-following.md §2)."""

    d: Array  # m, signed lateral distance, left of the direction of travel positive
    theta_e: Array  # rad, heading error theta - theta_p, wrapped to (-pi, pi]
    kappa: Array  # 1/m, path curvature at the closest point
    s: Array  # m, arc length of the closest point
    u: Array  # path parameter of the closest point (warm start for the next call)
    theta_p: Array  # rad, path tangent angle at the closest point
    at_end: Array  # bool, the robot is past an end of the valid domain (closest point clamped there)


def wrap_angle(a: Array) -> Array:
    """Wrap an angle to ``(-pi, pi]`` (:func:`pfjax.numerics.elementary.wrap_angle`)."""
    return E.wrap_angle(a)


def tangent_angle(path, u: Array) -> Array:
    """Path tangent angle ``theta_p(u)`` in rad."""
    dx, dy = path.d1(u)
    return E.atan2(dy, dx)


def curvature(path, u: Array) -> Array:
    """Signed curvature ``kappa(u) = (x' y'' - y' x'') / (x'^2 + y'^2)^{3/2}`` in 1/m."""
    dx, dy = path.d1(u)
    ddx, ddy = path.d2(u)
    speed2 = dx * dx + dy * dy
    return E.divide(dx * ddy - dy * ddx, speed2 * jnp.sqrt(speed2))


def arc_length(path, u: Array) -> Array:
    """Arc length ``s(u)`` from ``u_ref = clip(0, u_min, u_max)`` in m (negative before it)."""
    u_ref = jnp.clip(0.0, path.u_min, path.u_max)
    h = (u - u_ref) / ARC_PANELS
    mids = u_ref + h * (jnp.arange(ARC_PANELS) + 0.5)
    dtype = jnp.result_type(h)
    w = mids[:, None] + 0.5 * h * jnp.asarray(_GL_X, dtype)[None, :]
    dx, dy = path.d1(w)
    return 0.5 * h * jnp.sum(jnp.asarray(_GL_W, dtype) * jnp.sqrt(dx * dx + dy * dy))


def _newton_update(path, u: Array, qx: Array, qy: Array) -> Array:
    """One safeguarded Newton step on ``g(u) = (p - q) . p'``.

    ``g'(u) = |p'|^2 + (p - q) . p''`` is positive near a minimum of the distance; where it is
    not, or barely (``g' < 0.01 |p'|^2``: at or beyond the centre of curvature on the inside of a
    bend), the step falls back to Gauss-Newton (``g' ~ |p'|^2``).
    The step moves the point at most ``max(|p - q|, 0.25 m)`` along the curve and ``u`` stays
    in the domain.
    """
    px, py = path.point(u)
    dx, dy = path.d1(u)
    ddx, ddy = path.d2(u)
    ex, ey = px - qx, py - qy
    speed2 = dx * dx + dy * dy
    g = ex * dx + ey * dy
    gp = speed2 + ex * ddx + ey * ddy
    gp = jnp.where(gp > 0.01 * speed2, gp, speed2)
    step = E.divide(-g, gp)
    # max(|p - q|, 0.25) / |p'| written as sqrt(max(|p - q|^2, 0.0625) / |p'|^2): the same value, a
    # finite derivative when the robot is exactly on the path (d sqrt/dx is infinite at 0, and
    # 0 * inf = NaN in the derivative even where the maximum picks 0.25), and one square root and no
    # rsqrt (XLA rewrites sqrt(a) / sqrt(b) into sqrt(a) * rsqrt(b): slow in float64 on CPU, see
    # pfjax.numerics.elementary.rsqrt)
    max_step = jnp.sqrt(E.divide(E.clip(ex * ex + ey * ey, 0.0625, np.inf), speed2))
    step = E.clip(step, -max_step, max_step)
    return E.clip(u + step, path.u_min, path.u_max)


def closest_parameter(path, qx: Array, qy: Array, u_guess: Array, iters: int = 3) -> Array:
    """Local closest-point parameter by ``iters`` Newton steps from ``u_guess`` (warm start).

    **Derivative** (one-step differentiation): JAX differentiates only the last Newton step, taken
    from the previous iterate ``u_{n-1}`` held constant (``stop_gradient``). At a root of ``g`` this
    is the implicit-function derivative of the closest point,

        du* = -(dg/dq . dq + dg/dpath . dpath) / g'(u*)        (g' the safeguarded Newton slope),

    and it differs from the derivative of the unrolled iterations only by terms proportional to the
    residual ``g(u_{n-1})`` (about 1e-9 m^2 after two warm-started steps at 5 ms; the unrolled
    derivative's dependence on ``u_guess`` is of the same order). The values are unchanged; the
    derivative costs one Newton step instead of ``iters`` (reverse mode through the simulator
    about 4.7x instead of 7.0x the forward pass, measured; README, Performance). Where the last step is
    clipped to the domain's end the derivative is 0, as the clip's.
    """
    u = u_guess
    for _ in range(iters - 1):
        u = _newton_update(path, u, qx, qy)
    return _newton_update(path, checkpoint_name(jax.lax.stop_gradient(u), NEWTON_START), qx, qy)


def polish_parameter(path, qx: Array, qy: Array, u_guess: Array, iters: int = 8) -> Array:
    """``iters`` Newton steps from ``u_guess`` (as :func:`closest_parameter`) in a rolled loop: one
    Newton step in the compiled program whatever ``iters``, for a one-off start-up projection. No
    derivative flows through it (``stop_gradient``): follow it with :func:`closest_parameter`,
    whose last step carries the derivative."""
    u = jax.lax.fori_loop(0, int(iters), lambda _, u: _newton_update(path, u, qx, qy), u_guess)
    return jax.lax.stop_gradient(u)


def global_parameter(path, qx: Array, qy: Array, iters: int = 8) -> Array:
    """Global closest-point parameter: best of ``GLOBAL_SAMPLES`` dense samples, polished by Newton.

    Used for the cold start, so a robot that starts far from the path (or nearer to a
    different branch of it) is matched with its true closest point.
    """
    grid = path.u_min + (path.u_max - path.u_min) * jnp.linspace(0.0, 1.0, GLOBAL_SAMPLES)
    px, py = path.point(grid)
    dist2 = (px - qx) ** 2 + (py - qy) ** 2
    # Closed or multi-lap paths have equally close points on every lap, and rounding must not pick a
    # later one: take the earliest sample whose distance is within the grid's own resolution
    # (one sample spacing of arc) of the minimum.
    dx, dy = path.d1(grid)
    h = (path.u_max - path.u_min) / (GLOBAL_SAMPLES - 1) * jnp.sqrt(dx * dx + dy * dy)
    dmin = jnp.sqrt(jnp.min(dist2))
    near = jnp.sqrt(dist2) <= dmin + h
    i = jnp.argmax(near)
    # iters - 1 rolled steps, then the last one (which carries the derivative) as closest_parameter's
    return closest_parameter(path, qx, qy, polish_parameter(path, qx, qy, grid[i], iters - 1), 1)


def measure(path, x: Array, y: Array, theta: Array, u: Array) -> Projection:
    """Lateral error, heading error, curvature and arc length of the pose against the point ``p(u)``.

    ``u`` should be a closest-point parameter (:func:`closest_parameter`); then
    ``d = (q - p(u)) . n`` with ``n`` the left unit normal is the signed distance.
    """
    px, py = path.point(u)
    dx, dy = path.d1(u)
    inv = E.rsqrt(dx * dx + dy * dy)
    tx, ty = dx * inv, dy * inv  # unit tangent (cos theta_p, sin theta_p)
    d = -(x - px) * ty + (y - py) * tx
    # Beyond an end: the closest point is clamped to the end AND the robot lies past it along the
    # tangent (more than END_TOL). A robot exactly at the start is not beyond it.
    along = (x - px) * tx + (y - py) * ty
    # theta_e = wrap(theta - theta_p) as the angle from the tangent to the heading: one atan2, no wrap.
    sh, ch = E.sincos(theta)
    eps = 1e-9 * (path.u_max - path.u_min)
    at_end = ((u <= path.u_min + eps) & (along < -END_TOL)) | ((u >= path.u_max - eps) & (along > END_TOL))
    return Projection(
        d=d,
        theta_e=E.atan2(tx * sh - ty * ch, tx * ch + ty * sh),
        kappa=curvature(path, u),
        s=arc_length(path, u),
        u=u,
        theta_p=E.atan2(dy, dx),
        at_end=at_end,
    )


def project(path, x: Array, y: Array, theta: Array, u_guess: Array | None = None, iters: int = 3) -> Projection:
    """Closest-point projection of the pose ``(x, y, theta)`` onto ``path``.

    Args:
        path: any shape from :mod:`pfjax.paths.shapes`.
        x, y, theta: pose of the rear-axle centre (m, m, rad).
        u_guess: warm start (previous closest parameter); ``None`` for a global (cold) search.
        iters: Newton steps from the warm start.
    """
    if u_guess is None:
        u = global_parameter(path, x, y)
    else:
        u = closest_parameter(path, x, y, u_guess, iters)
    return measure(path, x, y, theta, u)
