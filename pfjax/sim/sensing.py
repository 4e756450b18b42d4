"""What the controllers see: the measured pose's closest point on the path (:func:`measure_pose`), the
:class:`~pfjax.controllers.base.Observation` built from it (:func:`observation`) and, with
:class:`SensorNoise`, the noisy measurement (:func:`noisy_observation`). Shared by the slip vehicle
(:mod:`pfjax.sim.simulate`) and the dynamic vehicle (:mod:`pfjax.sim.dynamic`)."""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import jax.numpy as jnp
from jax import Array

from pfjax.controllers.base import Observation
from pfjax.models.slip import Pose
from pfjax.numerics import elementary as E
from pfjax.numerics.random import step_normals
from pfjax.paths.geometry import Projection, closest_parameter, measure, wrap_angle


class SensorNoise(NamedTuple):
    """White Gaussian noise on the measured rear-axle pose: one pair of standard normals
    ``(n0, n1)`` per integrator step ``k`` from ``(key, k)``
    (:func:`pfjax.numerics.random.step_normals`; deterministic, O(1) memory).

    The sensor measures the pose; every controller sees the same noisy measurement. The measured
    pose is the true one displaced by ``e_d = sigma_d n0`` (m) along the path's left unit normal at
    the closest point and rotated by ``e_theta = sigma_theta_e n1`` (rad)::

        psi_p   = theta - theta_e                  (rad, path tangent angle at the closest point)
        x_m     = x - e_d sin(psi_p)               (m)
        y_m     = y + e_d cos(psi_p)               (m)
        theta_m = theta + e_theta                  (rad)

    so the measured errors are ``d_m = d + e_d`` (m) and ``theta_e,m = wrap(theta_e + e_theta)``
    (rad): the measured pose projects onto the same closest point (while ``|d + e_d|`` stays below
    the path's radius of curvature there), at signed distance ``d + e_d``, with heading error
    ``theta_e + e_theta``. Controllers on ``(d, theta_e)`` see noise of std
    ``sigma_d`` and ``sigma_theta_e`` on them; the geometric trackers (Stanley, pure pursuit) compute
    their commands from the measured pose, consistent with those errors (see :func:`noisy_observation`).
    The noise is white: independent between steps and between ``d`` and ``theta_e``. The metrics
    and the health checks use the true errors.

    Attributes:
        sigma_d: std of the lateral (path-normal) position error ``e_d``, m.
        sigma_theta_e: std of the heading error ``e_theta``, rad.
        key: ``uint32[2]``, a ``jax.random.PRNGKey``.
    """

    sigma_d: Array  # m
    sigma_theta_e: Array  # rad
    key: Array  # uint32[2], a jax.random.PRNGKey


def observation(proj: Projection, pose: Pose, v, L, delta_max, path) -> Observation:
    """What the controllers see of a measured pose: its closest point ``proj``, the rear-axle
    ``pose`` (m, m, rad), the speed ``v`` (m/s), wheelbase ``L`` (m) and steering limit ``delta_max``
    (rad) they may use, and the ``path`` (for trackers that look ahead)."""
    return Observation(
        d=proj.d,
        theta_e=proj.theta_e,
        kappa=proj.kappa,
        s=proj.s,
        u=proj.u,
        pose=pose,
        v=jnp.asarray(v, float),
        L=jnp.asarray(L, float),
        delta_max=jnp.asarray(delta_max, float),
        path=path,
    )


def noisy_observation(obs: Observation, noise: SensorNoise | None, k) -> Observation:
    """The observation the controllers see at step ``k``: the exact one (``noise is None``), or the
    one measured from the noisy pose (:class:`SensorNoise`'s equations), with
    ``(n0, n1) = step_normals(noise.key, k, 2)``: ``d_m = d + e_d``, ``theta_e,m = wrap(theta_e + e_theta)``
    and the pose displaced by ``e_d`` (m) along the path's left normal and rotated by ``e_theta``
    (rad). ``kappa``, ``s`` and ``u`` (the closest point's) are unchanged: the measured pose
    projects onto the same point (locally); ``u`` is only the trackers' warm start.

    ``k`` is the integrator step (the noise's counter; in continuous mode every RK4 stage of step
    ``k`` sees the same draw). Returns ``obs`` itself when ``noise is None`` (no operations).
    """
    if noise is None:
        return obs
    n = step_normals(noise.key, k, 2, obs.d.dtype)
    e_d, e_theta = noise.sigma_d * n[0], noise.sigma_theta_e * n[1]
    pose = obs.pose
    sin_p, cos_p = E.sincos(pose.theta - obs.theta_e)  # the path tangent at the closest point
    measured = Pose(pose.x - e_d * sin_p, pose.y + e_d * cos_p, pose.theta + e_theta)
    return obs._replace(d=obs.d + e_d, theta_e=wrap_angle(obs.theta_e + e_theta), pose=measured)


def measure_pose(sc: WithPath, pose: Pose, u_guess, iters) -> Projection:
    """The rear-axle ``pose``'s closest point on ``sc.path`` (any scenario with a ``path``): ``iters``
    warm-started Newton steps from ``u_guess``, then the errors ``d``, ``theta_e`` and the path's
    ``kappa``, ``s`` there (:func:`pfjax.paths.geometry.measure`)."""
    # the closest point and (below) the command and the applied steering are read by many of the
    # step's kernels, and their cotangents by many of the backward step's: each is computed once
    # (E.computed_once; measured: reverse mode about 30 % cheaper, forward mode about 13 % dearer,
    # the forward pass 1-2.5 % slower). So is the heading error (an atan2 read by the controller and
    # by the steady-state metric: the forward pass about 2 % faster, and both read the same rounding)
    u = E.computed_once(closest_parameter(sc.path, pose.x, pose.y, u_guess, iters))
    proj = measure(sc.path, pose.x, pose.y, pose.theta, u)
    return proj._replace(theta_e=E.computed_once(proj.theta_e))


class WithPath(Protocol):
    """Any scenario with a ``path`` (the slip vehicle's :class:`Scenario`, the dynamic vehicle's)."""

    @property
    def path(self) -> Any: ...
