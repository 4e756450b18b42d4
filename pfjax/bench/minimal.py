"""A minimal JAX implementation of the benchmark problem, written for speed: the limit pfjax's
simulator is measured against.

It solves exactly the runs of :mod:`pfjax.bench.problem` with the steps of
:mod:`pfjax.bench.references` (3 safeguarded Newton steps from the previous closest point, the
held state-feedback command, RK4 at 5 ms, the trapezoid IAE) and nothing else: no metrics but the
IAE, no statuses, no path pytree (``y = sin x`` is written in), no slip profile (constant slip),
no controller interface. It uses what the simulator uses to be fast, so that the difference
between the two is the cost of the simulator's generality and nothing else:

* the same elementary functions (:mod:`pfjax.numerics.elementary`: polynomial sine, cosine and
  arctangent, the shared sine-cosine pair) and the simulator's cheapest forms of the geometry: the
  Newton step bounded by one square root of a ratio, the unit tangent by one reciprocal square
  root, the heading error by one arctangent of the rotated heading (no angle wrap);
* the same devices and blocks (:func:`pfjax.sim.sharding.plan_batch` and
  :func:`~pfjax.sim.sharding.map_runs`: the batch split over every device, each device's share in
  cache-sized blocks);
* the same compiler options (:func:`pfjax.numerics.compiler.jit`).

It also does what the general simulator cannot: ``y = sin x`` gives the path's point and
derivatives from one sine-cosine pair, the heading's sine and cosine from one step's measurement
are reused by the next step's first RK4 stage, and RK4's two middle stages (the same heading,
since the yaw rate is constant over a step) are computed once.

The per-run IAE agrees with pfjax's to the benchmark's tolerances (:data:`pfjax.bench.run.TOLERANCE`).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from pfjax.bench import problem as P
from pfjax.numerics import compiler
from pfjax.numerics import elementary as E
from pfjax.sim import sharding


def _newton(u, x, y):
    """One safeguarded Newton step towards the closest point of ``p(u) = (u, sin u)`` to ``(x, y)``."""
    su, cu = E.sincos(u)
    ex, ey = u - x, su - y
    speed2 = 1.0 + cu * cu
    g = ex + ey * cu
    gp = speed2 - ey * su
    gp = jnp.where(gp > 0.01 * speed2, gp, speed2)  # Gauss-Newton where the curvature term dominates
    # max(|p - q|, 0.25) / |p'| as one square root of a ratio (no rsqrt: see elementary.rsqrt)
    max_step = jnp.sqrt(jnp.maximum(ex * ex + ey * ey, 0.0625) / speed2)
    return jnp.clip(u + jnp.clip(-g / gp, -max_step, max_step), P.U_MIN, P.U_MAX)


def _measure(u, x, y, sh, ch):
    """``(d, theta_e)``: signed lateral distance (m) and heading error (rad, in [-pi, pi]) at the
    point ``u``, for the heading's sine ``sh`` and cosine ``ch``: the unit tangent
    ``(1, cos u) / sqrt(1 + cos^2 u)`` and one arctangent, no angle wrap."""
    su, cu = E.sincos(u)
    tx = E.rsqrt(1.0 + cu * cu)
    ty = cu * tx
    d = -(x - u) * ty + (y - su) * tx
    return d, E.atan2(tx * sh - ty * ch, tx * ch + ty * sh)


def _run(r: P.Batch, n_steps: int) -> jax.Array:
    """The IAE of one run (m s)."""
    x, y, th, u, br, bf = r
    dt = P.DT
    tbr = E.tan(br)
    u = jax.lax.fori_loop(0, 8, lambda _, u: _newton(u, x, y), u)
    sh, ch = E.sincos(th)
    d, te = _measure(u, x, y, sh, ch)

    def rhs(s, c):
        return P.V * (c - tbr * s), P.V * (s + tbr * c)

    def step(_, carry):
        x, y, th, sh, ch, u, d, te, iae = carry
        delta = jnp.clip(P.K[0] * d + P.K[1] * te, -P.DELTA_MAX, P.DELTA_MAX)
        w = (P.V / P.L) * (E.tan(delta - bf) - tbr)  # yaw rate, constant over the step (constant slip)
        x1, y1 = rhs(sh, ch)  # the heading's sine and cosine carried from the last measurement
        x2, y2 = rhs(*E.sincos(th + 0.5 * dt * w))  # stages 2 and 3 coincide: theta' does not depend on the state
        th = th + dt * w
        sh, ch = E.sincos(th)
        x4, y4 = rhs(sh, ch)
        x = x + (dt / 6.0) * (x1 + 4.0 * x2 + x4)
        y = y + (dt / 6.0) * (y1 + 4.0 * y2 + y4)
        for _ in range(P.NEWTON_ITERS):
            u = _newton(u, x, y)
        d, te = _measure(u, x, y, sh, ch)
        return x, y, th, sh, ch, u, d, te, iae + dt * jnp.abs(d)

    d0 = d
    init = (x, y, th, sh, ch, u, d, te, jnp.zeros_like(x))
    *_, d_n, _, iae = jax.lax.fori_loop(0, n_steps, step, init)
    return iae + 0.5 * dt * (jnp.abs(d0) - jnp.abs(d_n))  # trapezoid: half weight at both ends


@partial(compiler.jit, static_argnames=("n_steps", "layout"))
def _batch(runs: P.Batch, *, n_steps: int, layout: sharding.Layout) -> jax.Array:
    return sharding.map_runs(partial(_run, n_steps=n_steps), runs, layout)


def runs(batch: P.Batch, dtype=np.float32) -> P.Batch:
    """The batch as JAX arrays of ``dtype`` (float64 needs ``jax.enable_x64``)."""
    return P.Batch(*(jnp.asarray(np.asarray(a, dtype)) for a in batch))


def simulate(r: P.Batch, n_steps: int | None = None, devices=None) -> jax.Array:
    """Per-run IAE (m s) of the runs ``r`` (from :func:`runs`), computed on every device in blocks
    as pfjax's simulator is (what the benchmark times)."""
    n_steps = P.n_steps() if n_steps is None else n_steps
    placed, n, layout = sharding.plan_batch(r, devices)
    return sharding.unpad(_batch(placed, n_steps=n_steps, layout=layout), n)


def iae(batch: P.Batch, dtype=np.float32, n_steps: int | None = None, devices=None) -> np.ndarray:
    """Per-run IAE (m s) of ``batch`` in ``dtype`` (float64 needs ``jax.enable_x64``), as NumPy."""
    return np.asarray(simulate(runs(batch, dtype), n_steps, devices), np.float64)
