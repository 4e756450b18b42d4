"""Local descents of the multi-start tuner, batched over chains: projected BFGS, Adam, compass polish.

Coordinates are box-normalised (``z in [0, 1]^D``, :mod:`pfjax.tuning.gradient`). The gradient
descents take one cost-and-gradient evaluation per chain and step, so every chain advances in
lockstep and the chains batch into one vmapped call (:func:`pfjax.tuning.multistart._step`):

* **projected BFGS** (default): the trial point is ``z + d``, ``d = -H_F g_F`` on the free
  coordinates ``F`` (those not on a bound the gradient pushes against), steepest descent when that
  is not a descent direction, scaled to ``|d|_inf <= radius`` and clipped to the box; a trial that
  lowers the cost is accepted (radius doubled, up to 0.5) and its pair ``s = z_t - z``,
  ``y = g_t - g`` updates the inverse Hessian ``H`` when ``s.y > 0`` (Nocedal & Wright eq. 6.17,
  ``H`` first scaled by eq. 6.20); a rejected trial quarters the radius;
* **Adam**: the cosine-decayed Adam of :func:`pfjax.tuning.gradient.gradient_tune`.

The **compass polish** (:func:`compass_points`, :func:`compass_update`) is value-only: it evaluates
the ``2 D`` points ``z* +- h e_i`` around the incumbent in one batched call, moves to the lowest if
it is lower (``h`` doubled, up to 0.5), and halves ``h`` otherwise (Kolda, Lewis & Torczon 2003,
SIAM Review 45(3), algorithm 3.1 with expansion). IAE costs have kinks along coordinate hyperplanes (where the error
trajectory gains or loses a zero crossing, e.g. ``k_theta = -2`` for the integral controller on the
source's line): the minimum lies in a V-shaped valley along the kink, where a gradient step leaves
the valley floor on every trial and the BFGS radius shrinks to nothing, while compass moves along
the other coordinates stay on it. A value-only rollout costs one forward pass, a gradient rollout
``1 + D`` (:func:`pfjax.numerics.autodiff.forward_passes_per_gradient`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from pfjax.tuning.gradient import adam

LOCALS = ("bfgs", "adam")


class Local(NamedTuple):
    """A batched local descent: ``init(z (m, D)) -> state``; :func:`bfgs_trial` / :func:`bfgs_update`
    (per chain) or Adam's update. Hashable (static under jit)."""

    name: str
    learning_rate: float
    steps: int

    def init(self, z):
        m, D = z.shape
        if self.name == "adam":
            return (z, adam(self.learning_rate, self.steps).init(z))
        eye = jnp.broadcast_to(jnp.eye(D, dtype=z.dtype), (m, D, D))
        inf = jnp.full((m,), jnp.inf, z.dtype)
        return BFGSState(z, inf, jnp.zeros_like(z), eye, jnp.full((m,), self.learning_rate, z.dtype), inf < 0)

    @property
    def program(self) -> Local:
        """The static argument of this descent's compiled step: Adam's schedule depends on its
        learning rate and step count, while BFGS's first radius is in its state (:meth:`init`),
        so every BFGS descent (the halving rounds, the restarts' quarter radius) shares one step
        program per chain count."""
        return self if self.name == "adam" else local(self.name, 0.0, 0)


@functools.lru_cache(maxsize=32)
def local(name: str, learning_rate: float, steps: int) -> Local:
    """The (cached, so compiled programs are shared) local descent ``name`` (:data:`LOCALS`)."""
    return Local(name, learning_rate, steps)


class BFGSState(NamedTuple):
    """Per-chain state of the projected BFGS descent (leading axis: chains)."""

    z: jnp.ndarray  # (D,) accepted point, normalised
    J: jnp.ndarray  # () its cost (inf before the first evaluation)
    g: jnp.ndarray  # (D,) its gradient, normalised units
    H: jnp.ndarray  # (D, D) inverse-Hessian approximation
    radius: jnp.ndarray  # () step bound, inf-norm, normalised units
    scaled: jnp.ndarray  # () bool: H has been scaled by the first curvature pair


def bfgs_trial(st: BFGSState):
    """Projected quasi-Newton trial point: ``d = -H_F g_F`` on the free coordinates ``F`` (not at a
    bound the gradient pushes against), steepest descent if that is not a descent direction, scaled
    to ``|d|_inf <= radius``, clipped to the box. Before the first evaluation: the start itself."""
    at_lo, at_hi = (st.z <= 0.0) & (st.g > 0.0), (st.z >= 1.0) & (st.g < 0.0)
    free = ~(at_lo | at_hi)
    gf = jnp.where(free, st.g, 0.0)
    d = -(st.H * free[:, None] * free[None, :]) @ gf
    d = jnp.where(jnp.dot(gf, d) < 0.0, d, -gf)
    d = d * jnp.minimum(1.0, st.radius / jnp.maximum(jnp.max(jnp.abs(d)), 1e-30))
    return jnp.where(jnp.isfinite(st.J), jnp.clip(st.z + d, 0.0, 1.0), st.z)


def bfgs_update(st: BFGSState, zt, Jt, gt):
    """Accept the trial if it lowers the cost (then double the radius up to 0.5; else quarter it),
    and update ``H`` by BFGS with the accepted pair ``s = z_t - z``, ``y = g_t - g`` when
    ``s.y > 0`` (the first pair scales ``H`` to ``(s.y / y.y) I`` first, Nocedal & Wright eq. 6.20)."""
    first = ~jnp.isfinite(st.J)
    accept = jnp.isfinite(Jt) & (Jt < st.J)
    s, y = zt - st.z, gt - st.g
    sy = jnp.dot(s, y)
    curv = accept & ~first & (sy > 1e-12 * jnp.linalg.norm(s) * jnp.linalg.norm(y)) & (sy > 0)
    D = s.shape[0]
    eye = jnp.eye(D, dtype=s.dtype)
    H0 = jnp.where(st.scaled, st.H, eye * sy / jnp.maximum(jnp.dot(y, y), 1e-300))
    rho = 1.0 / jnp.where(curv, sy, 1.0)
    V = eye - rho * jnp.outer(s, y)
    Hn = V @ H0 @ V.T + rho * jnp.outer(s, s)
    H = jnp.where(curv, Hn, st.H)
    radius = jnp.where(first, st.radius, jnp.where(accept, jnp.minimum(2.0 * st.radius, 0.5), st.radius / 4.0))
    return BFGSState(
        jnp.where(accept, zt, st.z),
        jnp.where(accept, Jt, st.J),
        jnp.where(accept, gt, st.g),
        H,
        radius,
        st.scaled | curv,
    )


def compass_points(z, h: float) -> np.ndarray:
    """The ``2 D`` compass points ``z +- h e_i`` (rows ``+e_0, -e_0, +e_1, ...``), clipped to the box."""
    D = z.size
    steps = np.repeat(np.eye(D), 2, axis=0) * np.tile([h, -h], D)[:, None]
    return np.clip(z[None, :] + steps, 0.0, 1.0)


def compass_update(z, J: float, h: float, Zp, Jp) -> tuple[np.ndarray, float, float]:
    """One compass iteration from ``(z, J)`` with step ``h`` given the costs ``Jp`` at the points
    ``Zp``: the lowest point if it is lower (with ``min(2 h, 0.5)``), else ``z`` with ``h / 2``."""
    Jp = np.where(np.isfinite(Jp), Jp, np.inf)
    i = int(np.argmin(Jp))
    if Jp[i] < J:
        return np.asarray(Zp[i], np.float64), float(Jp[i]), min(2.0 * h, 0.5)
    return z, J, h / 2.0
