"""One scanner period of a parking run, and the run as a system on the one loop (:mod:`pfjax.sim.loop`).

A period of length T_s (docs/reproductions/parking.md §3) is :func:`decide` — the direction-switch
decision, logged, with the cut-off and ``stuck`` checks — then :func:`integrate` — ``n_sub`` RK4
steps of :func:`pfjax.parking.model.vector_field` with direction and α held, each followed by the
stop checks (converged, heading limit, non-finite, timeout; :mod:`pfjax.parking.simulate`).

On the loop (:func:`system`): one sample is one period; the loop owns the status (``RUNNING`` the
live code, :class:`pfjax.parking.runs.Status` in the loop's status table) and the period count; the
rest of the run's carry is :class:`Carry`, the loop's unfrozen ``aux``, because a period that ends in
a stop keeps the RK4 steps up to the stop (the steps freeze themselves one by one).
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple

import jax.numpy as jnp
from jax import lax

from pfjax.parking.geometry import ObstacleMap, obstacle_ahead
from pfjax.parking.model import parking_error, vector_field
from pfjax.parking.runs import ParkingConfig, RunParams, RunResult, Status, SwitchCause, Trajectory
from pfjax.parking.schedules import alpha_at
from pfjax.sim import loop
from pfjax.sim.integrators import rk4_step

Array = jnp.ndarray


class Carry(NamedTuple):
    """A parking run's carry between periods (the loop's ``aux``; status and period count are the loop's)."""

    t: Array  # s
    state: Array  # (4,) x, y, θ, q (PI integrator, rad)
    direction: Array  # ±1
    n_switches: Array  # int
    backed: Array  # bool: has switched to backward once
    distance: Array  # m travelled
    log_t: Array  # (M,) s, NaN where unused
    log_pose: Array  # (M, 3) pose at each switch
    log_cause: Array  # (M,) SwitchCause
    prev_pose: Array  # (3,) pose at the start of the previous period (the delayed scanner's view)
    pause_left: Array  # s still to stand at the current reversal
    travel_at: Array  # (K,) m travelled at the last K reversals, a ring (stuck test)


class Before(NamedTuple):
    """A period's start, as recorded (:class:`pfjax.parking.runs.Trajectory`)."""

    t: Array  # s
    state: Array  # (4,)
    running: Array  # bool


def start(omap: ObstacleMap, cfg: ParkingConfig, p: RunParams) -> loop.Start:
    """The run at t = 0: status ``START_OVERLAP`` if the rectangle meets an obstacle, else ``RUNNING``."""
    m = cfg.log_len
    dt = p.pose0.dtype
    overlap = obstacle_ahead(p.pose0, p.shape, 1.0, omap) | obstacle_ahead(p.pose0, p.shape, -1.0, omap)
    carry = Carry(
        t=jnp.asarray(0.0, dt),
        state=jnp.concatenate([p.pose0, jnp.zeros(1, dt)]),
        direction=jnp.asarray(p.direction0, dt),
        n_switches=jnp.asarray(0),
        backed=jnp.asarray(False),
        distance=jnp.asarray(0.0, dt),
        log_t=jnp.full(m, jnp.nan, dt),
        log_pose=jnp.full((m, 3), jnp.nan, dt),
        log_cause=jnp.zeros(m, jnp.int32),
        prev_pose=p.pose0,
        pause_left=jnp.asarray(0.0, dt),
        travel_at=jnp.zeros(max(cfg.stuck_switches or 1, 1), dt),
    )
    status = jnp.where(overlap, int(Status.START_OVERLAP), int(Status.RUNNING)).astype(dt)
    return loop.Start(state=(), metrics=None, zero=jnp.zeros((), dt), aux=carry, status=status)


def decide(c: Carry, status, p: RunParams, omap: ObstacleMap, cfg: ParkingConfig) -> tuple[Carry, Array]:
    """The switch decision at a period's start: reverse when an obstacle lies in the travel-side half
    (on the pose the scanner sees), or by the garage rule (backing after a first switch to backward,
    ``x ≤ X_s``); log the switch; fail the run by the cut-off or as ``stuck``. Returns the carry with
    direction, count, log, ring and pause set, and the status (float code)."""
    running = status == Status.RUNNING
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
    cause = jnp.where(hit, int(SwitchCause.OBSTACLE), int(SwitchCause.SWITCH_POINT))
    if cfg.max_switches is not None:
        status = jnp.where(running & (n > cfg.max_switches), int(Status.TOO_MANY_SWITCHES), status)
    travel_at = c.travel_at
    if cfg.stuck_switches is not None:  # travel over the last K legs: now minus at the K-th last reversal
        slot = n % cfg.stuck_switches
        stuck = switch & (n >= cfg.stuck_switches) & (c.distance - travel_at[slot] < cfg.stuck_travel)
        travel_at = jnp.where(switch, travel_at.at[slot].set(c.distance), travel_at)
        status = jnp.where(running & (status == Status.RUNNING) & stuck, int(Status.STUCK), status)
    decided = c._replace(
        direction=direction,
        n_switches=n,
        backed=c.backed | (switch & (direction < 0)),
        log_t=jnp.where(logged, c.log_t.at[i].set(c.t), c.log_t),
        log_pose=jnp.where(logged, c.log_pose.at[i].set(pose), c.log_pose),
        log_cause=jnp.where(logged, c.log_cause.at[i].set(cause), c.log_cause),
        prev_pose=pose,
        pause_left=jnp.where(switch, p.pause, c.pause_left),
        travel_at=travel_at,
    )
    return decided, status


#: The timeout's step is the first whole step at or after ``t_max`` less this fraction of a step
#: (the rounding of ``t_max / h``).
TIME_SLACK = 1e-6


def stop_code(new, t_new, h, cfg: ParkingConfig):
    """The status after one RK4 step of ``h`` (s) to state ``new`` at ``t_new`` (s): the first stop
    that holds; the timeout from the first whole step at or after ``t_max`` on, counted in steps
    (``round(t_new / h) >= ceil(t_max / h - TIME_SLACK)``: a run starts at t = 0 and its time
    advances by ``h`` per step, so the count is exact although the accumulated time rounds, by
    several float32 ulps after hundreds of steps; a run of any scanner period and precision times
    out at ``t_max``, never one step before or after)."""
    return jnp.select(
        [
            ~jnp.all(jnp.isfinite(new)),
            jnp.abs(new[2]) >= 0.5 * math.pi,
            parking_error(new[0], new[1], new[2]) < cfg.tol,
            jnp.round(t_new / h) >= jnp.ceil(cfg.t_max / h - TIME_SLACK),
        ],
        [int(Status.NONFINITE), int(Status.HEADING_LIMIT), int(Status.CONVERGED), int(Status.TIMEOUT)],
        int(Status.RUNNING),
    )


def integrate(c: Carry, status, p: RunParams, cfg: ParkingConfig) -> tuple[Carry, Array]:
    """``n_sub`` RK4 steps of h = T_s / n_sub with direction and α held, standing still while a
    pause is left; each step is kept while the run is running (a non-finite one is not) and stops
    it by :func:`stop_code`. Returns the carry and the status after the period."""
    alpha = alpha_at(p.schedule, c.n_switches)
    v1 = c.direction * p.control.speed
    h = p.scan_period / cfg.n_sub

    def step(_, carry):
        state, t, st, dist, left = carry
        run = st == Status.RUNNING
        moving = left <= 1e-9
        v = jnp.where(moving, v1, 0.0 * v1)
        new = rk4_step(lambda _t, s: vector_field(s, v, alpha, p.control), t, state, h)
        keep = run & jnp.all(jnp.isfinite(new))
        return (
            jnp.where(keep, new, state),
            jnp.where(run, t + h, t),
            jnp.where(run, stop_code(new, t + h, h, cfg), st),
            dist + jnp.where(run & moving, p.control.speed * h, 0.0),
            jnp.maximum(left - h, 0.0),
        )

    state, t, status, dist, left = lax.fori_loop(0, cfg.n_sub, step, (c.state, c.t, status, c.distance, c.pause_left))
    return c._replace(t=t, state=state, distance=dist, pause_left=left), status


def _step(omap: ObstacleMap, cfg: ParkingConfig, p: RunParams, carry: loop.LoopCarry, k) -> loop.Sample:
    c = carry.aux
    decided, status = decide(c, carry.status, p, omap, cfg)
    after, status = integrate(decided, status, p, cfg)
    return loop.Sample((), status, after.t, Before(c.t, c.state, carry.status == Status.RUNNING), after)


def _record(p: RunParams, s: loop.Sample, _state) -> Trajectory:
    c = s.aux
    return Trajectory(s.out.t, s.out.state, c.direction, alpha_at(p.schedule, c.n_switches), s.out.running)


def _finish(p: RunParams, r: loop.Run):
    """The run's result; a run still going when the loop ends has reached ``t_max`` (``timeout``):
    ``cfg.max_samples`` and a recording's ``n_periods`` cover :func:`pfjax.parking.runs.periods_needed`."""
    c = r.aux
    status = jnp.where(r.status == Status.RUNNING, int(Status.TIMEOUT), r.status).astype(c.n_switches.dtype)
    x, y, th = c.state[0], c.state[1], c.state[2]
    error = parking_error(x, y, th)
    result = RunResult(status, c.t, c.state[:3], c.n_switches, c.distance, error, c.log_t, c.log_pose, c.log_cause)
    return result if r.records is None else (result, r.records)


def system(omap: ObstacleMap, cfg: ParkingConfig) -> loop.System:
    """A parking run on the one loop (inputs: :class:`pfjax.parking.runs.RunParams`; run it with ``until_done``)."""
    return loop.System(
        init=partial(start, omap, cfg),
        step=partial(_step, omap, cfg),
        update=lambda p, metrics, s, live, was_live: metrics,
        record=_record,
        finish=_finish,
        no_failure=math.nan,
        live=int(Status.RUNNING),
    )
