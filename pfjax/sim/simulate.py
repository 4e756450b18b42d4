"""The slip vehicle: the world-frame slip model on the simulation loop (:mod:`pfjax.sim.loop`).

Per sample ``k`` (time ``t_k = k dt``, ``k = 0..N``), :func:`_step`:

1. measure the pose against the path (closest point, warm-started Newton, docs/reproductions/path-following.md §2) and, with
   :class:`SensorNoise`, give the controller the noisy measurement (:func:`_noisy`);
2. sampled controllers: every ``control_every`` steps compute a new command and hold it
   (zero-order hold); continuous controllers: evaluated inside every RK4 stage instead;
3. saturate the steering at ``+-delta_max``; check the run's health (:mod:`pfjax.sim.status`);
4. propose one RK4 step of the pose (and a continuous controller's state), slip evaluated at the
   stage times; the loop accumulates the metrics (:func:`_update`) and freezes a failed run.

:func:`simulate` is one run (write single-run code); :func:`simulate_batch` is the jitted,
vmapped entry point. ``SimConfig`` fixes the shapes and is a static argument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
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
from pfjax.numerics.random import step_normals
from pfjax.paths.geometry import (
    NEWTON_START,
    Projection,
    closest_parameter,
    global_parameter,
    measure,
    polish_parameter,
    wrap_angle,
)
from pfjax.sim import loop, sharding
from pfjax.sim.integrators import rk4_step
from pfjax.sim.loop import stack, unstack  # noqa: F401  (re-exported: a batch of runs, run i of a batch)
from pfjax.sim.slip_profiles import SlipProfile, slip_at
from pfjax.sim.status import classify

#: Newton steps that polish a scenario's given start parameter ``u0`` before sample 0.
U0_ITERS = 8

#: What reverse mode saves per step besides the carry: the projection's last-but-one Newton iterate,
#: so the backward step recomputes only the differentiated last Newton step (measured: 5 % less CPU
#: time for the benchmark's gradient); a whole step's residuals would cost far more memory traffic.
_SAVED = jax.checkpoint_policies.save_only_these_names(NEWTON_START)


@dataclass(frozen=True)
class SimConfig:
    """Static settings (they fix array shapes; hashable so they can be jit-static).

    Attributes:
        dt: integrator step, s (default 5 ms).
        horizon: simulated time, s (docs/reproductions/path-following.md §6: *assumed* 20 s).
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
        d=proj.d,
        theta_e=proj.theta_e,
        kappa=proj.kappa,
        s=proj.s,
        u=proj.u,
        pose=pose,
        v=jnp.asarray(p.v, float),
        L=jnp.asarray(p.L, float),
        delta_max=jnp.asarray(p.delta_max, float),
        path=sc.path,
    )


def _noisy(obs: Observation, noise: SensorNoise | None, k) -> Observation:
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


def _measure(sc: Scenario, pose: Pose, u_guess, iters) -> Projection:
    # the closest point and (below) the command and the applied steering are read by many of the
    # step's kernels, and their cotangents by many of the backward step's: each is computed once
    # (E.computed_once; measured: reverse mode about 30 % cheaper, forward mode about 13 % dearer,
    # the forward pass 1-2.5 % slower). So is the heading error (an atan2 read by the controller and
    # by the steady-state metric: the forward pass about 2 % faster, and both read the same rounding)
    u = E.computed_once(closest_parameter(sc.path, pose.x, pose.y, u_guess, iters))
    proj = measure(sc.path, pose.x, pose.y, pose.theta, u)
    return proj._replace(theta_e=E.computed_once(proj.theta_e))


class _State(NamedTuple):
    """What the loop freezes at a failure."""

    pose: Pose  # rear-axle pose (m, m, rad)
    c: Any  # controller state
    u: Array  # path parameter, warm start of the next projection


class _Held(NamedTuple):
    """Carried on whatever the status (the loop's ``aux``)."""

    u_last: Array  # path parameter of the last sample's closest point (the final state's projection)
    cmd: Array  # rad, the (held) command
    delta: Array  # rad, the applied steering (the rate limit's previous value)


class _Out(NamedTuple):
    """Sample ``k`` as the metrics and the record read it."""

    t: Array  # s
    first: Array  # bool, k == 0
    last: Array  # bool, k == N
    pose: Pose  # (m, m, rad)
    proj: Projection  # the pose's closest point
    cmd: Array  # rad, controller command (before saturation)
    delta: Array  # rad, applied steering
    saturated: Array  # 1.0 where |cmd| > delta_max, else 0.0


def _start(controller: Controller, sc: Scenario) -> loop.Start:
    """The pose, its path parameter (polished ``u0`` or a global search) and the controller's state;
    the command, the steering and the metrics' ``d0_sign`` and ``prev_delta`` are set by sample 0."""
    pose0 = Pose(*(jnp.asarray(a, float) for a in sc.pose0))
    if sc.u0 is None:
        u0 = global_parameter(sc.path, pose0.x, pose0.y)
    else:  # polish the given start parameter (a rolled loop: one Newton step in the program, not eight)
        u0 = polish_parameter(sc.path, pose0.x, pose0.y, jnp.asarray(sc.u0, pose0.x.dtype), U0_ITERS)
    zero = jnp.zeros((), pose0.x.dtype)
    return loop.Start(
        _State(pose0, controller.init(sc.gains), u0), running.init(zero, zero), zero, _Held(u0, zero, zero)
    )


def _closed_loop_rhs(controller: Controller, sc: Scenario, u_guess, k, iters):
    """Vector field of (pose, controller state) with the controller inside (continuous mode)."""
    dmax = jnp.asarray(sc.params.delta_max, float)

    def f(t, y):
        pose, c = y
        obs = _noisy(_observation(_measure(sc, pose, u_guess, iters), pose, sc), sc.noise, k)
        cmd = E.computed_once(controller.output(sc.gains, c, obs))
        delta = jnp.clip(cmd, -dmax, dmax)
        br, bf = slip_at(sc.slip, t)
        return world_rhs(pose, delta, br, bf, sc.params), controller.rate(sc.gains, c, obs, cmd, delta)

    return f


def _sampled_command(controller: Controller, config: SimConfig, sc: Scenario, c, obs, held: _Held, k, last):
    """Sampled controller: ``(cmd, c_next, delta)`` at sample ``k``: a new command every
    ``control_every`` steps, held in between (zero-order hold) and at sample ``N``; saturated at
    ``+-delta_max`` and rate limited, ``|delta_k - delta_{k-1}| <= delta_rate_max dt``."""
    dt, every = config.dt, int(config.control_every)
    if every == 1:  # every step: no conditional (it would split XLA's fused loop body)
        new_cmd, c_next = step(controller, sc.gains, c, obs, dt)
    else:
        new_cmd, c_next = jax.lax.cond(
            k % every == 0, lambda: step(controller, sc.gains, c, obs, every * dt), lambda: (held.cmd, c)
        )
    cmd = jnp.where(last, held.cmd, E.computed_once(new_cmd))
    dmax = jnp.asarray(sc.params.delta_max, float)
    rate = jnp.asarray(sc.params.delta_rate_max, float)
    delta, prev = jnp.clip(cmd, -dmax, dmax), held.delta
    # steering rate limit (exactly a no-op when rate = inf); held at sample N
    limited = prev + jnp.clip(delta - prev, -rate * dt, rate * dt)
    delta = E.computed_once(jnp.where(last, prev, jnp.where(jnp.isfinite(rate), limited, delta)))
    return cmd, c_next, delta


def _step(controller: Controller, config: SimConfig, sc: Scenario, carry: loop.LoopCarry, k) -> loop.Sample:
    """Sample ``k`` (``t_k = k dt``, ``k = 0..N``): measure, command, health; the proposed RK4 step
    to ``t_{k+1}``. Sample ``N`` only measures (the trapezoid's end point; ``keep``), with the command
    held from step ``N - 1`` (sampled controllers) or evaluated there (continuous)."""
    pose, c, u = carry.state
    dt, n_steps, iters = config.dt, config.n_steps, config.newton_iters
    dmax = jnp.asarray(sc.params.delta_max, float)
    first, last = k == 0, k == n_steps
    t = jnp.where(last, jnp.asarray(n_steps * dt, pose.x.dtype), k * dt)
    proj = _measure(sc, pose, u, iters)
    obs = _noisy(_observation(proj, pose, sc), sc.noise, k)
    if config.control_every is None:
        cmd = E.computed_once(controller.output(sc.gains, c, obs))
        delta = jnp.clip(cmd, -dmax, dmax)
        new_pose, c_next = rk4_step(_closed_loop_rhs(controller, sc, proj.u, k, iters), t, (pose, c), dt)
    else:
        cmd, c_next, delta = _sampled_command(controller, config, sc, c, obs, carry.aux, k, last)
        rhs = lambda tt, ps: world_rhs(ps, delta, *slip_at(sc.slip, tt), sc.params)
        new_pose = rk4_step(rhs, t, pose, dt)
    finite = jnp.isfinite(pose.x) & jnp.isfinite(pose.y) & jnp.isfinite(pose.theta) & jnp.isfinite(proj.d)
    health = classify(finite, jnp.abs(proj.d), 1.0 - proj.kappa * proj.d, proj.at_end, config.d_fail)
    out = _Out(t, first, last, pose, proj, cmd, delta, (jnp.abs(cmd) > dmax).astype(float))
    # u: warm start of the next projection (frozen after a failure); proj.u: the final state's
    return loop.Sample(_State(new_pose, c_next, proj.u), health, t, out, _Held(proj.u, cmd, delta), keep=last)


def _update(config: SimConfig, sc: Scenario, acc: running.Accumulator, s: loop.Sample, live, was_live):
    """Accumulate sample ``k``'s metrics (trapezoid weight 1/2 at both ends, 0 after a failure)."""
    o = s.out
    acc = acc._replace(
        d0_sign=jnp.where(o.first, jnp.sign(o.proj.d), acc.d0_sign),
        prev_delta=jnp.where(o.first, o.delta, acc.prev_delta),
    )
    return running.update(
        acc,
        o.t,
        config.dt,
        jnp.where(live, jnp.where(o.first | o.last, 0.5, 1.0), 0.0),
        jnp.where(live, o.proj.d, 0.0),
        jnp.where(live, o.proj.theta_e, 0.0),
        o.delta,
        o.saturated,
        band=config.settle_band,
        steady_from=config.n_steps * config.dt - config.steady_window,
        success_from=config.success_start,
    )


def _record(sc: Scenario, s: loop.Sample, state: _State) -> Trajectory:
    o = s.out
    br, bf = slip_at(sc.slip, o.t)
    return Trajectory(
        o.t, o.pose.x, o.pose.y, o.pose.theta, o.proj.d, o.proj.theta_e, o.proj.kappa, o.proj.s, o.cmd, o.delta, br, bf
    )


def _finish(config: SimConfig, sc: Scenario, r: loop.Run) -> SimResult:
    metrics = running.finalize(r.metrics, config.n_steps * config.dt, r.failed, config.success_band)
    pose = r.state.pose
    proj = measure(sc.path, pose.x, pose.y, pose.theta, r.aux.u_last)  # sample N's projection
    final = Final(pose.x, pose.y, pose.theta, proj.d, proj.theta_e, r.aux.delta, proj.s)
    return SimResult(metrics, r.status, r.fail_time, final, r.records)


def system(controller: Controller, config: SimConfig) -> loop.System:
    """The slip vehicle as a :class:`pfjax.sim.loop.System` (inputs: a :class:`Scenario`)."""
    return loop.System(
        init=partial(_start, controller),
        step=partial(_step, controller, config),
        update=partial(_update, config),
        record=_record,
        finish=partial(_finish, config),
        no_failure=math.nan,
    )


def simulate(controller: Controller, sc: Scenario, config: SimConfig) -> SimResult:
    """Simulate one run (pure, unbatched; see :func:`simulate_batch` for the entry point): samples
    ``k = 0..N`` of :func:`system` through :func:`pfjax.sim.loop.run`.

    One loop for samples 0..N (no separate first and last sample: a third less compile time); reverse
    mode stores the carry and ``_SAVED`` per step and recomputes the step; the small inputs enter the
    loop as scalars (:mod:`pfjax.numerics.layout`).

    Args:
        controller: the controller (static).
        sc: the run's scenario.
        config: static settings.

    Returns:
        ``SimResult``: metrics, status, failure time, final state, trajectory (if ``config.record``).
    """
    controller.check_params(sc.gains)  # at trace time: a PI given state-feedback gains is bad input
    return loop.run(
        system(controller, config),
        sc,
        config.n_steps + 1,
        record=config.record,
        scalar_inputs=True,
        checkpoint_policy=_SAVED,
    )


@compiler.jit(static_argnames=("controller", "config", "layout"))
def _simulate_vmapped(
    scenarios: Scenario,
    *,
    controller: Controller,
    config: SimConfig,
    layout: sharding.Layout = sharding.Layout(None, 1),
) -> SimResult:
    return sharding.map_runs(lambda sc: simulate(controller, sc, config), scenarios, layout)


def simulate_batch(
    scenarios: Scenario, *, controller: Controller, config: SimConfig, devices=None, block: int | str | None = "auto"
) -> SimResult:
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
        resources.check_memory(
            "record",
            n_runs * resources.run_bytes(config.n_steps, record=True),
            f"recording {n_runs} runs of {config.n_steps + 1} samples",
            "simulate with record=False (the metrics need no trajectory), or fewer runs",
        )
    placed, n, layout = sharding.plan_batch(scenarios, devices, block)
    return sharding.unpad(_simulate_vmapped(placed, controller=controller, config=config, layout=layout), n)


simulate_batch._cache_size = _simulate_vmapped._cache_size  # the jitted core's compilation count
