"""One parking run as a pure, jittable, vmappable function on the one loop; batched entry points.

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
* ``timeout``: ``t ≥ t_max`` (200 s; the loop's bound :attr:`ParkingConfig.max_samples` covers
  every run's ``t_max / scan_period``, so no run ends before ``t_max`` other than by an event);
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

A run is the system :func:`pfjax.parking.period.system` on the one loop, run until done
(:func:`pfjax.sim.loop.run` with ``until_done``: a ``lax.while_loop`` over scanner periods; the
recorded run a ``lax.scan`` over ``n_periods``). Its types and statuses are in
:mod:`pfjax.parking.runs` (re-exported here).

Speed on the one loop, against a ``lax.while_loop`` of parking's own over the same period with an
integer status and its own period counter (the structure of ``own_while_loop`` in
``tests/test_parking_loop.py``; results bit-identical): ``run_batch`` in one process, the two
alternating over 15 rounds, float64, jax 0.10.2, a 2-core AMD EPYC (AVX-512) shared with other
jobs. CPU time (``time.process_time``), loop / own, least and median round: the garage Monte
Carlo (1,024 runs, :func:`pfjax.parking.montecarlo.sample`, default settings) 0.996 and 0.987; a
GA population (20 random chromosomes, the search's settings) 0.951 and 0.959. The Monte Carlo's
wall-clock ratios of the least rounds over three sittings scattered 0.94-1.11 with the machine's
load (6 on 2 cores), the medians 0.79-1.19: no cost beyond noise.
"""

from __future__ import annotations

import math

import jax
import numpy as np

from pfjax.errors import InputError
from pfjax.numerics import compiler
from pfjax.parking.defaults import SCAN_PERIOD
from pfjax.parking.geometry import ObstacleMap
from pfjax.parking.maps import PARALLEL, to_obstacle_map
from pfjax.parking.period import system
from pfjax.parking.runs import (  # noqa: F401  (re-exported: the run's types, statuses and constructors)
    SEARCH_MAX_SWITCHES,
    STATUS_NAMES,
    ParkingConfig,
    RunParams,
    RunResult,
    Status,
    SwitchCause,
    Trajectory,
    periods_needed,
    run_params,
    stack_params,
)
from pfjax.parking.schedules import CASES
from pfjax.sim import loop


def run(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig = ParkingConfig()) -> RunResult:
    """Simulate one run until it stops (a ``lax.while_loop``; vmapped, it runs until every run has stopped)."""
    return loop.run(system(omap, cfg), p, cfg.max_samples, record=False, until_done=True)


def run_recorded(p: RunParams, omap: ObstacleMap, cfg: ParkingConfig, n_periods: int) -> tuple[RunResult, Trajectory]:
    """One run with its trajectory over ``n_periods`` scanner periods (``lax.scan``), same period as :func:`run`."""
    return loop.run(system(omap, cfg), p, n_periods, record=True, until_done=True)


# 512-bit vectors on AVX-512 CPUs (pfjax.numerics.compiler: no XLA trigonometry in these programs)
run_jit = compiler.jit(run, static_argnums=2)
run_recorded_jit = compiler.jit(run_recorded, static_argnums=(2, 3))
run_batch = compiler.jit(jax.vmap(run, in_axes=(0, None, None)), static_argnums=2)


def n_periods_for(cfg: ParkingConfig, scan_period: float) -> int:
    """Scanner periods to record for a run at ``scan_period`` (s): :func:`periods_needed`."""
    return periods_needed(cfg.t_max, scan_period)


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
    so every call with the same ``chunk`` reuses one compilation); NumPy out, in input order.

    Raises:
        InputError: (``scan_period``) a run needs more scanner periods than ``cfg.max_samples``
            (:func:`periods_needed`): it would be cut off before ``t_max``.
    """
    n = int(params.pose0.shape[0])
    shortest = float(np.min(np.asarray(params.scan_period))) if n else math.inf
    if n and periods_needed(cfg.t_max, shortest) > cfg.max_samples:
        raise InputError(
            f"scan_period: a run of t_max {cfg.t_max:g} s at {shortest:g} s takes up to "
            f"{periods_needed(cfg.t_max, shortest)} scanner periods, more than max_samples = {cfg.max_samples}",
            "scan_period",
        )
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


def simulated_first_switch(
    front: float, *, control=None, scan_period: float = SCAN_PERIOD, cfg: ParkingConfig = ParkingConfig()
) -> dict:
    """Case A (:data:`pfjax.parking.schedules.CASES`) simulated with reach ``front`` (m), the
    controller ``control`` (default the source's), scanner period ``scan_period`` (s) and run
    config ``cfg``: time (s) and pose (m, m, deg) of its first sampled switch, to check the
    calibration of a_f (:mod:`pfjax.parking.calibrate`) against the source's point."""
    a = CASES["A"]
    p = run_params(a["x0"], a["direction"], a["schedule"], front=front, scan_period=scan_period, control=control)
    r = run_jit(p, to_obstacle_map(list(PARALLEL.values())), cfg)
    x, y, th = (float(v) for v in r.log_pose[0])
    return {"t": float(r.log_t[0]), "x": x, "y": y, "theta_deg": math.degrees(th)}
