"""Equilibria and local stability of the state-feedback loop under constant slip (docs/reproductions/path-following.md §7).

Closed loop on a path of constant curvature ``kappa`` (0: the straight line) with
``delta = sat(K x)``, ``x = [d, theta_e]``, in the Frenet model (eq. 6)::

    d'       = v (sin theta_e + tan beta_r cos theta_e)
    theta_e' = yaw_rate(delta, beta_r, beta_f) - kappa v (cos theta_e - tan beta_r sin theta_e) / (1 - kappa d)

**True equilibrium.** ``d' = 0`` forces ``theta_e* = -beta_r`` (forward travel). On a line the yaw
rate must vanish, so ``delta* = beta_r + beta_f`` (source convention; ``beta_r - beta_f`` in
Lenain's), and ``K x* = delta*`` gives ``d* = (delta* + K_2 beta_r) / K_1``. The equilibrium exists
only if ``|delta*| <= delta_max``: beyond, the saturated loop has no rest point. On a curve the
same holds with ``d*`` solved by Newton, which counts as converged when its last step is below
``64 eps (|d| + L)`` (``eps`` of the working precision: a criterion that means the same in float32
and float64; measured, converged points take last steps below ``8 eps (|d| + L)`` in both). The
boundary ``|delta*| = delta_max``, up to ``max(1e-9, 1000 eps)`` rad, counts as existing (not as
locally stable, below): the loop rests there with the steering at its limit, and rounding must not
decide which side a grid point falls on. The source instead linearises at ``[0, -beta_r]`` (appendix B), which is not an
equilibrium unless ``delta* = -K_2 beta_r``.

**Local stability.** Eigenvalues of the Jacobian of the unsaturated field at the point
(closed form for 2x2). ``hurwitz`` asks, besides both real parts < 0, that the steering at the
equilibrium is inside the limit, ``|delta*| < delta_max`` by more than the boundary's tolerance: on
the boundary the steering is at its limit, so a disturbance that asks for more gets none, the yaw
rate stays zero, ``theta_e`` stays where it is and ``d`` drifts (the runs of the line test from the
source's start drift away there), whatever the unsaturated eigenvalues say. All functions are
jittable and vmap over slip grids.
"""

from __future__ import annotations

from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.models.slip import FRONT_SLIP_SIGN, LENAIN, SOURCE, FrenetState, SlipParams, frenet_rhs


class Equilibrium(NamedTuple):
    d: Array  # m
    theta_e: Array  # rad
    delta: Array  # rad, steering at the equilibrium
    exists: Array  # bool: Newton converged and |delta| <= delta_max (the boundary included, up to a tolerance)
    eig: Array  # (2,) complex, eigenvalues of the unsaturated loop's Jacobian there
    hurwitz: Array  # bool: exists, |delta| < delta_max (off the boundary) and both real parts < 0


def closed_loop_field(x: Array, K: Array, beta_r, beta_f, kappa, params: SlipParams, saturate=True) -> Array:
    """``[d', theta_e']`` of the state-feedback loop (Frenet model, constant ``kappa``)."""
    delta = K[0] * x[0] + K[1] * x[1]
    if saturate:
        delta = jnp.clip(delta, -params.delta_max, params.delta_max)
    dx = frenet_rhs(FrenetState(x[0], x[1], jnp.zeros_like(x[0])), delta, beta_r, beta_f, kappa, params)
    return jnp.stack([dx.d, dx.theta_e])


def _eig2(J: Array) -> Array:
    tr, det = J[0, 0] + J[1, 1], J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]
    disc = jnp.sqrt((0.25 * tr * tr - det).astype(complex))
    return jnp.stack([0.5 * tr + disc, 0.5 * tr - disc])


@jax.jit
def jacobian_eigenvalues(x: Array, K: Array, beta_r, beta_f, kappa, params: SlipParams) -> Array:
    """Eigenvalues of the unsaturated loop's Jacobian at ``x`` (rad/s)."""
    J = jax.jacfwd(closed_loop_field)(x, K, beta_r, beta_f, kappa, params, False)
    return _eig2(J)


@partial(jax.jit, static_argnames="iters")
def equilibrium(K: Array, beta_r, beta_f, params: SlipParams, kappa=0.0, iters: int = 30) -> Equilibrium:
    """True equilibrium of the loop for constant slip (and curvature) and its local stability.

    Jitted (``iters`` static): the 30 Newton steps run as one compiled program, not op by op
    (a call from Python took 5 s eagerly)."""
    K = jnp.asarray(K, float)
    theta = -jnp.asarray(beta_r, float)
    lenain = jnp.asarray(params.convention) == LENAIN
    sign = jnp.where(lenain, FRONT_SLIP_SIGN[LENAIN], FRONT_SLIP_SIGN[SOURCE])
    delta_line = beta_r + sign * beta_f  # the steering that holds a straight line
    d = (delta_line - K[1] * theta) / K[0]

    # Newton on theta_e' = 0 in d (theta_e fixed at -beta_r makes d' = 0 exactly).
    g = lambda dd: closed_loop_field(jnp.stack([dd, theta]), K, beta_r, beta_f, kappa, params, False)[1]
    # A loop, not 30 unrolled copies of the step and its derivative: with the unrolled copies
    # stability_map took ~18 s to trace and compile, with the loop ~7 s.
    newton_step = lambda dd: g(dd) / jax.grad(g)(dd)
    d = jax.lax.fori_loop(0, iters, lambda _, dd: dd - newton_step(dd), d)
    x = jnp.stack([d, theta])
    delta = K[0] * d + K[1] * theta
    eps = jnp.finfo(d.dtype).eps
    converged = jnp.abs(newton_step(d)) <= 64 * eps * (jnp.abs(d) + jnp.abs(params.L))
    boundary = jnp.maximum(1e-9, 1000 * eps)  # rad: the steering at its limit counts as existing
    exists = converged & (jnp.abs(delta) <= params.delta_max + boundary) & jnp.isfinite(d)
    inside = jnp.abs(delta) < params.delta_max - boundary  # off the boundary: the steering has room
    eig = jacobian_eigenvalues(x, K, beta_r, beta_f, kappa, params)
    return Equilibrium(d, theta, delta, exists, eig, exists & inside & jnp.all(eig.real < 0))


@jax.jit
def source_linearisation(K: Array, beta_r, beta_f, params: SlipParams) -> Array:
    """Eigenvalues the source plots (appendix B, Figs. 4-5): Jacobian at ``[0, -beta_r]`` on a line."""
    x = jnp.stack([jnp.zeros_like(jnp.asarray(beta_r, float)), -jnp.asarray(beta_r, float)])
    return jacobian_eigenvalues(x, jnp.asarray(K, float), beta_r, beta_f, 0.0, params)


@jax.jit
def stability_map(K: Array, beta_r: Array, beta_f: Array, params: SlipParams) -> tuple[Equilibrium, Array]:
    """True equilibria and the source's eigenvalues over a grid ``beta_r[i] x beta_f[j]`` (rad), on a line.

    Returns:
        ``(Equilibrium with leaves of shape (n_r, n_f[, 2]), source eigenvalues (n_r, n_f, 2))``.
    """
    BR, BF = jnp.meshgrid(beta_r, beta_f, indexing="ij")
    eq = jax.vmap(jax.vmap(lambda br, bf: equilibrium(K, br, bf, params)))(BR, BF)
    src = jax.vmap(jax.vmap(lambda br, bf: source_linearisation(K, br, bf, params)))(BR, BF)
    return eq, src


def converged_to(status, d, theta_e, d_star, theta_e_star, *, tol_d: float, tol_theta_deg: float):
    """Whether runs ended at an equilibrium (NumPy, elementwise): status ``OK`` (0), ``|d - d*| <
    tol_d`` (m) and ``|theta_e - theta_e*| < tol_theta_deg`` (deg) at the end of the run, with
    ``d*``, ``theta_e*`` the equilibrium's (:func:`equilibrium`, :func:`stability_map`). The
    simulation cross-check of the paper reproduction's stability grid."""
    import math

    import numpy as np

    return (
        (np.asarray(status) == 0)
        & (np.abs(np.asarray(d) - np.asarray(d_star)) < tol_d)
        & (np.abs(np.asarray(theta_e) - np.asarray(theta_e_star)) < math.radians(tol_theta_deg))
    )


class PIQuasiEquilibrium(NamedTuple):
    """The PI loop's quasi-equilibrium under constant rear slip (:func:`pi_quasi_equilibrium`)."""

    d_q: float  # m, the standing lateral offset
    poles: Any  # (3,) NumPy complex, 1/s, eigenvalues of the loop linearised there (e, phi, sigma)


def pi_quasi_equilibrium(gains, beta_r: float, params: SlipParams) -> PIQuasiEquilibrium:
    """The quasi-equilibrium of the source's PI (:func:`pfjax.controllers.pi`, gains ``kp_d``,
    ``ki_d``, ``kp_theta``, ``ki_theta``) on a straight line under constant rear slip ``beta_r``
    (rad), in the source's convention, unsaturated, and the poles of the loop linearised there.

    With rear slip ``d' = 0`` needs ``theta_e = -beta_r``, so the integral on ``theta_e`` ramps at
    ``ki_theta beta_r`` for ever and the loop has no equilibrium; the steering stays at its
    straight-line value while the integral on ``d`` ramps the other way, which needs the standing
    offset ``d_q = ki_theta beta_r / ki_d`` (m). With ``a = v / cos beta_r``,
    ``b = v / (L cos^2 beta_r)``, ``e = d - d_q``, ``phi = theta_e + beta_r`` and ``sigma`` the sum
    of the two integral terms, the loop linearised there is::

        d/dt [e, phi, sigma] = [[0, a, 0], [-b kp_d, -b kp_theta, b], [-ki_d, -ki_theta, 0]] [e, phi, sigma - sigma_q]

    NumPy, not traced. Holds while the steering is not saturated; a reading whose linearised loop
    is not Hurwitz, or whose steering saturates, does not approach ``d_q``."""
    import math

    import numpy as np

    from pfjax.errors import InputError

    if int(np.asarray(params.convention)) != SOURCE:
        raise InputError(
            "params.convention: the quasi-equilibrium is derived in the source's convention", "params.convention"
        )
    v, L, br = float(params.v), float(params.L), float(beta_r)
    kp_d, ki_d, kp_t, ki_t = (float(_gain(gains, k)) for k in ("kp_d", "ki_d", "kp_theta", "ki_theta"))
    if ki_d == 0:
        raise InputError("gains.ki_d: the quasi-equilibrium needs an integral on d (ki_d != 0)", "gains.ki_d")
    a, b = v / math.cos(br), v / (L * math.cos(br) ** 2)
    jac = np.array([[0.0, a, 0.0], [-b * kp_d, -b * kp_t, b], [-ki_d, -ki_t, 0.0]])
    return PIQuasiEquilibrium(ki_t * br / ki_d, np.linalg.eigvals(jac))


def _gain(gains, name: str):
    return gains[name] if isinstance(gains, dict) else getattr(gains, name)
