"""Leader motions: the leader's reference point ``z_d(t)`` as one pytree (a batch can mix kinds).

A leader moves along a planar curve ``c(u)`` with its path parameter advancing as ``u = s(t)``::

    z_d(t) = (x0, y0) + Rot(heading) (c(s(t)) - c(0))

Curves (``kind``):

* ``GRAPH`` (0): ``c(u) = (u, sum_k A_k sin(w_k u + ph_k))`` — a line (all ``A_k = 0``), a sine
  (one term) or a random smooth path (several random terms);
* ``CIRCLE`` (1): ``c(u) = (R sin(u/R), R (1 - cos(u/R)))``, ``u`` arc length, ``R < 0`` turns right;
* ``LANE_CHANGE`` (2): ``c(u) = (u, W/2 (1 + tanh((u - u_c) / L_c)))``.

Speed profile (stop-and-go when ``depth > 0``; constant speed ``V0`` when ``depth = 0``)::

    s'(t) = V0 (1 - depth (1 - cos(2 pi t / T)) / 2)                 (0 <= depth <= 1)
    s(t)  = V0 (t - depth (t/2 - T/(4 pi) sin(2 pi t / T)))

``depth = 1`` stops the leader at ``t = T/2, 3T/2, ...``. For graphs ``u`` is the abscissa, so the
leader's speed is ``s'(t) |c'(u)|``. The velocity ``z_d'(t)`` is the exact derivative (``jax.jvp``).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.arrays import Leaf
from pfjax.numerics import elementary as E

GRAPH, CIRCLE, LANE_CHANGE = 0, 1, 2
N_TERMS = 3  # sinusoids of a graph leader
KINDS = ("line", "circle", "sine", "lane-change", "random")


class Leader(NamedTuple):
    kind: Leaf  # int: GRAPH, CIRCLE, LANE_CHANGE
    x0: Leaf  # m, start point
    y0: Leaf  # m
    heading: Leaf  # rad, rotation of the curve (initial direction of travel for line / circle)
    speed: Leaf  # m/s, V0 (rate of u)
    depth: Leaf  # -, stop-and-go depth in [0, 1]
    period: Leaf  # s, stop-and-go period T
    amps: Leaf  # (N_TERMS,) m, graph amplitudes
    omegas: Leaf  # (N_TERMS,) rad/m, graph wavenumbers
    phases: Leaf  # (N_TERMS,) rad
    radius: Leaf  # m, circle radius (signed, left positive)
    lane_width: Leaf  # m, W
    lane_center: Leaf  # m, u_c
    lane_length: Leaf  # m, L_c


def _leader(
    kind,
    *,
    x0=0.0,
    y0=0.0,
    heading=0.0,
    speed=1.0,
    depth=0.0,
    period=10.0,
    amps=None,
    omegas=None,
    phases=None,
    radius=5.0,
    lane_width=3.5,
    lane_center=10.0,
    lane_length=3.0,
) -> Leader:
    def vec(v, fill):
        out = np.full(N_TERMS, fill, dtype=float)
        if v is not None:
            v = np.atleast_1d(np.asarray(v, dtype=float))
            out[: v.size] = v
        return out

    f = lambda v: np.asarray(v, dtype=float)
    return Leader(
        kind=np.asarray(kind, dtype=np.int32),
        x0=f(x0),
        y0=f(y0),
        heading=f(heading),
        speed=f(speed),
        depth=f(depth),
        period=f(period),
        amps=vec(amps, 0.0),
        omegas=vec(omegas, 1.0),
        phases=vec(phases, 0.0),
        radius=f(radius),
        lane_width=f(lane_width),
        lane_center=f(lane_center),
        lane_length=f(lane_length),
    )


def line(speed=1.0, heading=0.0, **kw) -> Leader:
    """Straight line at constant speed (or stop-and-go with ``depth``)."""
    return _leader(GRAPH, speed=speed, heading=heading, **kw)


def sine(amplitude=1.0, wavenumber=0.3, speed=1.0, **kw) -> Leader:
    """``y = A sin(k x)`` along the heading."""
    return _leader(GRAPH, amps=[amplitude], omegas=[wavenumber], speed=speed, **kw)


def circle(radius=5.0, speed=1.0, **kw) -> Leader:
    """Circle of signed radius (left turn positive), entered along ``heading``."""
    return _leader(CIRCLE, radius=radius, speed=speed, **kw)


def lane_change(width=3.5, center=10.0, length=3.0, speed=1.0, **kw) -> Leader:
    """Smooth lateral step of ``width`` centred at ``u = center`` over ``~2 length``."""
    return _leader(LANE_CHANGE, lane_width=width, lane_center=center, lane_length=length, speed=speed, **kw)


def random_smooth(key, speed=1.0, max_curvature=0.1, **kw) -> Leader:
    """Random smooth graph: three sinusoids, wavenumbers in [0.1, 0.5] rad/m, random phases.

    Amplitudes are scaled so that ``sum_k A_k w_k^2 <= max_curvature`` (a bound on ``|y''|``, hence
    on the curvature), so the path stays within the follower's turning ability.
    """
    k1, k2, k3 = jax.random.split(key, 3)
    w = jax.random.uniform(k1, (N_TERMS,), minval=0.1, maxval=0.5)
    raw = jax.random.uniform(k2, (N_TERMS,), minval=0.2, maxval=1.0)
    amps = raw * max_curvature / jnp.sum(raw * w**2)
    ph = jax.random.uniform(k3, (N_TERMS,), minval=-jnp.pi, maxval=jnp.pi)
    return _leader(GRAPH, amps=np.asarray(amps), omegas=np.asarray(w), phases=np.asarray(ph), speed=speed, **kw)


def by_name(name: str, **kw) -> Leader:
    """A leader from its CLI name (``line``, ``circle``, ``sine``, ``lane-change``); ``kw`` go to it."""
    return {"line": line, "circle": circle, "sine": sine, "lane-change": lane_change}[name](**kw)


def progress(ld: Leader, t: Array) -> Array:
    """``s(t)`` (see module doc), m."""
    T = ld.period
    return jnp.asarray(ld.speed) * (t - ld.depth * (0.5 * t - T / (4.0 * jnp.pi) * E.sin(2.0 * jnp.pi * t / T)))


def _curve(ld: Leader, u: Array) -> tuple[Array, Array]:
    """``c(u)`` as its two components, m. Component by component and one sinusoid at a time: every
    operation is an array over the runs (a ``(runs, 2)`` stack or a ``(runs, N_TERMS)`` sine and its
    sum do not vectorise over the runs on CPU; see :mod:`pfjax.numerics.layout`)."""
    gy = sum(ld.amps[..., i] * E.sin(ld.omegas[..., i] * u + ld.phases[..., i]) for i in range(ld.amps.shape[-1]))
    R = ld.radius
    cs, cc = E.sincos(u / R)
    ly = 0.5 * ld.lane_width * (1.0 + jnp.tanh((u - ld.lane_center) / ld.lane_length))
    circle, lane = ld.kind == CIRCLE, ld.kind == LANE_CHANGE
    x = jnp.where(circle, R * cs, u)
    y = jnp.where(circle, R * (1.0 - cc), jnp.where(lane, ly, gy))
    return x, y


def curve_point(ld: Leader, u: Array) -> Array:
    """World point of the leader's curve at parameter ``u``, ``(2,)`` m."""
    x, y = _curve(ld, u)
    x0, y0 = _curve(ld, jnp.zeros_like(u))
    lx, ly = x - x0, y - y0
    s, c = E.sincos(ld.heading)
    return jnp.stack([ld.x0 + c * lx - s * ly, ld.y0 + s * lx + c * ly])


def position(ld: Leader, t: Array) -> Array:
    """``z_d(t)``, ``(2,)`` m."""
    return curve_point(ld, progress(ld, t))


def position_velocity(ld: Leader, t: Array) -> tuple[Array, Array]:
    """``(z_d(t), z_d'(t))``, m and m/s (exact derivative by forward-mode AD)."""
    t = jnp.asarray(t, dtype=jnp.result_type(float))
    return jax.jvp(lambda tt: position(ld, tt), (t,), (jnp.ones_like(t),))


def start_heading(ld: Leader) -> Array:
    """Direction of travel at ``t = 0``, rad."""
    _, du = jax.jvp(lambda u: curve_point(ld, u), (jnp.zeros(()),), (jnp.ones(()),))
    return E.atan2(du[1], du[0])
