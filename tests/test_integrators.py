"""The RK4 step and its rolled form (:mod:`pfjax.sim.integrators`).

References: one step of ``y' = A y`` is the fourth-order Taylor polynomial of ``exp(h A)`` applied to
``y`` (the closed form of classic RK4 on a linear system); the rolled form against the written-out
one on a time-dependent nonlinear pytree system and on the drift model's vector field, in float32
and float64, with their derivatives; the rolled form traces its vector field once.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.sim.integrators import rk4_step, rk4_step_rolled

STEPS = {"written-out": rk4_step, "rolled": rk4_step_rolled}


class State(NamedTuple):
    pos: jax.Array  # shape (2,)
    phase: jax.Array  # shape ()


def _field(p):
    """A time-dependent nonlinear system on a two-leaf pytree (a forced, damped pendulum pair)."""

    def f(t, s):
        a = -p * jnp.sin(s.pos) - 0.3 * s.pos[::-1] + jnp.cos(2.0 * t + s.phase)
        return State(a, 0.5 + 0.1 * jnp.sin(s.pos[0]))

    return f


def _trajectory(step, dtype, p=1.3, n=400, dt=0.01):
    y0 = State(jnp.asarray([0.4, -0.2], dtype), jnp.asarray(0.1, dtype))
    f = _field(jnp.asarray(p, dtype))
    body = lambda y, k: (step(f, k * dt, y, dt),) * 2
    return jax.jit(lambda y: jax.lax.scan(body, y, jnp.arange(n))[1])(y0)


@pytest.mark.parametrize("name", STEPS)
def test_one_step_of_a_linear_system_is_the_taylor_polynomial(name):
    """RK4 on ``y' = A y``: ``y1 = (I + hA + (hA)^2/2 + (hA)^3/6 + (hA)^4/24) y0``, float64, to 1e-15
    relative (a few roundings of numbers of size one)."""
    A = np.array([[-0.5, 2.0], [-3.0, -0.1]])
    y0, h = np.array([0.7, -1.1]), 0.05
    hA = h * A
    poly = np.eye(2) + hA + hA @ hA / 2 + hA @ hA @ hA / 6 + hA @ hA @ hA @ hA / 24
    got = np.asarray(STEPS[name](lambda t, y: jnp.asarray(A) @ y, 0.0, jnp.asarray(y0), h))
    np.testing.assert_allclose(got, poly @ y0, rtol=1e-15, atol=0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rolled_and_written_out_steps_agree_and_keep_the_dtype(dtype):
    """400 steps of the nonlinear pytree system: the same numbers, up to XLA contracting a
    multiply-add into one rounding in one program and not the other (a few units in the last place
    per step, grown by the system's own sensitivity over the run); float32 stays float32."""
    a, b = (_trajectory(s, dtype) for s in STEPS.values())
    for x, y in zip(a, b):
        assert x.dtype == y.dtype == dtype
        eps = np.finfo(dtype).eps
        np.testing.assert_allclose(np.asarray(y), np.asarray(x), rtol=0, atol=50 * eps)


def test_derivatives_through_both_forms_agree():
    """d(final state)/d(parameter) in forward and reverse mode, float64, 1e-12 relative."""
    loss = lambda step: lambda p: jnp.sum(_trajectory(step, np.float64, p=p, n=200).pos[-1])
    for grad in (jax.grad, jax.jacfwd):
        a, b = (float(grad(loss(s))(1.3)) for s in STEPS.values())
        assert abs(a) > 1e-3
        assert b == pytest.approx(a, rel=1e-12)


def test_rolled_form_traces_its_vector_field_once():
    calls = {name: 0 for name in STEPS}
    for name, step in STEPS.items():

        def f(t, y, name=name):
            calls[name] += 1
            return -y

        jax.make_jaxpr(lambda y: step(f, 0.0, y, 0.1))(jnp.ones(3))
    assert calls == {"written-out": 4, "rolled": 1}


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_both_forms_agree_on_the_drift_models_vector_field(dtype):
    """One step of the STD model (Pacejka tyres, the vector field the dynamic simulator integrates)
    from a loaded state: the two forms to a few units in the last place of each component."""
    from pfjax.models import single_track as st

    p = st.drift_parameter_set("vehicle2")
    u = jnp.asarray([0.2, 1.0], dtype)
    x0 = jnp.asarray([0.0, 0.0, 0.05, 12.0, 0.2, 0.3, 0.02, 12.0 / p.R_w, 12.5 / p.R_w], dtype)
    f = lambda t, x: st.rhs_drift(x, u, p)
    a, b = (np.asarray(jax.jit(lambda x, s=s: s(f, 0.0, x, 0.002))(x0)) for s in STEPS.values())
    assert a.dtype == b.dtype == dtype and np.all(np.isfinite(a))
    scale = np.maximum(np.abs(a), 1.0)
    assert np.max(np.abs(a - b) / scale) <= 8 * np.finfo(dtype).eps, np.abs(a - b)
