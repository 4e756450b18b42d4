"""One parking run as a pure, jittable, vmappable function; batched entry points.

Time is divided into scanner periods T_s (spec §3: 0.1 s). At the start of each period the robot
(1) reverses its travel direction when an obstacle lies in the half of its rectangle toward which
it travels, or — in the garage rule — when, after it has once switched to backward, it travels
backward and ``x ≤ X_s``; (2) then integrates the closed loop (:func:`pfjax.parking.model.vector_field`)
over the period with ``n_sub`` RK4 steps, direction and α held. After every RK4 step it stops
with a status: converged (``|x| + sqrt(y² + tan²θ) < tol``), heading limit (``|θ| ≥ π/2``,
where the controller is undefined), non-finite state, or timeout (``t ≥ t_max``); a switch that
would be the (max_switches + 1)-th fails the run with ``TOO_MANY_SWITCHES``. Every switch is
logged (time, pose, cause) in fixed-size arrays, so the log batches too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from pfjax.numerics import compiler
from pfjax.parking.geometry import ObstacleMap, RobotShape, obstacle_ahead
from pfjax.parking.model import ControlParams, parking_error, vector_field
from pfjax.parking.schedules import alpha_at
from pfjax.sim.integrators import rk4_step

Array = jnp.ndarray


class Status(IntEnum):
    RUNNING = -1  #: internal only
    CONVERGED = 0  #: |x| + sqrt(y² + tan²θ) < tol
    TIMEOUT = 1  #: not converged after t_max (200 s)
    TOO_MANY_SWITCHES = 2  #: more than max_switches (10) direction switches
    HEADING_LIMIT = 3  #: |θ| ≥ π/2, where the controller is undefined
    NONFINITE = 4  #: the state became NaN or infinite


STATUS_NAMES = {int(s): s.name.lower() for s in Status if s is not Status.RUNNING}


class SwitchCause(IntEnum):
    NONE = 0
    OBSTACLE = 1  #: an obstacle entered the travel-side half of the rectangle
    SWITCH_POINT = 2  #: the garage rule, x ≤ X_s while backing


@dataclass(frozen=True)
class ParkingConfig:
    """Settings that fix shapes and loop lengths (static under jit)."""

    t_max: float = 200.0  # s
    max_switches: int = 10
    tol: float = 0.02  # stop when |x| + sqrt(y² + tan²θ) < tol
    n_sub: int = 2  # RK4 steps per scanner period (0.05 s at T_s = 0.1 s; n_sub = 10 agrees, see tests)
    max_samples: int = 20000  # hard loop bound (scanner periods)

    @property
    def log_len(self) -> int:
        return self.max_switches + 1


class RunParams(NamedTuple):
    """Everything that varies between runs (a pytree; batch any leaf with vmap)."""

    pose0: Array  # (3,) x m, y m, θ rad
    direction0: Array  # +1 forward, −1 backward
    schedule: Array  # (SCHEDULE_LEN,) α at the start and after each switch
    xs: Array  # m, garage switching point X_s
    use_xs: Array  # 1.0 = garage rule on
    scan_period: Array  # s, scanner sampling period T_s
    control: ControlParams
    shape: RobotShape


class Carry(NamedTuple):
    k: Array  # scanner periods done
    t: Array  # s
    state: Array  # (4,) x, y, θ, q (PI integrator, rad)
    direction: Array  # ±1
    n_switches: Array  # int
    backed: Array  # bool: has switched to backward once
    status: Array  # int, Status
    distance: Array  # m travelled
    log_t: Array  # (M,) s, NaN where unused
    log_pose: Array  # (M, 3) pose at each switch
    log_cause: Array  # (M,) SwitchCause


class RunResult(NamedTuple):
    status: Array  # Status
    time: Array  # s at the end (parking time when converged)
    final: Array  # (3,) final pose
    n_switches: Array
    distance: Array  # m travelled
    error: Array  # |x| + sqrt(y² + tan²θ) at the end
    log_t: Array  # (M,)
    log_pose: Array  # (M, 3)
    log_cause: Array  # (M,)


class Trajectory(NamedTuple):
    """Sampled at the start of every scanner period (after the switch decision)."""

    t: Array  # (K,) s
    state: Array  # (K, 4)
    direction: Array  # (K,)
    alpha: Array  # (K,)
    running: Array  # (K,) bool


def _init(p: RunParams, cfg: ParkingConfig) -> Carry:
    m = cfg.log_len
    dt = p.pose0.dtype
    return Carry(
        k=jnp.asarray(0), t=jnp.asarray(0.0, dt), state=jnp.concatenate([p.pose0, jnp.zeros(1, dt)]),
        direction=jnp.asarray(p.direction0, dt), n_switches=jnp.asarray(0), backed=jnp.asarray(False),
        status=jnp.asarray(int(Status.RUNNING)), distance=jnp.asarray(0.0, dt),
        log_t=jnp.full(m, jnp.nan, dt), log_pose=jnp.full((m, 3), jnp.nan, dt), log_cause=jnp.zeros(m, jnp.int32),
    )


def _period(c: Carry, p: RunParams, omap: ObstacleMap, cfg: ParkingConfig) -> Carry:
    """One scanner period: switch decision, then ``n_sub`` RK4 steps (frozen once stopped)."""
    running = c.status == Status.RUNNING
    pose = c.state[:3]
    hit = obstacle_ahead(pose, p.shape, c.direction, omap)
    at_xs = (p.use_xs > 0.5) & c.backed & (c.direction < 0) & (pose[0] <= p.xs)
    switch = running & (hit | at_xs)
    direction = jnp.where(switch, -c.direction, c.direction)
    n = c.n_switches + switch.astype(c.n_switches.dtype)
    i = jnp.minimum(n - 1, cfg.log_len - 1)
    log_t = jnp.where(switch, c.log_t.at[i].set(c.t), c.log_t)
    log_pose = jnp.where(switch, c.log_pose.at[i].set(pose), c.log_pose)
    cause = jnp.where(hit, int(SwitchCause.OBSTACLE), int(SwitchCause.SWITCH_POINT))
    log_cause = jnp.where(switch, c.log_cause.at[i].set(cause), c.log_cause)
    status = jnp.where(running & (n > cfg.max_switches), int(Status.TOO_MANY_SWITCHES), c.status)

    alpha = alpha_at(p.schedule, n)
    v1 = direction * p.control.speed
    h = p.scan_period / cfg.n_sub

    def rhs(_t, s):
        return vector_field(s, v1, alpha, p.control)

    def step(_, carry):
        state, t, st, dist = carry
        run = st == Status.RUNNING
        new = rk4_step(rhs, t, state, h)
        t_new = t + h
        finite = jnp.all(jnp.isfinite(new))
        code = jnp.select(
            [~finite, jnp.abs(new[2]) >= 0.5 * math.pi, parking_error(new[0], new[1], new[2]) < cfg.tol, t_new >= cfg.t_max - 1e-9],
            [int(Status.NONFINITE), int(Status.HEADING_LIMIT), int(Status.CONVERGED), int(Status.TIMEOUT)],
            int(Status.RUNNING),
        )
        keep = run & finite
        return (jnp.where(keep, new, state), jnp.where(run, t_new, t), jnp.where(run, code, st),
                dist + jnp.where(run, p.control.speed * h, 0.0))

    state, t, status, dist = lax.fori_loop(0, cfg.n_sub, step, (c.state, c.t, status, c.distance))
    return Carry(c.k + 1, t, state, direction, n, c.backed | (switch & (direction < 0)), status, dist, log_t, log_pose, log_cause)


def _result(c: Carry, cfg: ParkingConfig) -> RunResult:
    status = jnp.where(c.status == Status.RUNNING, int(Status.TIMEOUT), c.status)
    x, y, th = c.state[0], c.state[1], c.state[2]
    return RunResult(status, c.t, c.state[:3], c.n_switches, c.distance, parking_error(x, y, th), c.log_t, c.log_pose, c.log_cause)


def run(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig = ParkingConfig()) -> RunResult:
    """Simulate one run until it stops (``lax.while_loop``; vmapped, it runs until every run has stopped)."""
    final = lax.while_loop(lambda c: (c.status == Status.RUNNING) & (c.k < cfg.max_samples),
                           lambda c: _period(c, p, omap, cfg), _init(p, cfg))
    return _result(final, cfg)


def run_recorded(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig, n_periods: int) -> tuple[RunResult, Trajectory]:
    """One run with its trajectory over ``n_periods`` scanner periods (``lax.scan``), same step as :func:`run`."""

    def body(c, _):
        c2 = _period(c, p, omap, cfg)
        a = alpha_at(p.schedule, c2.n_switches)
        return c2, Trajectory(c.t, c.state, c2.direction, a, c.status == Status.RUNNING)

    final, traj = lax.scan(body, _init(p, cfg), None, length=n_periods)
    return _result(final, cfg), traj


# 512-bit vectors on AVX-512 CPUs (pfjax.numerics.compiler: no XLA trigonometry in these programs)
run_jit = compiler.jit(run, static_argnums=2)
run_recorded_jit = compiler.jit(run_recorded, static_argnums=(2, 3))
run_batch = compiler.jit(jax.vmap(run, in_axes=(0, None, None)), static_argnums=2)


def n_periods_for(cfg: ParkingConfig, scan_period: float) -> int:
    return int(math.ceil(cfg.t_max / scan_period)) + 1


def _take(tree, sl):
    return jax.tree_util.tree_map(lambda a: a[sl], tree)


def run_many(params: RunParams, omap: ObstacleMap, cfg: ParkingConfig = ParkingConfig(), *, chunk: int = 4096,
             progress: bool = False, desc: str = "parking runs") -> RunResult:
    """Batched runs in jitted chunks of exactly ``chunk`` runs (short chunks padded by repeating the last run,
    so every call with the same ``chunk`` reuses one compilation); NumPy out, in input order."""
    n = int(params.pose0.shape[0])
    size = chunk
    outs = []
    starts = range(0, n, size)
    if progress:
        from tqdm import tqdm

        starts = tqdm(starts, desc=desc, unit="chunk")
    for s in starts:
        idx = np.minimum(np.arange(s, s + size), n - 1)
        r = run_batch(_take(params, idx), omap, cfg)
        outs.append(jax.tree_util.tree_map(lambda a: np.asarray(a)[: min(size, n - s)], r))
    return jax.tree_util.tree_map(lambda *a: np.concatenate(a), *outs)


def run_params(x0, direction=1, schedule=(1.0,), *, xs=None, front=None, scan_period=0.1, control=None,
               theta_in_degrees=True, width=None, length=None) -> RunParams:
    """Convenience constructor of one run's parameters (``x0 = (x m, y m, θ deg)`` by default)."""
    from pfjax.parking.calibrate import A_F
    from pfjax.parking.geometry import L1_WIDTH, L2_LENGTH, robot_shape
    from pfjax.parking.model import control_params
    from pfjax.parking.schedules import pad_schedule

    x, y, th = (float(v) for v in x0)
    th = math.radians(th) if theta_in_degrees else th
    f = lambda v: jnp.asarray(v, dtype=float)  # noqa: E731
    return RunParams(
        pose0=f([x, y, th]), direction0=f(1.0 if direction > 0 else -1.0), schedule=f(pad_schedule(schedule)),
        xs=f(0.0 if xs is None else xs), use_xs=f(0.0 if xs is None else 1.0), scan_period=f(scan_period),
        control=control if control is not None else control_params(),
        shape=robot_shape(A_F if front is None else front, L1_WIDTH if width is None else width, L2_LENGTH if length is None else length),
    )


def stack_params(items: list[RunParams]) -> RunParams:
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *items)
