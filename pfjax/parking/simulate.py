"""One parking run as a pure, jittable, vmappable function; batched entry points.

Time is divided into scanner periods T_s (docs/reproductions/parking.md §3: 0.1 s). At the start of each period the robot
(1) reverses its travel direction when an obstacle lies in the half of its rectangle toward which
it travels, or — in the garage rule — when, after it has once switched to backward, it travels
backward and ``x ≤ X_s``; (2) then integrates the closed loop (:func:`pfjax.parking.model.vector_field`)
over the period with ``n_sub`` RK4 steps, direction and α held. After every RK4 step it stops
with a status:

* ``converged``: ``|x| + sqrt(y² + tan²θ) < tol``;
* ``heading_limit``: ``|θ| ≥ π/2``, where the controller is undefined;
* ``nonfinite``: the state became NaN or infinite;
* ``stuck``: switching repeatedly in place (:class:`ParkingConfig`): the robot has travelled less
  than ``stuck_travel`` metres over its last ``stuck_switches`` legs between reversals — it reverses
  again before getting anywhere (the source's case B: "switches repeatedly in place"). Travel is
  the progress measure: while it moves, the source's Lyapunov function decreases (its Theorem), so
  a run that keeps moving keeps progressing, however many times it reverses;
* ``timeout``: ``t ≥ t_max`` (200 s);
* ``start_overlap``: the rectangle meets an obstacle at the start pose (a start in a sweep over
  poses; a single run's start is refused with an error instead, :func:`pfjax.parking.maps.check_start`);
* ``too_many_switches``: only with a cut-off ``max_switches`` (the GA search's: the source's
  search "terminates the simulation if the number of switching operations exceeds 10"); single
  runs, cases, maps over starts and the Monte Carlo have none.

Two **assumed** timings are options (:class:`RunParams`): ``pause``, seconds the robot stands still
at each reversal (the source's experiments stood still 1 s), and ``decision_delay``, the scanner deciding
on the pose one period old (a scan's latency). Every switch is logged (time, pose, cause) in
fixed-size arrays (:attr:`ParkingConfig.log_len` entries; later switches are counted, not logged),
so the log batches too.
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
    TOO_MANY_SWITCHES = 2  #: more than max_switches direction switches (the GA search's cut-off only)
    HEADING_LIMIT = 3  #: |θ| ≥ π/2, where the controller is undefined
    NONFINITE = 4  #: the state became NaN or infinite
    STUCK = 5  #: reversing repeatedly without progress (see the module docstring)
    START_OVERLAP = 6  #: the robot's rectangle meets an obstacle at the start pose (not simulated)


STATUS_NAMES = {int(s): s.name.lower() for s in Status if s is not Status.RUNNING}


class SwitchCause(IntEnum):
    NONE = 0
    OBSTACLE = 1  #: an obstacle entered the travel-side half of the rectangle
    SWITCH_POINT = 2  #: the garage rule, x ≤ X_s while backing


@dataclass(frozen=True)
class ParkingConfig:
    """Settings that fix shapes and loop lengths (static under jit).

    Attributes:
        t_max: timeout, s.
        max_switches: fail a run at its (max_switches + 1)-th reversal (``TOO_MANY_SWITCHES``);
            None: no cut-off. The GA search uses 10 (:data:`SEARCH_MAX_SWITCHES`).
        tol: stop when ``|x| + sqrt(y² + tan²θ) < tol``.
        n_sub: RK4 steps per scanner period (0.05 s at T_s = 0.1 s; n_sub = 10 agrees, see tests).
        max_samples: hard loop bound (scanner periods).
        stuck_switches: the legs between reversals over which travel is measured (``stuck``, module
            docstring); None disables the status.
        stuck_travel: m, travel over those legs below which a run is stuck (0.1 m: 2 s at the
            source's 0.05 m/s, against legs of 0.2-0.7 m when it parks).
        log_capacity: switches logged when there is no cut-off.
    """

    t_max: float = 200.0
    max_switches: int | None = None
    tol: float = 0.02
    n_sub: int = 2
    max_samples: int = 20000
    stuck_switches: int | None = 4
    stuck_travel: float = 0.1
    log_capacity: int = 32

    @property
    def log_len(self) -> int:
        return self.log_capacity if self.max_switches is None else self.max_switches + 1


#: The GA search's cut-off (docs/reproductions/parking.md §5): more than 10 switches and the candidate counts as failed.
SEARCH_MAX_SWITCHES = 10


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
    pause: Array  # s the robot stands still at each reversal (0: none)
    decision_delay: Array  # 1.0: the scanner decides on the pose one period old; 0.0: on the current pose


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
    prev_pose: Array  # (3,) pose at the start of the previous period (the delayed scanner's view)
    pause_left: Array  # s still to stand at the current reversal
    travel_at: Array  # (K,) m travelled at the last K reversals, a ring (stuck test)


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


def _init(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig) -> Carry:
    m = cfg.log_len
    dt = p.pose0.dtype
    overlap = obstacle_ahead(p.pose0, p.shape, 1.0, omap) | obstacle_ahead(p.pose0, p.shape, -1.0, omap)
    return Carry(
        k=jnp.asarray(0),
        t=jnp.asarray(0.0, dt),
        state=jnp.concatenate([p.pose0, jnp.zeros(1, dt)]),
        direction=jnp.asarray(p.direction0, dt),
        n_switches=jnp.asarray(0),
        backed=jnp.asarray(False),
        status=jnp.where(overlap, int(Status.START_OVERLAP), int(Status.RUNNING)),
        distance=jnp.asarray(0.0, dt),
        log_t=jnp.full(m, jnp.nan, dt),
        log_pose=jnp.full((m, 3), jnp.nan, dt),
        log_cause=jnp.zeros(m, jnp.int32),
        prev_pose=p.pose0,
        pause_left=jnp.asarray(0.0, dt),
        travel_at=jnp.zeros(max(cfg.stuck_switches or 1, 1), dt),
    )


def _period(c: Carry, p: RunParams, omap: ObstacleMap, cfg: ParkingConfig) -> Carry:
    """One scanner period: switch decision, then ``n_sub`` RK4 steps (frozen once stopped)."""
    running = c.status == Status.RUNNING
    pose = c.state[:3]
    seen = jnp.where(p.decision_delay > 0.5, c.prev_pose, pose)  # what the scanner decides on
    paused = c.pause_left > 1e-9  # standing at a reversal: no new decision
    hit = obstacle_ahead(seen, p.shape, c.direction, omap)
    at_xs = (p.use_xs > 0.5) & c.backed & (c.direction < 0) & (seen[0] <= p.xs)
    switch = running & ~paused & (hit | at_xs)
    direction = jnp.where(switch, -c.direction, c.direction)
    n = c.n_switches + switch.astype(c.n_switches.dtype)
    i = jnp.minimum(n - 1, cfg.log_len - 1)
    logged = switch & (n <= cfg.log_len)
    log_t = jnp.where(logged, c.log_t.at[i].set(c.t), c.log_t)
    log_pose = jnp.where(logged, c.log_pose.at[i].set(pose), c.log_pose)
    cause = jnp.where(hit, int(SwitchCause.OBSTACLE), int(SwitchCause.SWITCH_POINT))
    log_cause = jnp.where(logged, c.log_cause.at[i].set(cause), c.log_cause)
    status = c.status
    if cfg.max_switches is not None:
        status = jnp.where(running & (n > cfg.max_switches), int(Status.TOO_MANY_SWITCHES), status)
    travel_at = c.travel_at
    if cfg.stuck_switches is not None:  # travel over the last K legs: now minus at the K-th last reversal
        k = cfg.stuck_switches
        slot = n % k
        stuck = switch & (n >= k) & (c.distance - travel_at[slot] < cfg.stuck_travel)
        travel_at = jnp.where(switch, travel_at.at[slot].set(c.distance), travel_at)
        status = jnp.where(running & (status == Status.RUNNING) & stuck, int(Status.STUCK), status)
    pause_left = jnp.where(switch, p.pause, c.pause_left)

    alpha = alpha_at(p.schedule, n)
    v1 = direction * p.control.speed
    h = p.scan_period / cfg.n_sub

    def rhs(_t, s, moving):
        return vector_field(s, jnp.where(moving, v1, 0.0 * v1), alpha, p.control)

    def step(_, carry):
        state, t, st, dist, left = carry
        run = st == Status.RUNNING
        moving = left <= 1e-9
        new = rk4_step(lambda tt, s: rhs(tt, s, moving), t, state, h)
        t_new = t + h
        finite = jnp.all(jnp.isfinite(new))
        code = jnp.select(
            [
                ~finite,
                jnp.abs(new[2]) >= 0.5 * math.pi,
                parking_error(new[0], new[1], new[2]) < cfg.tol,
                t_new >= cfg.t_max - 1e-9,
            ],
            [int(Status.NONFINITE), int(Status.HEADING_LIMIT), int(Status.CONVERGED), int(Status.TIMEOUT)],
            int(Status.RUNNING),
        )
        keep = run & finite
        return (
            jnp.where(keep, new, state),
            jnp.where(run, t_new, t),
            jnp.where(run, code, st),
            dist + jnp.where(run & moving, p.control.speed * h, 0.0),
            jnp.maximum(left - h, 0.0),
        )

    state, t, status, dist, pause_left = lax.fori_loop(
        0, cfg.n_sub, step, (c.state, c.t, status, c.distance, pause_left)
    )
    return Carry(
        c.k + 1,
        t,
        state,
        direction,
        n,
        c.backed | (switch & (direction < 0)),
        status,
        dist,
        log_t,
        log_pose,
        log_cause,
        pose,
        pause_left,
        travel_at,
    )


def _result(c: Carry, cfg: ParkingConfig) -> RunResult:
    status = jnp.where(c.status == Status.RUNNING, int(Status.TIMEOUT), c.status)
    x, y, th = c.state[0], c.state[1], c.state[2]
    return RunResult(
        status, c.t, c.state[:3], c.n_switches, c.distance, parking_error(x, y, th), c.log_t, c.log_pose, c.log_cause
    )


def run(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig = ParkingConfig()) -> RunResult:
    """Simulate one run until it stops (``lax.while_loop``; vmapped, it runs until every run has stopped)."""
    final = lax.while_loop(
        lambda c: (c.status == Status.RUNNING) & (c.k < cfg.max_samples),
        lambda c: _period(c, p, omap, cfg),
        _init(p, omap, cfg),
    )
    return _result(final, cfg)


def run_recorded(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig, n_periods: int) -> tuple[RunResult, Trajectory]:
    """One run with its trajectory over ``n_periods`` scanner periods (``lax.scan``), same step as :func:`run`."""

    def body(c, _):
        c2 = _period(c, p, omap, cfg)
        a = alpha_at(p.schedule, c2.n_switches)
        return c2, Trajectory(c.t, c.state, c2.direction, a, c.status == Status.RUNNING)

    final, traj = lax.scan(body, _init(p, omap, cfg), None, length=n_periods)
    return _result(final, cfg), traj


# 512-bit vectors on AVX-512 CPUs (pfjax.numerics.compiler: no XLA trigonometry in these programs)
run_jit = compiler.jit(run, static_argnums=2)
run_recorded_jit = compiler.jit(run_recorded, static_argnums=(2, 3))
run_batch = compiler.jit(jax.vmap(run, in_axes=(0, None, None)), static_argnums=2)


def n_periods_for(cfg: ParkingConfig, scan_period: float) -> int:
    return int(math.ceil(cfg.t_max / scan_period)) + 1


def _take(tree, sl):
    return jax.tree_util.tree_map(lambda a: a[sl], tree)


def run_many(
    params: RunParams,
    omap: ObstacleMap,
    cfg: ParkingConfig = ParkingConfig(),
    *,
    chunk: int = 4096,
    progress: bool = False,
    desc: str = "parking runs",
) -> RunResult:
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


def run_params(
    x0,
    direction=1,
    schedule=(1.0,),
    *,
    xs=None,
    front=None,
    scan_period=0.1,
    control=None,
    theta_in_degrees=True,
    width=None,
    length=None,
    split=None,
    zone=0.0,
    pause=0.0,
    decision_delay=False,
) -> RunParams:
    """Convenience constructor of one run's parameters (``x0 = (x m, y m, θ deg)`` by default).

    ``front``: the rectangle's reach ahead of the axle, m (default the calibrated a_f); ``split``:
    body-frame x of the boundary between its halves, m (default the middle); ``zone``: m each half's
    detection zone reaches into the other (``length``: the whole rectangle); ``pause``: s standing
    still at each reversal; ``decision_delay``: the scanner decides on the pose one period old."""
    from pfjax.parking.calibrate import A_F
    from pfjax.parking.geometry import L1_WIDTH, L2_LENGTH, robot_shape
    from pfjax.parking.model import control_params
    from pfjax.parking.schedules import pad_schedule

    x, y, th = (float(v) for v in x0)
    th = math.radians(th) if theta_in_degrees else th
    f = lambda v: jnp.asarray(v, dtype=float)
    return RunParams(
        pose0=f([x, y, th]),
        direction0=f(1.0 if direction > 0 else -1.0),
        schedule=f(pad_schedule(schedule)),
        xs=f(0.0 if xs is None else xs),
        use_xs=f(0.0 if xs is None else 1.0),
        scan_period=f(scan_period),
        control=control if control is not None else control_params(),
        shape=robot_shape(
            A_F if front is None else front,
            L1_WIDTH if width is None else width,
            L2_LENGTH if length is None else length,
            split,
            zone,
        ),
        pause=f(pause),
        decision_delay=f(1.0 if decision_delay else 0.0),
    )


def stack_params(items: list[RunParams]) -> RunParams:
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *items)


def simulated_first_switch(front: float) -> dict:
    """Case A (:data:`pfjax.parking.schedules.CASES`) simulated with reach ``front`` (m): time (s)
    and pose (m, m, deg) of its first sampled switch, to check the calibration of a_f
    (:mod:`pfjax.parking.calibrate`) against the source's point."""
    from pfjax.parking.maps import PARALLEL, to_obstacle_map

    r = run_jit(
        run_params((-0.4, 0.5, 0.0), 1, (1.0,), front=front), to_obstacle_map(list(PARALLEL.values())), ParkingConfig()
    )
    x, y, th = (float(v) for v in r.log_pose[0])
    return {"t": float(r.log_t[0]), "x": x, "y": y, "theta_deg": math.degrees(th)}
