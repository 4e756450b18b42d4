"""The simulator: one ``lax.scan`` over integrator steps of the world-frame slip model.

Per step ``k`` (time ``t_k = k dt``):

1. measure the pose against the path (closest point, warm-started Newton, spec §2) and, with
   :class:`SensorNoise`, give the controller the noisy measurement (:func:`_noisy`);
2. sampled controllers: every ``control_every`` steps compute a new command and hold it
   (zero-order hold); continuous controllers: evaluated inside every RK4 stage instead;
3. saturate the steering at ``+-delta_max``;
4. check the run's health (:mod:`pfjax.sim.status`) and accumulate the metrics;
5. advance the pose (and a continuous controller's state) by one RK4 step, slip evaluated at
   the stage times.

:func:`simulate` is one run (write single-run code); :func:`simulate_batch` is the jitted,
vmapped entry point. ``SimConfig`` fixes the shapes and is a static argument.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax import errors, resources
from pfjax.controllers.base import Controller, Observation, step
from pfjax.errors import InputError
from pfjax.metrics import running
from pfjax.models.slip import Pose, SlipParams, world_rhs
from pfjax.numerics import compiler
from pfjax.numerics import elementary as E
from pfjax.numerics.layout import as_scalars
from pfjax.numerics.random import step_normals
from pfjax.paths.geometry import NEWTON_START, Projection, closest_parameter, global_parameter, measure, polish_parameter, wrap_angle
from pfjax.sim import sharding
from pfjax.sim.integrators import rk4_step
from pfjax.sim.slip_profiles import SlipProfile, slip_at
from pfjax.sim.status import Status, classify, first_failure


#: Newton steps that polish a scenario's given start parameter ``u0`` before sample 0.
U0_ITERS = 8

#: What reverse mode saves per step besides the carry (see the ``lax.scan`` in :func:`simulate`).
_SAVED = jax.checkpoint_policies.save_only_these_names(NEWTON_START)


@dataclass(frozen=True)
class SimConfig:
    """Static settings (they fix array shapes; hashable so they can be jit-static).

    Attributes:
        dt: integrator step, s (default 5 ms).
        horizon: simulated time, s (spec §6 *assumed* 20 s).
        control_every: controller sampling period in integrator steps (zero-order hold);
            ``None`` evaluates the controller continuously inside every RK4 stage.
        newton_iters: Newton steps of the warm-started projection per measurement.
        record: ``True`` returns full trajectories (memory O(horizon) per run);
            ``False`` only the running metrics (memory independent of the horizon).
        d_fail: |d| above which a run is flagged ``DIVERGED``, m.
        settle_band: band on |d| for the settling time, m.
        steady_window: final part of the run for the steady-state errors, s.
        success_band: a run succeeds if it does not fail and |d| <= this from ``success_from`` on, m.
        success_from: start of the success window, s (``None``: the steady window's start).
    """

    dt: float = 0.005
    horizon: float = 20.0
    control_every: int | None = 1
    newton_iters: int = 3
    record: bool = True
    d_fail: float = 10.0
    settle_band: float = 0.05
    steady_window: float = 5.0
    success_band: float = 0.05
    success_from: float | None = None

    def __post_init__(self):
        """Checks every setting (:class:`~pfjax.errors.InputError` naming it)."""
        errors.number("dt", self.dt, positive=True, unit=" s")
        errors.number("horizon", self.horizon, positive=True, unit=" s")
        if not self.horizon >= self.dt:
            raise InputError(f"horizon: must be >= dt ({self.dt:g} s), got {self.horizon:g}")
        resources.check_steps(self.horizon, self.dt)
        if self.control_every is not None:
            errors.integer("control_every", self.control_every, low=1, high=resources.MAX_STEPS)
        errors.integer("newton_iters", self.newton_iters, low=1, high=100)
        for name in ("d_fail", "settle_band", "steady_window", "success_band"):
            errors.number(name, getattr(self, name), positive=True)
        if self.success_from is not None:
            errors.number("success_from", self.success_from, nonnegative=True, unit=" s")

    @property
    def n_steps(self) -> int:
        return int(round(self.horizon / self.dt))

    @property
    def success_start(self) -> float:
        return self.n_steps * self.dt - self.steady_window if self.success_from is None else self.success_from


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
    their commands from the measured pose, consistent with those errors (see :func:`_noisy`).
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


class Scenario(NamedTuple):
    """Everything that varies between runs (a pytree; batch it along a leading axis)."""

    pose0: Pose  # initial rear-axle pose (m, m, rad)
    slip: SlipProfile  # slip angles over time
    params: SlipParams  # v, L, delta_max, convention
    path: Any  # a path shape from pfjax.paths
    gains: Any  # the controller's parameter pytree
    noise: SensorNoise | None = None  # measurement noise seen by the controller (None: exact)
    u0: Any = None  # path parameter near the start's closest point (None: global search). Set it when
    #                 the start is built from the path, so a path that loops back cannot capture the start.


class Trajectory(NamedTuple):
    """Samples at ``t_k = k dt``, ``k = 0..N`` (shape ``(N+1,)`` per run)."""

    t: Array  # s
    x: Array  # m
    y: Array  # m
    theta: Array  # rad
    d: Array  # m
    theta_e: Array  # rad
    kappa: Array  # 1/m
    s: Array  # m
    delta_cmd: Array  # rad, controller command (before saturation)
    delta: Array  # rad, applied steering
    beta_r: Array  # rad
    beta_f: Array  # rad


class Final(NamedTuple):
    """State at the end of the horizon (or at the failure)."""

    x: Array  # m
    y: Array  # m
    theta: Array  # rad
    d: Array  # m
    theta_e: Array  # rad
    delta: Array  # rad, applied steering
    s: Array  # m


class SimResult(NamedTuple):
    metrics: running.Metrics
    status: Array  # int32, a pfjax.sim.status.Status
    fail_time: Array  # s, time of the first failure (NaN if none)
    final: Final
    trajectory: Trajectory | None


def _observation(proj: Projection, pose: Pose, sc: Scenario) -> Observation:
    p = sc.params
    return Observation(
        d=proj.d, theta_e=proj.theta_e, kappa=proj.kappa, s=proj.s, u=proj.u, pose=pose,
        v=jnp.asarray(p.v, float), L=jnp.asarray(p.L, float), delta_max=jnp.asarray(p.delta_max, float),
        path=sc.path,
    )


def _noisy(obs: Observation, noise: SensorNoise | None, k) -> Observation:
    """The observation the controllers see at step ``k``: the exact one (``noise is None``), or the
    one measured from the noisy pose of :class:`SensorNoise`.

    With ``(n0, n1) = step_normals(noise.key, k, 2)``, ``e_d = sigma_d n0`` (m) and
    ``e_theta = sigma_theta_e n1`` (rad), the measured observation is::

        d_m       = d + e_d                                   (m)
        theta_e,m = wrap(theta_e + e_theta)                   (rad)
        pose_m    = (x - e_d sin(psi_p), y + e_d cos(psi_p), theta + e_theta),
                    psi_p = theta - theta_e                   (m, m, rad)

    ``psi_p`` is the path tangent angle at the closest point (modulo 2 pi), so the pose is displaced
    along the path's left unit normal ``(-sin psi_p, cos psi_p)`` there: the measured pose's closest
    point is the same point ``p(u)`` (locally: ``|d + e_d| kappa < 1``), its signed distance is
    ``d + e_d`` and its heading error ``theta_e + e_theta``. ``kappa``, ``s`` and ``u`` (the closest point's) are therefore unchanged;
    ``u`` is only the trackers' warm start for their own projections of the measured pose.

    Args:
        obs: the exact observation at step ``k`` (true pose, true errors).
        noise: the run's sensor noise, or ``None``.
        k: integrator step index (the noise's counter; in continuous mode every RK4 stage of step
            ``k`` sees the same draw).

    Returns:
        The observation the controllers read; ``obs`` itself when ``noise is None`` (no operations).
    """
    if noise is None:
        return obs
    n = step_normals(noise.key, k, 2, obs.d.dtype)
    e_d, e_theta = noise.sigma_d * n[0], noise.sigma_theta_e * n[1]
    pose = obs.pose
    sin_p, cos_p = E.sincos(pose.theta - obs.theta_e)  # the path tangent at the closest point
    measured = Pose(pose.x - e_d * sin_p, pose.y + e_d * cos_p, pose.theta + e_theta)
    return obs._replace(d=obs.d + e_d, theta_e=wrap_angle(obs.theta_e + e_theta), pose=measured)


def _measure(sc: Scenario, pose: Pose, u_guess, iters) -> Projection:
    # the closest point and (below) the command and the applied steering are read by many of the
    # step's kernels, and their cotangents by many of the backward step's: each is computed once
    # (E.computed_once; measured: reverse mode about 30 % cheaper, forward mode about 13 % dearer,
    # the forward pass 1-2.5 % slower). So is the heading error (an atan2 read by the controller and
    # by the steady-state metric: the forward pass about 2 % faster, and both read the same rounding)
    u = E.computed_once(closest_parameter(sc.path, pose.x, pose.y, u_guess, iters))
    proj = measure(sc.path, pose.x, pose.y, pose.theta, u)
    return proj._replace(theta_e=E.computed_once(proj.theta_e))


def simulate(controller: Controller, sc: Scenario, config: SimConfig) -> SimResult:
    """Simulate one run (pure, unbatched; see :func:`simulate_batch` for the entry point).

    Args:
        controller: the controller (static).
        sc: the run's scenario.
        config: static settings.

    Returns:
        ``SimResult`` with metrics, status, failure time, final state and (if
        ``config.record``) the trajectory.
    """
    controller.check_params(sc.gains)  # at trace time: a PI given state-feedback gains is bad input
    dt, n_steps, iters = config.dt, config.n_steps, config.newton_iters
    horizon = n_steps * dt
    continuous = config.control_every is None
    every = 1 if continuous else int(config.control_every)
    pose0 = Pose(*(jnp.asarray(a, float) for a in sc.pose0))
    if sc.u0 is None:
        u0 = global_parameter(sc.path, pose0.x, pose0.y)
    else:  # polish the given start parameter (a rolled loop: one Newton step in the program, not eight)
        u0 = polish_parameter(sc.path, pose0.x, pose0.y, jnp.asarray(sc.u0, pose0.x.dtype), U0_ITERS)
    c0 = controller.init(sc.gains)
    t_end = jnp.asarray(horizon, pose0.x.dtype)

    def make_body(sc: Scenario):
        """The loop body, reading the run's inputs from ``sc`` (rebuilt inside the loop: see
        :mod:`pfjax.numerics.layout`)."""
        gains, params = sc.gains, sc.params
        dmax = jnp.asarray(params.delta_max, float)
        rate = jnp.asarray(params.delta_rate_max, float)
        rate_limited = jnp.isfinite(rate)

        def closed_loop_rhs(u_guess, k):
            """Vector field of (pose, controller state) with the controller inside (continuous mode)."""

            def f(t, y):
                pose, c = y
                obs = _noisy(_observation(_measure(sc, pose, u_guess, iters), pose, sc), sc.noise, k)
                cmd = E.computed_once(controller.output(gains, c, obs))
                delta = jnp.clip(cmd, -dmax, dmax)
                br, bf = slip_at(sc.slip, t)
                return world_rhs(pose, delta, br, bf, params), controller.rate(gains, c, obs, cmd, delta)

            return f

        def health(pose, proj):
            finite = jnp.isfinite(pose.x) & jnp.isfinite(pose.y) & jnp.isfinite(pose.theta) & jnp.isfinite(proj.d)
            return classify(finite, jnp.abs(proj.d), 1.0 - proj.kappa * proj.d, proj.at_end, config.d_fail)

        def record_of(t, pose, proj, cmd, delta):
            br, bf = slip_at(sc.slip, t)
            return Trajectory(t, pose.x, pose.y, pose.theta, proj.d, proj.theta_e, proj.kappa, proj.s, cmd, delta, br, bf)

        def body(carry, k):
            """Sample ``k`` (``t_k = k dt``, ``k = 0..N``): measure, command, health, metrics; then, for
            ``k < N``, one RK4 step. Sample ``N`` only measures (the trapezoid's end point), with the
            command held from step ``N - 1`` (sampled controllers) or evaluated there (continuous)."""
            pose, c, u, _, cmd, delta_prev, (acc, status, fail_time) = carry
            first, last = k == 0, k == n_steps
            t = jnp.where(last, t_end, k * dt)
            proj = _measure(sc, pose, u, iters)
            obs = _noisy(_observation(proj, pose, sc), sc.noise, k)
            if continuous:
                cmd = E.computed_once(controller.output(gains, c, obs))
            else:
                if every == 1:  # every step: no conditional (it would split XLA's fused loop body)
                    new_cmd, new_c = step(controller, gains, c, obs, dt)
                else:
                    new_cmd, new_c = jax.lax.cond(
                        k % every == 0,
                        lambda: step(controller, gains, c, obs, every * dt),
                        lambda: (cmd, c),
                    )
                cmd, c_next = jnp.where(last, cmd, E.computed_once(new_cmd)), new_c
            delta = jnp.clip(cmd, -dmax, dmax)
            if not continuous:  # steering rate limit (exactly a no-op when rate = inf); held at sample N
                limited = delta_prev + jnp.clip(delta - delta_prev, -rate * dt, rate * dt)
                delta = E.computed_once(jnp.where(last, delta_prev, jnp.where(rate_limited, limited, delta)))
            # health check and metrics (trapezoid weight 1/2 at both ends)
            status, fail_time = first_failure(status, fail_time, health(pose, proj), t)  # status: a float code
            live = status == Status.OK
            acc = acc._replace(d0_sign=jnp.where(first, jnp.sign(proj.d), acc.d0_sign),
                               prev_delta=jnp.where(first, delta, acc.prev_delta))
            acc = running.update(
                acc, t, dt, jnp.where(live, jnp.where(first | last, 0.5, 1.0), 0.0), jnp.where(live, proj.d, 0.0),
                jnp.where(live, proj.theta_e, 0.0), delta, (jnp.abs(cmd) > dmax).astype(float),
                band=config.settle_band, steady_from=horizon - config.steady_window,
                success_from=config.success_start,
            )
            if continuous:
                new_pose, c_next = rk4_step(closed_loop_rhs(proj.u, k), t, (pose, c), dt)
            else:
                rhs = lambda tt, ps: world_rhs(ps, delta, *slip_at(sc.slip, tt), params)
                new_pose = rk4_step(rhs, t, pose, dt)
            advance = live & ~last
            keep = lambda new, old: jax.tree_util.tree_map(lambda a, b: jnp.where(advance, a, b), new, old)
            out = record_of(t, pose, proj, cmd, delta) if config.record else None
            # u: warm start of the next projection (frozen after a failure); proj.u: the final state's
            return (keep(new_pose, pose), keep(c_next, c), jnp.where(live, proj.u, u), proj.u, cmd, delta,
                    (acc, status, fail_time)), out

        return body

    dtype = pose0.x.dtype
    zero = jnp.zeros((), dtype)
    # d0_sign and prev_delta are set by sample 0
    acc0 = running.init(zero, zero)
    init = (pose0, c0, u0, u0, zero, zero, (acc0, zero + Status.OK, jnp.asarray(jnp.nan, dtype)))
    # One loop for samples 0..N: no separate first and last sample (a third less compile time).
    # Reverse mode stores only the carry per step and recomputes the step (jax.checkpoint): the
    # residuals of a whole step would cost far more memory traffic than recomputing it. It also
    # stores the projection's last-but-one Newton iterate (one value per run and step), so the
    # backward step recomputes only the differentiated last Newton step: measured 5 % less CPU time
    # for the benchmark's reverse-mode gradient (with the values computed once; no gain before).
    # The run's small inputs enter the loop as scalars, so reverse mode accumulates their cotangents
    # as (runs,) arrays (pfjax.numerics.layout).
    parts, join = as_scalars(sc)
    body = lambda carry, k: make_body(join(parts))(carry, k)
    (pose, c, _, u_last, cmd, delta, (acc, status, fail_time)), traj = jax.lax.scan(
        jax.checkpoint(body, prevent_cse=False, policy=_SAVED), init, jnp.arange(n_steps + 1))

    metrics = running.finalize(acc, horizon, status != Status.OK, config.success_band)
    proj = measure(sc.path, pose.x, pose.y, pose.theta, u_last)  # sample N's projection
    final = Final(pose.x, pose.y, pose.theta, proj.d, proj.theta_e, delta, proj.s)
    return SimResult(metrics, status.astype(jnp.int32), fail_time, final, traj)


@compiler.jit(static_argnames=("controller", "config", "layout"))
def _simulate_vmapped(scenarios: Scenario, *, controller: Controller, config: SimConfig,
                      layout: sharding.Layout = sharding.Layout(None, 1)) -> SimResult:
    return sharding.map_runs(lambda sc: simulate(controller, sc, config), scenarios, layout)


def simulate_batch(scenarios: Scenario, *, controller: Controller, config: SimConfig, devices=None,
                   block: int | None | str = "auto") -> SimResult:
    """Jitted, vmapped :func:`simulate` over a batch of scenarios (leading axis of every leaf),
    sharded over ``devices`` (default: every device JAX sees) and, on CPU, evaluated in cache-sized
    blocks of runs (``block``: runs per block, ``"auto"`` or ``None`` for one block;
    :mod:`pfjax.sim.sharding`).

    Compiled once per controller, ``config``, batch shape, device set and block count. Under
    ``jit``/``grad`` the batch is not re-sharded or blocked (the outer call decides). Results are
    the same, run for run, whatever the number of devices and blocks, up to rounding (XLA compiles
    each block shape into its own vector code: at most an ulp or two in a metric, measured).
    """
    controller.check_params(scenarios.gains)  # here, not at trace time: JAX would add to the message
    if config.record and not errors.is_traced(scenarios):
        n_runs = int(np.shape(jax.tree_util.tree_leaves(scenarios)[0])[0])
        resources.check_memory("record", n_runs * resources.run_bytes(config.n_steps, record=True),
                               f"recording {n_runs} runs of {config.n_steps + 1} samples",
                               "simulate with record=False (the metrics need no trajectory), or fewer runs")
    placed, n, layout = sharding.plan_batch(scenarios, devices, block)
    return sharding.unpad(_simulate_vmapped(placed, controller=controller, config=config, layout=layout), n)


simulate_batch._cache_size = _simulate_vmapped._cache_size  # the jitted core's compilation count


def stack(items):
    """Stack a list of pytrees with identical structure along a new leading axis: NumPy arrays, one
    per leaf, built on the host (``simulate_batch`` places them on the devices).

    In NumPy because JAX would compile one small program per leaf shape and item count
    (``jnp.stack``): 13 compilations in the paper reproduction, 4.6 s by JAX's compile log."""
    items = list(items)
    first = jax.tree_util.tree_structure(items[0])
    for i, item in enumerate(items[1:], 1):
        if jax.tree_util.tree_structure(item) != first:
            raise ValueError(f"stack: item {i} has a different structure from item 0 (e.g. a slip profile with other "
                             f"terms present: give every run the same terms, zeros where unused)")
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *items)


def unstack(tree, i: int):
    """Run ``i`` of a batched pytree (arrays stay on their device; NumPy leaves stay NumPy).

    One jitted gather for the whole tree: indexing each leaf from Python would dispatch (and
    compile) one program per leaf shape, seconds for a batch with trajectories."""
    leaves = jax.tree_util.tree_leaves(tree)
    if all(isinstance(a, np.ndarray) for a in leaves):
        return jax.tree_util.tree_map(lambda a: a[i], tree)
    if isinstance(i, (int, np.integer)) and leaves and not -leaves[0].shape[0] <= i < leaves[0].shape[0]:
        raise IndexError(f"unstack: run {i} is out of range for a batch of {leaves[0].shape[0]}")
    return _take(tree, i)


@jax.jit
def _take(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)
