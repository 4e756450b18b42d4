"""Path shapes as pytrees: each is a regular parametric curve ``p(u)`` on ``[u_min, u_max]``.

Every shape is a ``NamedTuple`` of arrays, so a batch of paths of one shape (say sines
of different amplitude) is vmapped like any other pytree. A shape provides the curve
and its first two derivatives in its own parameter ``u``; everything else (tangent
angle, curvature, arc length, closest-point projection) is computed generically in
:mod:`pfjax.paths.geometry` from those three functions, so a new shape is three
one-line methods.

Direction of travel is increasing ``u`` (docs/reproductions/path-following.md §6: increasing ``x`` for the graphs: line, parabola, sine).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.numerics import elementary as E


def _f(x) -> Array:
    return jnp.asarray(x, dtype=jnp.result_type(float))


class Graph(NamedTuple):
    """A graph ``y = f(x)`` travelled towards increasing ``x``, parameterised by ``u = x`` (m), with

        f(x) = y0 + b x + a x^2 + A sin(w x + phi).

    The source's three test paths are such graphs, built by :func:`line` (``y = x``: ``b = 1``),
    :func:`parabola` (``y = x^2``: ``a = 1``) and :func:`sine` (``y = sin x``: ``A = w = 1``). Being one
    pytree type they share one compiled simulator program (a study over the three paths compiles one
    program per controller instead of three), and one batch may mix them. The terms a path lacks are
    exact zeros (``0 * finite`` and ``+ 0`` are exact), so each path's point and derivatives are
    those of its own formula, up to the compiler's choice of fused multiply-adds. ``x(u) = u`` is
    kept literal rather than a general direction: XLA then folds ``x' = 1`` and ``x'' = 0`` into the
    projection and curvature (a general-direction form measured 10 % slower on the sine path).
    """

    y0: Array  # m
    slope: Array  # b (-)
    a: Array  # 1/m, quadratic coefficient
    amplitude: Array  # m, A
    omega: Array  # rad/m, w
    phase: Array  # rad, phi
    u_min: Array  # m (x)
    u_max: Array  # m (x)

    # sin and cos of one argument share one range reduction (E.sincos); XLA merges the repeats.
    def point(self, u):
        return u, self.y0 + self.slope * u + self.a * (u * u) + self.amplitude * E.sin(self.omega * u + self.phase)

    def d1(self, u):
        return jnp.ones_like(u), self.slope + 2.0 * self.a * u + self.amplitude * self.omega * E.cos(
            self.omega * u + self.phase
        )

    def d2(self, u):
        return jnp.zeros_like(u), 2.0 * self.a - self.amplitude * self.omega**2 * E.sin(self.omega * u + self.phase)


class Circle(NamedTuple):
    """Circle of radius ``R`` about ``(cx, cy)``, travelled counter-clockwise (``direction = +1``)
    or clockwise (``-1``), starting at polar angle ``phi0``. ``u`` is arc length (m)."""

    cx: Array  # m
    cy: Array  # m
    radius: Array  # m
    phi0: Array  # rad
    direction: Array  # +1 CCW (left turn, kappa > 0), -1 CW
    u_min: Array  # m
    u_max: Array  # m

    def _phi(self, u):
        return self.phi0 + self.direction * u / self.radius

    def point(self, u):
        s, c = E.sincos(self._phi(u))
        return self.cx + self.radius * c, self.cy + self.radius * s

    def d1(self, u):
        s, c = E.sincos(self._phi(u))
        return -self.direction * s, self.direction * c

    def d2(self, u):
        s, c = E.sincos(self._phi(u))
        return -c / self.radius, -s / self.radius


class Spline(NamedTuple):
    """Natural cubic spline through waypoints, chord-length parameter ``u`` (m).

    Piece ``i`` on ``[knots[i], knots[i+1]]`` is ``p(u) = sum_j coef[i, j] (u - knots[i])^j``
    (per coordinate). Curvature is continuous (C2 spline), so Newton projection is well
    behaved. Build with :func:`spline_through`.
    """

    knots: Array  # (n,) m, chord-length parameter of each waypoint
    coef_x: Array  # (n-1, 4)
    coef_y: Array  # (n-1, 4)
    u_min: Array  # m
    u_max: Array  # m

    def _piece(self, u):
        i = jnp.clip(jnp.searchsorted(self.knots, u, side="right") - 1, 0, self.knots.shape[0] - 2)
        return self.coef_x[i], self.coef_y[i], u - self.knots[i]

    def point(self, u):
        cx, cy, t = self._piece(u)
        ev = lambda c: ((c[..., 3] * t + c[..., 2]) * t + c[..., 1]) * t + c[..., 0]
        return ev(cx), ev(cy)

    def d1(self, u):
        cx, cy, t = self._piece(u)
        ev = lambda c: (3.0 * c[..., 3] * t + 2.0 * c[..., 2]) * t + c[..., 1]
        return ev(cx), ev(cy)

    def d2(self, u):
        cx, cy, t = self._piece(u)
        ev = lambda c: 6.0 * c[..., 3] * t + 2.0 * c[..., 2]
        return ev(cx), ev(cy)


# ---------------------------------------------------------------- constructors


def line(x0=0.0, y0=0.0, heading=np.pi / 4, u_min=-20.0, u_max=80.0) -> Graph:
    """Line through ``(x0, y0)`` with direction ``heading`` (default: the source's ``y = x``), as a
    :class:`Graph` (``u = x``). ``u_min`` and ``u_max`` are arc lengths from ``(x0, y0)`` (m); the
    graph's domain is ``x0 + [u_min, u_max] cos(heading)``. The direction must point towards
    increasing ``x`` (``|heading| < 90 deg``): for other lines, rotate the scene or use
    :func:`spline_through`."""
    c = math.cos(float(heading))
    if not c > 1e-6:
        raise ValueError(f"heading: a line travels towards increasing x (|heading| < 90 deg), got {heading!r} rad")
    b = math.tan(float(heading))
    return Graph(*(_f(v) for v in (y0 - b * x0, b, 0.0, 0.0, 0.0, 0.0, x0 + u_min * c, x0 + u_max * c)))


def parabola(a=1.0, y0=0.0, u_min=-10.0, u_max=10.0) -> Graph:
    """Parabola ``y = a x^2 + y0`` (default: the source's ``y = x^2``), ``x`` in ``[u_min, u_max]``."""
    return Graph(*(_f(v) for v in (y0, 0.0, a, 0.0, 0.0, 0.0, u_min, u_max)))


def sine(amplitude=1.0, omega=1.0, phase=0.0, y0=0.0, u_min=-10.0, u_max=60.0) -> Graph:
    """Sine ``y = A sin(w x + phase) + y0`` (default: the source's ``y = sin x``), ``x`` in ``[u_min, u_max]``."""
    return Graph(*(_f(v) for v in (y0, 0.0, 0.0, amplitude, omega, phase, u_min, u_max)))


def circle(radius=2.0, cx=0.0, cy=0.0, phi0=-np.pi / 2, direction=1.0, laps=3.0) -> Circle:
    """Circle of ``radius`` about ``(cx, cy)`` starting (``u = 0``) at polar angle ``phi0``.

    The valid domain is half a lap before the start to ``laps`` turns after it.
    """
    return Circle(*(_f(v) for v in (cx, cy, radius, phi0, direction, -np.pi * radius, laps * 2 * np.pi * radius)))


def spline_through(waypoints) -> Spline:
    """Natural cubic spline through ``waypoints`` (shape ``(n, 2)``, ``n >= 3``, distinct consecutive points).

    Built with NumPy at the edge (``scipy.interpolate.CubicSpline``), evaluated in JAX.
    """
    from scipy.interpolate import CubicSpline

    w = np.asarray(waypoints, dtype=float)
    if w.ndim != 2 or w.shape[1] != 2 or w.shape[0] < 3:
        raise ValueError(f"waypoints: expected an (n, 2) array with n >= 3, got shape {w.shape}")
    chord = np.linalg.norm(np.diff(w, axis=0), axis=1)
    if np.any(chord <= 0) or not np.all(np.isfinite(w)):
        raise ValueError("waypoints: consecutive waypoints must be distinct and finite")
    knots = np.concatenate([[0.0], np.cumsum(chord)])
    cs = CubicSpline(knots, w, bc_type="natural")
    # CubicSpline.c has shape (4, n-1, 2) with highest power first.
    c = cs.c[::-1]  # (4, n-1, 2), lowest power first
    return Spline(
        knots=_f(knots),
        coef_x=_f(c[:, :, 0].T),
        coef_y=_f(c[:, :, 1].T),
        u_min=_f(knots[0]),
        u_max=_f(knots[-1]),
    )
