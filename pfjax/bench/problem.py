"""The benchmark problem: one random batch of the slip model on the source's sine path.

Every implementation (pfjax and the references in :mod:`pfjax.bench.references`) solves the same
runs: path ``y = sin x`` (``x`` in [-10, 60] m), the static state feedback ``delta = K [d, theta_e]``
with the source's published ``K`` sampled every step and held (zero-order hold), saturation at
30 deg, constant slip ``beta_r, beta_f ~ U(-10, 10) deg``, speed 1 m/s, wheelbase 0.2 m, start on
the path at ``x ~ U(0, 2) m`` displaced ``U(-0.5, 0.5) m`` along the normal with heading error
``U(-30, 30) deg``; closest point by 3 warm-started Newton steps, RK4 at 5 ms for 20 s.
The compared output is the per-run IAE = int |d| dt (trapezoid rule on the steps), in m s.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from pfjax.arrays import Leaf

K = (-2.7381, -2.0772)  # the source's published gain (pfjax.controllers.PAPER_K)
V, L, DELTA_MAX = 1.0, 0.2, math.radians(30.0)
U_MIN, U_MAX = -10.0, 60.0
DT, HORIZON, NEWTON_ITERS = 0.005, 20.0, 3
#: The units of K's entries: the state feedback's ``k_d`` and ``k_theta`` (pfjax.controllers.gain_units).
K_UNITS = ("rad/m", "rad/rad")
#: The unit of a rate: million rollout-steps (runs x RK4 steps) per second.
RATE = "1e6 rollout-steps/s"


class Batch(NamedTuple):
    """Initial poses and slips of ``B`` runs, shape ``(B,)`` each (NumPy float64 as drawn; JAX arrays
    in :mod:`pfjax.bench.minimal`)."""

    x0: Leaf  # m
    y0: Leaf  # m
    theta0: Leaf  # rad
    u0: Leaf  # path parameter (x) of the nominal start
    beta_r: Leaf  # rad
    beta_f: Leaf  # rad


def n_steps(horizon: float = HORIZON, dt: float = DT) -> int:
    return int(round(horizon / dt))


def random_batch(n: int, seed: int = 0) -> Batch:
    """``n`` runs drawn with ``numpy.random.default_rng(seed)`` (the distributions in the module doc)."""
    rng = np.random.default_rng(seed)
    u0 = rng.uniform(0.0, 2.0, n)
    off = rng.uniform(-0.5, 0.5, n)
    he = np.radians(rng.uniform(-30.0, 30.0, n))
    br, bf = np.radians(rng.uniform(-10.0, 10.0, (2, n)))
    slope = np.cos(u0)
    th_p = np.arctan2(slope, 1.0)
    x0 = u0 - off * np.sin(th_p)
    y0 = np.sin(u0) + off * np.cos(th_p)
    return Batch(x0, y0, th_p + he, u0, br, bf)


def scenarios(batch: Batch, dtype=np.float32):
    """The batch as a pfjax :class:`~pfjax.sim.Scenario` pytree in ``dtype`` (leading axis = run)."""
    import jax.numpy as jnp

    from pfjax.controllers import state_feedback_params
    from pfjax.models.slip import SOURCE, Pose, SlipParams
    from pfjax.paths import shapes
    from pfjax.sim import Scenario, constant_slip

    n = batch.x0.shape[0]
    f = lambda a: jnp.asarray(
        np.broadcast_to(np.asarray(a, dtype), (n,) + np.shape(a)[np.ndim(a) and np.shape(a)[0] == n :])
    )
    slip = constant_slip(0.0, 0.0)._replace(constant=jnp.asarray(np.stack([batch.beta_r, batch.beta_f], 1), dtype))
    path = shapes.sine(u_min=U_MIN, u_max=U_MAX)
    path = type(path)(*(f(np.asarray(v)) for v in path))
    gains = state_feedback_params(K)
    gains = type(gains)(*(f(np.asarray(g)) for g in gains))
    params = SlipParams(
        v=f(V), L=f(L), delta_max=f(DELTA_MAX), convention=jnp.full((n,), SOURCE, jnp.int32), delta_rate_max=f(np.inf)
    )
    return Scenario(
        pose0=Pose(f(batch.x0), f(batch.y0), f(batch.theta0)),
        slip=slip,
        params=params,
        path=path,
        gains=gains,
        noise=None,
        u0=f(batch.u0),
    )
