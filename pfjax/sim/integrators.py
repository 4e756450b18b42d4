"""Fixed-step explicit integrators on pytrees.

:func:`rk4_step` writes the four stages out, so the vector field appears four times in the compiled
program; :func:`rk4_step_rolled` computes the same step with the stages as one loop of four
iterations, so it appears once. They perform the same floating-point operations in the same order
(results differ at most where XLA contracts a multiply and an add into one fused operation in one
program and not the other: the last bit). Which to use is a compile-time against run-time choice,
measured per simulator (:mod:`pfjax.sim.dynamic` and the slip vehicle's continuous controllers
use the rolled step).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax


def _axpy(y, a, k):
    return jax.tree_util.tree_map(lambda yi, ki: yi + a * ki, y, k)


def rk4_step(f, t, y, dt):
    """Classic fourth-order Runge-Kutta step for ``y' = f(t, y)`` on any pytree ``y``.

    Local error O(dt^5), global O(dt^4) for smooth ``f`` (measured in the tests); a kink in
    ``f`` (steering saturation) lowers the local order at the step that crosses it.
    """
    k1 = f(t, y)
    k2 = f(t + 0.5 * dt, _axpy(y, 0.5 * dt, k1))
    k3 = f(t + 0.5 * dt, _axpy(y, 0.5 * dt, k2))
    k4 = f(t + dt, _axpy(y, dt, k3))
    return jax.tree_util.tree_map(
        lambda yi, a, b, c, d: yi + (dt / 6.0) * (a + 2.0 * b + 2.0 * c + d), y, k1, k2, k3, k4
    )


def rk4_step_rolled(f, t, y, dt):
    """:func:`rk4_step` with its four stages as one loop (``lax.fori_loop``, four iterations), so
    ``f`` is traced and compiled once instead of four times.

    Stage ``i`` evaluates ``k_i = f(t + c_i dt, y + a_i dt k_{i-1})`` with ``c = a = (0, 1/2, 1/2,
    1)`` (stage 0 takes ``t`` and ``y`` themselves) and adds ``w_i k_i`` to a sum, ``w = (1, 2, 2,
    1)``; the step is ``y + dt/6 * sum``. Every coefficient is a weakly typed scalar as in
    :func:`rk4_step`, so a float32 state stays float32, and the additions happen in the same order:
    the two functions agree to the last bit up to XLA's contraction of a multiply-add.

    For a large ``f`` (a tyre model: :mod:`pfjax.sim.dynamic`) XLA compiles the loop several times
    faster than the written-out stages and runs it as fast; for a small ``f`` the written-out
    stages are as quick to compile (measured: docs/performance.md, "How the simulator is made
    fast").
    """
    tm = jax.tree_util.tree_map

    def stage(i, carry):
        k, acc = carry
        first = i == 0
        h = jnp.where(i == 3, dt, 0.5 * dt)  # a_i dt (stage 0 does not use it)
        w = jnp.where((i == 1) | (i == 2), 2.0, 1.0)
        y_in = tm(lambda yi, zi: jnp.where(first, yi, zi), y, _axpy(y, h, k))
        k = f(jnp.where(first, t, t + h), y_in)
        return k, tm(lambda s, ki: s + w * ki, acc, k)

    zeros = tm(jnp.zeros_like, y)
    _, acc = lax.fori_loop(0, 4, stage, (zeros, zeros))
    return _axpy(y, dt / 6.0, acc)
