"""The dynamic vehicle: CommonRoad's ST single-track model (:mod:`pfjax.models.single_track`) or its
single-track drift model STD (Pacejka tyres, wheel speeds; :mod:`pfjax.models.single_track_drift`) on
the simulation loop (:mod:`pfjax.sim.loop`), path following with any registered controller. The
scenario's parameters pick the model (:class:`~pfjax.models.single_track.STParams`: ST;
:class:`~pfjax.models.single_track.STDParams`: STD); what follows holds for both.

The slip is not declared: it emerges from the tyre forces, the speed, the path's curvature and the
friction ``mu``. Per sample ``k`` (time ``t_k = k dt``, ``k = 0..N``), :func:`_step`:

1. measure the *rear-axle* pose ``(x_r, y_r, theta) = (sx - l_r cos psi, sy - l_r sin psi, psi)``
   against the path, exactly as the kinematic slip vehicle does (:func:`pfjax.sim.simulate.measure_pose`,
   sensor noise :func:`~pfjax.sim.simulate.noisy_observation`); the controller sees ``d``,
   ``theta_e``, ``kappa``, the pose, the wheelbase ``l = l_f + l_r``, the steering limit
   ``delta_max`` and the rear axle's longitudinal speed ``v cos(beta)`` (m/s): every registered
   controller runs unchanged;
2. the controller's command (sampled, zero-order hold: :func:`~pfjax.sim.simulate.held_command`),
   saturated at ``+-delta_max``, is ``delta_c``;
3. check the run's health (:mod:`pfjax.sim.status`: non-finite state, ``|d| > d_fail``, the Frenet
   singularity, the path's end);
4. propose one RK4 step of the model's state with the two low-level loops inside the vector field:

       v_delta = (delta_c - delta) / tau_delta     steering actuator, first order (tau_delta, s), then
                                                   rate limited to [v_delta_min, v_delta_max] and held
                                                   at the angle limits (the model's steering constraints)
       a_long  = k_v (v_ref - v)                   speed loop (k_v, 1/s) holding the reference speed
                                                   v_ref (m/s), limited by the model's acceleration
                                                   constraints (+-a_max, constant power above v_switch)

   The ST model has no rolling or air resistance, so the proportional speed loop has no
   steady-state error. The step's four stages are one loop
   (:func:`~pfjax.sim.integrators.rk4_step_rolled`): the tyre model is compiled once, not four
   times, which more than halves the drift model's compile time at the same or a lower run time.

The slip angles are measured at every sample (:func:`pfjax.models.single_track.tyre_slip`,
:func:`~pfjax.models.single_track.drift_tyre_slip`: the tyre slip angles the model's forces use, in the kinematic slip model's ``SOURCE`` convention, so
that they compare directly with the slip the kinematic studies declare): rear ``beta_r``, front
``beta_f`` and at the centre of mass ``beta``;
:class:`SlipMetrics` holds their largest and time-mean magnitudes (degrees). The path-following
metrics are the kinematic vehicle's (:func:`~pfjax.sim.simulate.update_metrics`; the applied steering
is the actuator's angle ``delta``). Only sampled controllers (``SimConfig.control_every >= 1``).

The run starts on the given rear-axle pose at the reference speed, straight (``delta = psi_dot =
beta = 0``; the drift model's wheels rolling, ``omega = v / R_w``). :func:`simulate_batch` is the jitted, vmapped entry point.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, NamedTuple

import jax.numpy as jnp
from jax import Array

from pfjax.controllers.base import Controller, saturate
from pfjax.errors import InputError
from pfjax.metrics import running
from pfjax.models import single_track as st
from pfjax.models.slip import Pose
from pfjax.numerics import elementary as E
from pfjax.paths.geometry import global_parameter, measure, polish_parameter
from pfjax.sim import batch, loop
from pfjax.sim.integrators import rk4_step_rolled
from pfjax.sim.simulate import (
    U0_ITERS,
    Final,
    SensorNoise,
    SimConfig,
    held_command,
    measure_pose,
    noisy_observation,
    observation,
    run_vehicle,
    update_metrics,
)
from pfjax.sim.status import classify


class DynamicScenario(NamedTuple):
    """Everything that varies between runs of the dynamic vehicle (a pytree; batch it along a leading axis)."""

    pose0: Pose  # initial rear-axle pose (m, m, rad)
    vehicle: st.STParams | st.STDParams  # the model's parameters (mu among them): ST or STD
    v_ref: Array | float  # m/s, reference speed of the speed loop (the start speed)
    path: Any  # a path shape from pfjax.paths
    gains: Any  # the controller's parameter pytree
    tau_delta: Array | float = 0.05  # s, steering actuator time constant
    k_v: Array | float = 5.0  # 1/s, speed loop gain
    noise: SensorNoise | None = None  # measurement noise seen by the controller (None: exact)
    u0: Any = None  # path parameter near the start's closest point (None: global search)


class SlipMetrics(NamedTuple):
    """Slip angles the run produced (up to its failure), degrees, in the kinematic model's convention;
    NaN for a run that fails at its first sample (``t = 0``: it has no samples), as its ``max_abs_d``
    (:func:`pfjax.metrics.running.finalize`)."""

    max_abs_beta_r_deg: Array  # deg, largest |rear-axle slip|
    max_abs_beta_f_deg: Array  # deg, largest |front-wheel slip|
    max_abs_beta_deg: Array  # deg, largest |slip at the centre of mass|
    mean_abs_beta_r_deg: Array  # deg, time-mean |rear-axle slip| (trapezoid rule)
    mean_abs_beta_f_deg: Array  # deg
    mean_abs_beta_deg: Array  # deg


SLIP_METRIC_NAMES = SlipMetrics._fields

#: A recorded run holds two trajectories' worth of samples per step (the states and the slips),
#: against one for the kinematic simulator (:func:`pfjax.sim.batch.check_record`).
RECORD_COPIES = 2


class DynamicTrajectory(NamedTuple):
    """Samples at ``t_k = k dt``, ``k = 0..N`` (shape ``(N+1,)`` per run)."""

    t: Array  # s
    x: Array  # m, rear axle
    y: Array  # m, rear axle
    theta: Array  # rad, yaw angle psi
    d: Array  # m
    theta_e: Array  # rad
    kappa: Array  # 1/m
    s: Array  # m
    delta_cmd: Array  # rad, controller command (before saturation)
    delta: Array  # rad, the actuator's steering angle
    beta_r: Array  # rad, measured rear-axle slip
    beta_f: Array  # rad, measured front-wheel slip
    beta: Array  # rad, slip angle at the centre of mass
    v: Array  # m/s, speed of the centre of mass
    psi_dot: Array  # rad/s, yaw rate


class DynamicResult(NamedTuple):
    metrics: running.Metrics  # the path-following metrics (as the kinematic vehicle's)
    slip: SlipMetrics  # the slip angles the run produced
    status: Array  # int32, a pfjax.sim.status.Status
    fail_time: Array  # s, time of the first failure (NaN if none)
    final: Final  # rear-axle pose and errors at the end (or at the failure)
    trajectory: DynamicTrajectory | None


class _Acc(NamedTuple):
    path: running.Accumulator
    slip_max: tuple  # rad: max |beta_r|, |beta_f|, |beta| (scalars: a batch keeps each a contiguous vector)
    slip_sum: tuple  # rad s: weighted sums of the same


class _State(NamedTuple):
    x: Any  # the model's state: st.STState or st.STDState
    c: Any  # controller state
    u: Array  # path parameter, warm start of the next projection


class _Held(NamedTuple):
    u_last: Array  # path parameter of the last sample's closest point
    cmd: Array  # rad, the (held) command


class _Out(NamedTuple):
    t: Array  # s
    first: Array  # bool
    last: Array  # bool
    pose: Pose  # rear axle
    proj: Any  # Projection of the rear axle
    cmd: Array  # rad
    delta: Array  # rad, the actuator's angle
    saturated: Array  # 1.0 where |cmd| > delta_max
    slip: tuple  # rad: beta_r, beta_f, beta
    x: Any  # the model's state


def rear_axle_pose(x, p) -> Pose:
    """The rear-axle pose of an ST or STD state: ``(sx - l_r cos psi, sy - l_r sin psi, psi)`` (m, m, rad)."""
    p = st.body(p)
    s, c = E.sincos(x.psi)
    return Pose(x.sx - p.l_r * c, x.sy - p.l_r * s, x.psi)


def start_state(pose0: Pose, v0, p):
    """The ST (or STD, for :class:`~pfjax.models.single_track.STDParams`) state of a vehicle whose rear
    axle is at ``pose0`` (m, m, rad), driving straight at ``v0`` (m/s), its wheels rolling."""
    pose0 = Pose(*pose0)
    b = st.body(p)
    s, c = E.sincos(pose0.theta)
    zero = jnp.zeros_like(pose0.x)
    x = st.STState(pose0.x + b.l_r * c, pose0.y + b.l_r * s, zero, zero + v0, pose0.theta, zero, zero)
    if isinstance(p, st.STDParams):
        return st.STDState(*x, *(2 * (x.v / p.R_w,)))
    return x


def closed_loop_rhs(x, delta_c, sc: DynamicScenario):
    """The model's vector field with the steering actuator and the speed loop closed (module docstring):
    ``vector_field(x, (delta_c - delta) / tau_delta, k_v (v_ref - v), vehicle)``, the division by
    ``tau_delta`` as a multiplication by its reciprocal (a run's constant; in a timing script, ST runs of 2000 steps: float64 about 16 % faster, float32 about 8 % slower)."""
    v_delta, a_long = (delta_c - x.delta) * (1 / sc.tau_delta), sc.k_v * (sc.v_ref - x.v)
    if isinstance(sc.vehicle, st.STDParams):
        return st.vector_field_drift(x, v_delta, a_long, sc.vehicle)
    return st.vector_field(x, v_delta, a_long, sc.vehicle)


def tyre_slip(x, p) -> tuple[Array, Array, Array]:
    """``(beta_r, beta_f, beta)`` of either model's state (rad, the kinematic model's convention)."""
    return st.drift_tyre_slip(x, p) if isinstance(p, st.STDParams) else st.tyre_slip(x, p)


def _start(controller: Controller, sc: DynamicScenario) -> loop.Start:
    pose0 = Pose(*(jnp.asarray(a, float) for a in sc.pose0))
    if sc.u0 is None:
        u0 = global_parameter(sc.path, pose0.x, pose0.y)
    else:
        u0 = polish_parameter(sc.path, pose0.x, pose0.y, jnp.asarray(sc.u0, pose0.x.dtype), U0_ITERS)
    zero = jnp.zeros((), pose0.x.dtype)
    acc = _Acc(running.init(zero, zero), (zero, zero, zero), (zero, zero, zero))
    x0 = start_state(pose0, jnp.asarray(sc.v_ref, zero.dtype), sc.vehicle)
    return loop.Start(_State(x0, controller.init(sc.gains), u0), acc, zero, _Held(u0, zero))


def _step(controller: Controller, config: SimConfig, sc: DynamicScenario, carry: loop.LoopCarry, k) -> loop.Sample:
    """Sample ``k``: measure the rear axle, command, health; the proposed RK4 step of the ST state.
    Sample ``N`` only measures (``keep``), the command held from step ``N - 1``."""
    x, c, u = carry.state
    p = st.body(sc.vehicle)
    dt, n_steps = config.dt, config.n_steps
    first, last = k == 0, k == n_steps
    t = jnp.where(last, jnp.asarray(n_steps * dt, x.v.dtype), k * dt)
    pose = rear_axle_pose(x, p)
    proj = measure_pose(sc, pose, u, config.newton_iters)
    slip = tyre_slip(x, sc.vehicle)
    dmax = jnp.asarray(p.delta_max, float)
    v_rear = x.v * E.sincos(x.beta)[1]  # m/s, the rear axle's longitudinal speed
    obs = noisy_observation(observation(proj, pose, v_rear, p.l_f + p.l_r, dmax, sc.path), sc.noise, k)
    cmd, c_next = held_command(controller, config, sc.gains, c, obs, carry.aux.cmd, k, last)
    delta_c = saturate(cmd, dmax)
    x_next = rk4_step_rolled(lambda tt, xx: closed_loop_rhs(xx, delta_c, sc), t, x, dt)
    finite = jnp.isfinite(proj.d)
    for value in x:
        finite = finite & jnp.isfinite(value)
    health = classify(finite, jnp.abs(proj.d), 1.0 - proj.kappa * proj.d, proj.at_end, config.d_fail)
    out = _Out(t, first, last, pose, proj, cmd, x.delta, (jnp.abs(cmd) > dmax).astype(x.v.dtype), slip, x)
    return loop.Sample(_State(x_next, c_next, proj.u), health, t, out, _Held(proj.u, cmd), keep=last)


def _update(config: SimConfig, sc: DynamicScenario, acc: _Acc, s: loop.Sample, live, was_live) -> _Acc:
    o = s.out
    path = update_metrics(config, sc, acc.path, s, live, was_live)
    w = jnp.where(live, jnp.where(o.first | o.last, 0.5, 1.0), 0.0) * config.dt
    mag = [jnp.where(live, jnp.abs(b), 0.0) for b in o.slip]
    return _Acc(
        path,
        tuple(jnp.maximum(m, b) for m, b in zip(acc.slip_max, mag)),
        tuple(total + w * b for total, b in zip(acc.slip_sum, mag)),
    )


def _record(sc: DynamicScenario, s: loop.Sample, state: _State) -> DynamicTrajectory:
    o = s.out
    return DynamicTrajectory(
        o.t,
        o.pose.x,
        o.pose.y,
        o.pose.theta,
        o.proj.d,
        o.proj.theta_e,
        o.proj.kappa,
        o.proj.s,
        o.cmd,
        o.delta,
        o.slip[0],
        o.slip[1],
        o.slip[2],
        o.x.v,
        o.x.psi_dot,
    )


def _finish(config: SimConfig, sc: DynamicScenario, r: loop.Run) -> DynamicResult:
    metrics = running.finalize(r.metrics.path, config.n_steps * config.dt, r.failed, config.success_band)
    deg = 180.0 / math.pi
    empty = r.metrics.path.time <= 0  # failed at its first sample: no samples, no slip (as running.finalize)
    time = jnp.where(empty, 1.0, r.metrics.path.time)
    slip = SlipMetrics(
        *(jnp.where(empty, jnp.nan, m * deg) for m in r.metrics.slip_max),
        *(jnp.where(empty, jnp.nan, total / time * deg) for total in r.metrics.slip_sum),
    )
    pose = rear_axle_pose(r.state.x, sc.vehicle)
    proj = measure(sc.path, pose.x, pose.y, pose.theta, r.aux.u_last)
    final = Final(pose.x, pose.y, pose.theta, proj.d, proj.theta_e, r.state.x.delta, proj.s)
    return DynamicResult(metrics, slip, r.status, r.fail_time, final, r.records)


def system(controller: Controller, config: SimConfig) -> loop.System:
    """The dynamic vehicle as a :class:`pfjax.sim.loop.System` (inputs: a :class:`DynamicScenario`)."""
    if config.control_every is None:
        raise InputError(
            "control_every: the dynamic vehicle takes a sampled controller (>= 1 steps); a continuous one "
            "is not supported",
            "control_every",
        )
    return loop.System(
        init=partial(_start, controller),
        step=partial(_step, controller, config),
        update=partial(_update, config),
        record=_record,
        finish=partial(_finish, config),
        no_failure=math.nan,
    )


def simulate(controller: Controller, sc: DynamicScenario, config: SimConfig, *, runs: int = 1) -> DynamicResult:
    """Simulate one run (pure, unbatched; :func:`simulate_batch` is the entry point): samples
    ``k = 0..N`` of :func:`system` through :func:`pfjax.sim.loop.run`.

    Args:
        controller: the controller (static).
        sc: the run's scenario.
        config: static settings (``config.control_every`` must be an integer).
        runs: the runs on its device, this one included (static; as
            :func:`pfjax.sim.simulate.simulate`).

    Returns:
        :class:`DynamicResult`: metrics, slip metrics, status, failure time, final state, trajectory.
    """
    controller.check_params(sc.gains)
    return run_vehicle(system(controller, config), sc, config, runs)


#: The jitted, vmapped :func:`simulate` and the jitted single run without a batch axis
#: (:func:`pfjax.sim.batch.vehicle_programs`).
_simulate_vmapped, _simulate_one = batch.vehicle_programs(simulate, module=__name__)


def simulate_batch(
    scenarios: DynamicScenario,
    *,
    controller: Controller,
    config: SimConfig,
    devices=None,
    block: int | str | None = "auto",
) -> DynamicResult:
    """Jitted, vmapped :func:`simulate` over a batch of scenarios (leading axis of every leaf),
    sharded and blocked as :func:`pfjax.sim.simulate_batch` (compiled once per controller,
    ``config``, batch shape, device set and block count)."""
    _check(scenarios, controller, config)
    return batch.call(_simulate_vmapped, scenarios, devices=devices, block=block, controller=controller, config=config)


def simulate_one(scenario: DynamicScenario, *, controller: Controller, config: SimConfig) -> DynamicResult:
    """Jitted :func:`simulate` of one run (a scenario without a batch axis), as
    :func:`pfjax.sim.simulate.simulate_one`: the numbers of that run in :func:`simulate_batch`."""
    _check(loop.stack([scenario]), controller, config)
    return _simulate_one(scenario, controller=controller, config=config)


def _check(scenarios: DynamicScenario, controller: Controller, config: SimConfig) -> None:
    """The entry points' input checks on a batch (leading axis), before tracing: the controller's
    gains, the settings (:func:`system`), the step (:func:`check_step`) and the memory of a
    recorded batch (states and slips)."""
    controller.check_params(scenarios.gains)
    system(controller, config)
    check_step(scenarios, config)
    if config.record:
        batch.check_record(scenarios, config.n_steps, copies=RECORD_COPIES)


def check_step(scenarios: DynamicScenario, config: SimConfig, key: str = "config.dt") -> None:
    """:class:`~pfjax.errors.InputError` naming ``key`` if ``config.dt`` is beyond the stable RK4
    step (:func:`pfjax.models.single_track.check_step`) of the batch's worst case: its highest
    friction and lowest reference speed, shortest steering time constant and stiffest speed loop.
    A batch of traced values (inside a caller's ``jit``) is not checked: its numbers are not known."""
    import jax
    import numpy as np

    from pfjax.errors import is_traced

    parts = (scenarios.vehicle, scenarios.v_ref, scenarios.tau_delta, scenarios.k_v)
    if is_traced(parts):
        return
    # host copies: a concrete batch a caller's jit captured would otherwise be reduced as traced values
    vehicle, v_ref, tau, k_v = jax.tree_util.tree_map(np.asarray, parts)
    first = jax.tree_util.tree_map(lambda a: a.reshape(-1)[0], vehicle)
    params = st.with_mu(first, float(np.max(st.body(vehicle).mu)))
    st.check_step(
        key,
        config.dt,
        params,
        float(np.min(v_ref)),
        float(np.min(tau)),
        float(np.max(k_v)),
        worst_case="the runs' worst case",
    )
