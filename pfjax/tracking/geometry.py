"""Focus point, virtual connection, tracking error and the focus point's input matrix (docs/reproductions/vehicle-tracking.md §2, §4).

Reference point (``c_f = (1 + f)/2``: 1 forward, 0 backward)::

    P_ref = P_b + c_f a (cos theta, sin theta)

Focus point, the output ``z`` (eq. 8.5)::

    z = P_r = P_ref + l (cos(theta + p gamma), sin(theta + p gamma))

Virtual connection (eq. 8.4): the leader's point ``z_d`` seen from ``P_ref`` in the follower's body
frame is ``w = R(theta) (z_d - P_ref)``; pfjax writes it as ``w = f d (cos phi, sin phi)`` with the
connection angle ``phi`` in ``(-pi/2, pi/2]`` (the connection is the line through ``P_ref`` and
``z_d``; ``phi`` is its angle to the heading) and ``d`` signed: ``d > 0`` when the leader lies in
the tracked half-plane (ahead of ``P_ref`` for ``f = +1``, behind it for ``f = -1``). Then (eq. 8.7)::

    z~ = z - z_d = R(theta)^T [ l cos(p gamma) - f d cos phi ;  l sin(p gamma) - f d sin phi ]

Output derivative (no slip): ``z' = M(theta, gamma) [v; omega]`` with, writing
``e(.) = (cos ., sin .)`` and ``n(.) = (-sin ., cos .)``::

    M[:, 0] = e(theta) + c_f tan(gamma) n(theta) + (l / a) tan(gamma) n(theta + p gamma)
    M[:, 1] = l p n(theta + p gamma)
    det M   = l p (cos(p gamma) + c_f tan(gamma) sin(p gamma))

so backward (``c_f = 0``): ``det M = l p cos(p gamma)``, invertible on ``|gamma| <= gamma_max`` iff
``|p| < pi / (2 gamma_max)`` (the bound of Lemma 8.1); forward (``c_f = 1``):
``det M = l p cos((p - 1) gamma) / cos(gamma)``, invertible iff ``|p - 1| < pi / (2 gamma_max)``.
Both need ``l != 0`` and ``p != 0``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
from jax import Array

from pfjax.numerics import elementary as E
from pfjax.tracking.model import Follower, FollowerParams


class Connection(NamedTuple):
    """Virtual intervehicular connection (eq. 8.4)."""

    d: Array  # m, signed length (positive: leader in the tracked half-plane)
    phi: Array  # rad, angle to the follower's heading, in (-pi/2, pi/2]


def _cf(params: FollowerParams) -> Array:
    return 0.5 * (1.0 + jnp.asarray(params.f))


def reference_point(s: Follower, params: FollowerParams) -> tuple[Array, Array]:
    """``P_ref``: front-axle centre (``f = +1``) or rear-axle centre (``f = -1``), m."""
    ca = _cf(params) * params.a
    return s.x + ca * E.cos(s.theta), s.y + ca * E.sin(s.theta)


def focus_point(s: Follower, params: FollowerParams) -> Array:
    """The output ``z = P_r`` (eq. 8.5), shape ``(2,)``, m."""
    rx, ry = reference_point(s, params)
    ang = s.theta + params.p * s.gamma
    return jnp.stack([rx + params.l * E.cos(ang), ry + params.l * E.sin(ang)])


def body_vector(s: Follower, zd: Array, params: FollowerParams) -> Array:
    """``w = R(theta) (z_d - P_ref)``: the leader's point in the follower's body frame, ``(2,)`` m."""
    rx, ry = reference_point(s, params)
    dx, dy = zd[0] - rx, zd[1] - ry
    c, sn = E.cos(s.theta), E.sin(s.theta)
    return jnp.stack([c * dx + sn * dy, -sn * dx + c * dy])


def connection(s: Follower, zd: Array, params: FollowerParams) -> Connection:
    """``(d, phi)`` with ``w = f d (cos phi, sin phi)``, ``phi`` in ``(-pi/2, pi/2]`` (see module doc)."""
    w = body_vector(s, zd, params)
    flip = (w[0] < 0) | ((w[0] == 0) & (w[1] < 0))  # the half-line representative in (-pi/2, pi/2]
    wx, wy = jnp.where(flip, -w[0], w[0]), jnp.where(flip, -w[1], w[1])
    phi = E.atan2(wy, wx)
    d = jnp.asarray(params.f) * jnp.where(flip, -1.0, 1.0) * jnp.hypot(wx, wy)
    return Connection(d=d, phi=phi)


def tracking_error(s: Follower, zd: Array, params: FollowerParams) -> Array:
    """``z~ = z - z_d`` in the world frame (eq. 8.7), ``(2,)`` m."""
    return focus_point(s, params) - zd


def tracking_error_from_connection(s: Follower, conn: Connection, params: FollowerParams) -> Array:
    """Eq. 8.7 written with the connection: ``R^T(theta) [l cos pg - f d cos phi; l sin pg - f d sin phi]``."""
    pg = params.p * s.gamma
    fd = jnp.asarray(params.f) * conn.d
    bx = params.l * E.cos(pg) - fd * E.cos(conn.phi)
    by = params.l * E.sin(pg) - fd * E.sin(conn.phi)
    c, sn = E.cos(s.theta), E.sin(s.theta)
    return jnp.stack([c * bx - sn * by, sn * bx + c * by])


def input_matrix(theta: Array, gamma: Array, params: FollowerParams) -> Array:
    """``M(theta, gamma)`` with ``z' = M [v; omega]`` (slip-free model), ``(2, 2)``; columns in m/m, m/rad."""
    tg = E.tan(gamma)
    ang = theta + params.p * gamma
    cf = _cf(params)
    e = jnp.stack([E.cos(theta), E.sin(theta)])
    n = jnp.stack([-E.sin(theta), E.cos(theta)])
    nf = jnp.stack([-E.sin(ang), E.cos(ang)])
    col_v = e + cf * tg * n + (params.l / params.a) * tg * nf
    col_w = params.l * params.p * nf
    return jnp.stack([col_v, col_w], axis=1)


def input_det(gamma: Array, params: FollowerParams) -> Array:
    """Closed form ``det M = l p (cos(p gamma) + c_f tan(gamma) sin(p gamma))`` (independent of ``theta``)."""
    pg = params.p * gamma
    return jnp.asarray(params.l) * params.p * (E.cos(pg) + _cf(params) * E.tan(gamma) * E.sin(pg))


def invertibility_factor(gamma: Array, params: FollowerParams) -> Array:
    """``det M / (l p)``: ``cos(p gamma)`` backward, ``cos((p - 1) gamma) / cos(gamma)`` forward."""
    pg = params.p * gamma
    return E.cos(pg) + _cf(params) * E.tan(gamma) * E.sin(pg)


def p_bound(gamma_max: float, f: int) -> tuple[float, float]:
    """Open interval of ``p`` on which ``M`` is invertible for every ``|gamma| <= gamma_max`` (``p != 0``).

    Backward: ``|p| < pi/(2 gamma_max)``; forward: ``|p - 1| < pi/(2 gamma_max)``.
    """
    b = math.pi / (2.0 * gamma_max)
    return (-b, b) if f < 0 else (1.0 - b, 1.0 + b)


def lemma_bound(gamma_max: float) -> float:
    """Lemma 8.1's bound on ``|p|``: ``pi / (2 gamma_max)``."""
    return math.pi / (2.0 * gamma_max)
