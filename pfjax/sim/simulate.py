"""The slip vehicle: the world-frame slip model on the simulation loop (:mod:`pfjax.sim.loop`).

Per sample ``k`` (time ``t_k = k dt``, ``k = 0..N``), :func:`_step`:

1. measure the pose against the path (closest point, warm-started Newton, docs/reproductions/path-following.md §2) and, with
   :class:`SensorNoise`, give the controller the noisy measurement (:func:`noisy_observation`);
2. sampled controllers: every ``control_every`` steps compute a new command and hold it
   (zero-order hold); continuous controllers: evaluated inside every RK4 stage instead;
3. saturate the steering at ``+-delta_max``; check the run's health (:mod:`pfjax.sim.status`);
4. propose one RK4 step of the pose (and a continuous controller's state), slip evaluated at the
   stage times; the loop accumulates the metrics (:func:`update_metrics`) and freezes a failed run.
   With a continuous controller (projection and controller in every stage) the stages are one loop
   (:func:`~pfjax.sim.integrators.rk4_step_rolled`, compiled about a quarter faster at the same run
   time); a sampled controller's small vector field keeps them written out.

:func:`simulate` is one run (write single-run code); :func:`simulate_batch` is the jitted,
vmapped entry point (:mod:`pfjax.sim.batch`). ``SimConfig`` (:mod:`pfjax.sim.settings`) fixes the
shapes and is a static argument; the measurement and the sensor noise are in :mod:`pfjax.sim.sensing`.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.controllers.base import Controller, Observation, saturate, step
from pfjax.metrics import running
from pfjax.models.slip import Pose, SlipParams, world_rhs
from pfjax.numerics import elementary as E
from pfjax.paths.geometry import (
    NEWTON_START,
    Projection,
    global_parameter,
    measure,
    polish_parameter,
)
from pfjax.sim import batch, loop
from pfjax.sim.integrators import rk4_step, rk4_step_rolled
from pfjax.sim.loop import stack, unstack  # noqa: F401  (re-exported: a batch of runs, run i of a batch)
from pfjax.sim.sensing import (
    SensorNoise,
    WithPath,
    measure_pose,
    noisy_observation,
    observation,
)
from pfjax.sim.settings import SimConfig
from pfjax.sim.slip_profiles import SlipProfile, slip_at
from pfjax.sim.status import classify

#: Newton steps that polish a scenario's given start parameter ``u0`` before sample 0.
U0_ITERS = 8

#: What reverse mode saves per step besides the carry: the projection's last-but-one Newton iterate,
#: so the backward step recomputes only the differentiated last Newton step (measured: 5 % less CPU
#: time for the benchmark's gradient); a whole step's residuals would cost far more memory traffic.
_SAVED = jax.checkpoint_policies.save_only_these_names(NEWTON_START)


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
    return observation(proj, pose, p.v, p.L, p.delta_max, sc.path)


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
        obs = noisy_observation(_observation(measure_pose(sc, pose, u_guess, iters), pose, sc), sc.noise, k)
        cmd = E.computed_once(controller.output(sc.gains, c, obs))
        delta = saturate(cmd, dmax)
        br, bf = slip_at(sc.slip, t)
        return world_rhs(pose, delta, br, bf, sc.params), controller.rate(sc.gains, c, obs, cmd, delta)

    return f


def held_command(controller: Controller, config: SimConfig, gains, c, obs, held_cmd, k, last):
    """A sampled controller's ``(cmd, c_next)`` at sample ``k``: a new command every ``control_every``
    steps (the state advanced by :func:`pfjax.controllers.base.step` over the sampling period), held
    in between (zero-order hold) and at sample ``N`` (``last``)."""
    dt, every = config.dt, int(config.control_every or 1)
    if every == 1:  # every step: no conditional (it would split XLA's fused loop body)
        new_cmd, c_next = step(controller, gains, c, obs, dt)
    else:
        new_cmd, c_next = jax.lax.cond(
            k % every == 0, lambda: step(controller, gains, c, obs, every * dt), lambda: (held_cmd, c)
        )
    return jnp.where(last, held_cmd, E.computed_once(new_cmd)), c_next


def _sampled_command(controller: Controller, config: SimConfig, sc: Scenario, c, obs, held: _Held, k, last):
    """Sampled controller: ``(cmd, c_next, delta)`` at sample ``k`` (:func:`held_command`);
    saturated at ``+-delta_max`` and rate limited, ``|delta_k - delta_{k-1}| <= delta_rate_max dt``."""
    dt = config.dt
    cmd, c_next = held_command(controller, config, sc.gains, c, obs, held.cmd, k, last)
    dmax = jnp.asarray(sc.params.delta_max, float)
    rate = jnp.asarray(sc.params.delta_rate_max, float)
    delta, prev = saturate(cmd, dmax), held.delta
    # steering rate limit (exactly a no-op when rate = inf); held at sample N
    limited = prev + E.clip(delta - prev, -rate * dt, rate * dt)
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
    proj = measure_pose(sc, pose, u, iters)
    obs = noisy_observation(_observation(proj, pose, sc), sc.noise, k)
    if config.control_every is None:
        cmd = E.computed_once(controller.output(sc.gains, c, obs))
        delta = saturate(cmd, dmax)
        new_pose, c_next = rk4_step_rolled(_closed_loop_rhs(controller, sc, proj.u, k, iters), t, (pose, c), dt)
    else:
        cmd, c_next, delta = _sampled_command(controller, config, sc, c, obs, carry.aux, k, last)
        rhs = lambda tt, ps: world_rhs(ps, delta, *slip_at(sc.slip, tt), sc.params)
        new_pose = rk4_step(rhs, t, pose, dt)
    finite = jnp.isfinite(pose.x) & jnp.isfinite(pose.y) & jnp.isfinite(pose.theta) & jnp.isfinite(proj.d)
    health = classify(finite, jnp.abs(proj.d), 1.0 - proj.kappa * proj.d, proj.at_end, config.d_fail)
    out = _Out(t, first, last, pose, proj, cmd, delta, (jnp.abs(cmd) > dmax).astype(float))
    # u: warm start of the next projection (frozen after a failure); proj.u: the final state's
    return loop.Sample(_State(new_pose, c_next, proj.u), health, t, out, _Held(proj.u, cmd, delta), keep=last)


def update_metrics(config: SimConfig, sc: WithPath, acc: running.Accumulator, s: loop.Sample, live, was_live):
    """Accumulate sample ``k``'s metrics (trapezoid weight 1/2 at both ends, 0 after a failure):
    :func:`pfjax.metrics.running.update` on the sample's ``out`` fields ``t``, ``first``, ``last``,
    ``proj`` (its ``d``, ``theta_e``), ``delta`` (applied steering) and ``saturated`` (any system on
    the loop whose sample has them: the slip vehicle, the dynamic vehicle)."""
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
        update=partial(update_metrics, config),
        record=_record,
        finish=partial(_finish, config),
        no_failure=math.nan,
    )


def simulate(controller: Controller, sc: Scenario, config: SimConfig, *, runs: int = 1) -> SimResult:
    """Simulate one run (pure, unbatched; see :func:`simulate_batch` for the entry point): samples
    ``k = 0..N`` of :func:`system` through :func:`pfjax.sim.loop.run`.

    One loop for samples 0..N (no separate first and last sample: a third less compile time); reverse
    mode stores the carry and ``_SAVED`` per step and recomputes the step; the small inputs enter the
    loop as scalars (:mod:`pfjax.numerics.layout`).

    Args:
        controller: the controller (static).
        sc: the run's scenario.
        config: static settings.
        runs: the runs on its device, this one included, in every block (static; the batched entry
            point's layout): they decide reverse mode's checkpoints (:func:`pfjax.sim.loop.run`).

    Returns:
        ``SimResult``: metrics, status, failure time, final state, trajectory (if ``config.record``).
    """
    controller.check_params(sc.gains)  # at trace time: a PI given state-feedback gains is bad input
    return run_vehicle(system(controller, config), sc, config, runs)


def run_vehicle(system: loop.System, sc, config: SimConfig, runs: int):
    """A controlled vehicle's samples ``k = 0..N`` through :func:`pfjax.sim.loop.run` (the slip and
    the dynamic vehicle): the small inputs as scalars, reverse mode's checkpoints by ``_SAVED``
    (in segments for many ``runs``)."""
    return loop.run(
        system,
        sc,
        config.n_steps + 1,
        record=config.record,
        scalar_inputs=True,
        checkpoint_policy=_SAVED,
        runs=runs,
    )


#: The jitted, vmapped :func:`simulate` and the jitted single run without a batch axis
#: (:func:`pfjax.sim.batch.vehicle_programs`).
_simulate_vmapped, _simulate_one = batch.vehicle_programs(simulate, module=__name__)


def simulate_batch(
    scenarios: Scenario, *, controller: Controller, config: SimConfig, devices=None, block: int | str | None = "auto"
) -> SimResult:
    """Jitted, vmapped :func:`simulate` over a batch of scenarios (leading axis of every leaf),
    sharded over ``devices`` (default: every device JAX sees) and, on CPU, evaluated in cache-sized
    blocks of runs (``block``: runs per block, ``"auto"`` or ``None`` for one block;
    :mod:`pfjax.sim.sharding`).

    Compiled once per controller, ``config``, batch shape, device set and block count. Under
    ``jit``/``grad`` the batch is not re-sharded and, unless ``block`` is a number of runs, not
    blocked (the outer call decides; a forward-mode gradient of ``D = 1..4`` gains ran 8-19 % faster
    at 2,000 runs in blocks of :func:`pfjax.sim.sharding.default_block` with ``tangents=D``; the
    outer function compiled by :func:`pfjax.numerics.compiler.jit` gets the simulator's vector
    width, a plain ``jax.jit`` XLA's default). Results are
    the same, run for run, whatever the number of devices and blocks, up to rounding (XLA compiles
    each block shape into its own vector code: at most an ulp or two in a metric, measured).
    """
    _check(scenarios, controller, config)
    return batch.call(_simulate_vmapped, scenarios, devices=devices, block=block, controller=controller, config=config)


def simulate_one(scenario: Scenario, *, controller: Controller, config: SimConfig) -> SimResult:
    """Jitted :func:`simulate` of one run (a scenario without a batch axis) on JAX's default device:
    the numbers that run gets in :func:`simulate_batch` up to rounding (tests/test_sharding.py), traced
    in less than half the time of a batch of one (:func:`pfjax.sim.batch.one_run`). ``pfjax
    simulate`` calls it."""
    _check(loop.stack([scenario]), controller, config)
    return _simulate_one(scenario, controller=controller, config=config)


def _check(scenarios: Scenario, controller: Controller, config: SimConfig) -> None:
    """The entry points' input checks on a batch (leading axis), before tracing, where JAX would add
    to the message: the controller's gains, and the memory of a recorded batch."""
    controller.check_params(scenarios.gains)
    if config.record:
        batch.check_record(scenarios, config.n_steps)
