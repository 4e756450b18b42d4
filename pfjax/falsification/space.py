"""The falsifier's search space: bounded, band-limited slip profiles and boxed initial conditions.

**Slip.** Per axle ``a`` (column 0 rear ``beta_r``, 1 front ``beta_f``), on the hold grid
``t_i = i h`` (``h = seq_dt``, ``i = 0..n-1``, ``n = ceil(T / h) + 1`` for the horizon ``T``)::

    s_a(t)      = c_a + sum_{j=1..m} (p_aj cos(2 pi f_j t) + q_aj sin(2 pi f_j t)),   f_j = j f_max / m
    M_a         = max_i |s_a(t_i)|
    beta_a(t_i) = A tanh(M_a) s_a(t_i) / M_a

with ``A`` the slip bound (rad). The coefficients ``z = (c, p, q)`` are unconstrained; the
simulator holds ``beta_a(t_i)`` on ``[t_i, t_{i+1})`` (``SlipProfile.seq``, zero-order hold).

* *Amplitude (exact).* ``|beta_a(t)| <= A tanh(M_a) < A`` at every time the simulator evaluates:
  the peak is taken over the very samples that are held, so no inter-sample overshoot exists.
* *Bandwidth.* Before the hold, ``beta_a`` is a trigonometric polynomial with frequencies in
  ``{0, f_1, ..., f_m}`` (all ``<= f_max``): ``tanh`` squashes the scalar peak ``M_a``, not the
  signal, so it scales the whole signal by one constant and creates no harmonics. The hold
  itself adds the staircase's images near multiples of ``1/h``, weighted by ``|sinc(f h)|``
  (keep ``h << 1/f_max``; ``h <= 1/(2 f_max)`` is enforced).
* *Coverage.* ``z -> beta`` maps onto ``{beta in span : max_i |beta(t_i)| < A}``: every
  signal of the span whose held peak is below the bound (constants, single sinusoids of any
  phase, square-like waves as far as ``m`` harmonics allow), not only those whose spectral
  amplitudes sum to ``< A``. Along a ray ``z = r z_hat`` the peak is ``A tanh(r M(z_hat))``;
  the map is smooth through ``z = 0``, so gradient steps can change a coefficient's sign (a
  constant slip can go from ``-A`` to ``+A``), and the bound is approached as ``|z| -> inf``,
  never attained.

**Initial conditions.** ``w = (d0, theta_e0, u0)`` in a box ``[lo, hi]`` (m, rad, path
parameter), ``w = lo + (hi - lo) sigmoid(z)``; the start pose is ``d0`` to the left of the
path point ``p(u0)``, heading ``theta_p(u0) + theta_e0``, and the run's projection starts from
``u0`` (``Scenario.u0``), so ``d0`` and ``theta_e0`` are the measured lateral and heading errors
at ``t = 0`` wherever ``p(u0)`` is the local closest point, i.e. ``|d0|`` below the radius of
curvature (a path that comes back near the start cannot capture it).

**Random sampling** of the same set (the baseline): ``z`` uniform in ``[-1, 1]^k`` per axle and
``beta = A s / max(1, M)`` (inside the bound as drawn, scaled back onto it where the draw's
peak exceeds it; for a constant slip this is uniform on ``[-A, A]``); ``w`` uniform in its box.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.models.slip import Pose
from pfjax.paths.geometry import tangent_angle
from pfjax.sim.simulate import Scenario
from pfjax.sim.slip_profiles import slip_profile

#: ``ic_bounds`` keys, in the order of ``w``: lateral offset (m), heading error (deg), path parameter.
IC_KEYS = ("d", "theta_e_deg", "u")


class SearchSpace(NamedTuple):
    """Bounds and slip basis of one search (a pytree of arrays)."""

    basis: Array  # (n, k) at t_i: [1,] cos(2 pi f_j t_i) (j = 1..m), sin(2 pi f_j t_i) (j = 1..m)
    seq_dt: Array  # () s, hold period h
    slip_bound: Array  # () rad, A
    ic_lo: Array  # (3,) lower corner of (d0 m, theta_e0 rad, u0)
    ic_hi: Array  # (3,) upper corner


class RawParams(NamedTuple):
    """Unconstrained parameters of one scenario (what gradient ascent moves)."""

    slip: Array  # (k, 2) coefficients z of s_a, columns (rear, front)
    ic: Array  # (3,) logits of (d0, theta_e0, u0) in their box


def frequencies(f_max_hz: float, n_freq: int) -> np.ndarray:
    """The slip's frequencies ``f_j = j f_max / m``, ``j = 1..m`` (Hz); none when ``f_max = 0``."""
    if f_max_hz == 0:
        return np.zeros((0,))
    return f_max_hz * np.arange(1, n_freq + 1) / n_freq


def _box(key, value) -> tuple[float, float]:
    lo, hi = (value, value) if np.ndim(value) == 0 else tuple(value)
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ValueError(f"ic_bounds[{key!r}]: expected a number or finite (lo, hi) with lo <= hi, got {value!r}")
    return lo, hi


def search_space(
    *,
    horizon: float,
    slip_bound_deg: float,
    f_max_hz: float,
    ic_bounds: dict,
    n_freq: int = 8,
    with_constant: bool = True,
    seq_dt: float = 0.05,
) -> SearchSpace:
    """Validate the bounds and build the :class:`SearchSpace` (NumPy at the edge).

    Args:
        horizon: simulated time, s (the sequence covers ``[0, horizon]``).
        slip_bound_deg: amplitude bound ``A`` on each axle's slip, deg.
        f_max_hz: bandwidth ``f_max``, Hz (0: constant slip only).
        ic_bounds: ``{"d": (lo, hi) m, "theta_e_deg": (lo, hi) deg, "u": (lo, hi) path parameter}``;
            a number fixes the quantity, a missing key fixes it at 0.
        n_freq: number ``m`` of frequencies on ``(0, f_max]`` (ignored when ``f_max = 0``).
        with_constant: include the constant term ``c_a`` (a zero-mean slip otherwise).
        seq_dt: hold period ``h``, s.
    """
    if not (math.isfinite(slip_bound_deg) and slip_bound_deg >= 0):
        raise ValueError(f"slip_bound_deg: must be finite and >= 0, got {slip_bound_deg}")
    if not (seq_dt > 0 and math.isfinite(seq_dt)):
        raise ValueError(f"seq_dt: must be > 0 s, got {seq_dt}")
    if not (math.isfinite(f_max_hz) and 0 <= f_max_hz <= 0.5 / seq_dt):
        raise ValueError(f"f_max_hz: must be in [0, 1/(2 seq_dt)] = [0, {0.5 / seq_dt:g}] Hz, got {f_max_hz}")
    if f_max_hz > 0 and (int(n_freq) != n_freq or n_freq < 1):
        raise ValueError(f"n_freq: must be a positive integer, got {n_freq}")
    if f_max_hz == 0 and not with_constant:
        raise ValueError("f_max_hz = 0 with with_constant = False leaves no slip to search")
    unknown = sorted(set(ic_bounds) - set(IC_KEYS))
    if unknown:
        raise ValueError(f"ic_bounds: unknown key {unknown[0]!r}; expected some of {list(IC_KEYS)}")
    lo, hi = np.array([_box(k, ic_bounds.get(k, 0.0)) for k in IC_KEYS]).T
    lo[1], hi[1] = np.radians(lo[1]), np.radians(hi[1])

    t = seq_dt * np.arange(int(math.ceil(horizon / seq_dt - 1e-9)) + 1)
    w = 2 * np.pi * np.outer(t, frequencies(f_max_hz, int(n_freq)))
    cols = ([np.ones((t.size, 1))] if with_constant else []) + [np.cos(w), np.sin(w)]
    f = lambda a: jnp.asarray(a, dtype=float)
    return SearchSpace(
        basis=f(np.concatenate(cols, axis=1)),
        seq_dt=f(seq_dt),
        slip_bound=f(math.radians(slip_bound_deg)),
        ic_lo=f(lo),
        ic_hi=f(hi),
    )


def _peak(s: Array) -> Array:
    return jnp.max(jnp.abs(s), axis=0)


def slip_from_raw(space: SearchSpace, z: Array) -> Array:
    """``beta(t_i) = A tanh(M) s(t_i) / M``, shape ``(n, 2)`` rad (module docstring).

    ``M`` is a max: its gradient flows through the sample that attains it (through one of
    them where samples tie). ``tanh(M)/M -> 1`` as ``M -> 0`` is evaluated safely.
    """
    s = space.basis @ z
    m = _peak(s)
    safe = jnp.where(m > 0, m, 1.0)
    return space.slip_bound * s * jnp.where(m > 0, jnp.tanh(safe) / safe, 1.0)


def ic_from_raw(space: SearchSpace, z: Array) -> Array:
    """``w = lo + (hi - lo) sigmoid(z)``: ``(d0 m, theta_e0 rad, u0)``."""
    return space.ic_lo + (space.ic_hi - space.ic_lo) * jax.nn.sigmoid(z)


def start_pose(path, ic: Array) -> Pose:
    """The pose ``d0`` left of ``p(u0)`` with heading error ``theta_e0`` (m, m, rad)."""
    d0, theta_e0, u0 = ic[0], ic[1], ic[2]
    px, py = path.point(u0)
    theta_p = tangent_angle(path, u0)
    return Pose(px - d0 * jnp.sin(theta_p), py + d0 * jnp.cos(theta_p), theta_p + theta_e0)


def build_scenario(space: SearchSpace, seq: Array, ic: Array, base: Scenario) -> Scenario:
    """``base`` (path, gains, physical parameters, noise) with the slip sequence ``seq`` and the start ``ic``."""
    # u0 = the start's path parameter: the run is matched to p(u0), not to a global closest point
    return base._replace(pose0=start_pose(base.path, ic), slip=slip_profile(seq=seq, seq_dt=space.seq_dt), u0=ic[2])


@partial(jax.jit, static_argnames="n")
def init_raw(space: SearchSpace, key: Array, n: int) -> RawParams:
    """``n`` random starting points: ``z ~ N(0, 1/k)`` (peak ``A tanh(M)`` with ``M`` of order 1-2),
    logits uniform on ``[-2, 2]`` (``w`` spread over the middle 76 % of each box). One jitted program
    (op by op, each of its operations would be compiled on its own: seconds in a cold process)."""
    k_slip, k_ic = jax.random.split(key)
    k = space.basis.shape[1]
    return RawParams(
        slip=jax.random.normal(k_slip, (n, k, 2), dtype=space.basis.dtype) / math.sqrt(k),
        ic=jax.random.uniform(k_ic, (n, 3), dtype=space.basis.dtype, minval=-2.0, maxval=2.0),
    )


@partial(jax.jit, static_argnames="n")
def sample(space: SearchSpace, key: Array, n: int) -> tuple[Array, Array]:
    """``n`` random draws of the set, as the module docstring's *Random sampling*: slip ``(n, n_seq, 2)``
    rad, ``ic`` ``(n, 3)``. One jitted program, as :func:`init_raw`."""
    k_slip, k_ic = jax.random.split(key)
    k = space.basis.shape[1]
    z = jax.random.uniform(k_slip, (n, k, 2), dtype=space.basis.dtype, minval=-1.0, maxval=1.0)
    s = jnp.einsum("ik,nka->nia", space.basis, z)
    seq = space.slip_bound * s / jnp.maximum(1.0, jnp.max(jnp.abs(s), axis=1, keepdims=True))
    u = jax.random.uniform(k_ic, (n, 3), dtype=space.basis.dtype)
    return seq, space.ic_lo + (space.ic_hi - space.ic_lo) * u
