"""What a parking run is: its settings, parameters, statuses and results (docs/reproductions/parking.md §3).

The simulation itself is :mod:`pfjax.parking.period` (one scanner period, a system on the one loop
:mod:`pfjax.sim.loop`) and its entry points :mod:`pfjax.parking.simulate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import NamedTuple

import jax
import jax.numpy as jnp

from pfjax.parking import defaults as D
from pfjax.parking.calibrate import A_F
from pfjax.parking.geometry import L1_WIDTH, L2_LENGTH, RobotShape, robot_shape
from pfjax.parking.limits import MAX_PERIODS
from pfjax.parking.model import ControlParams, control_params
from pfjax.parking.schedules import pad_schedule

Array = jnp.ndarray


class Status(IntEnum):
    """A run's status (codes in the one status table of :mod:`pfjax.sim.loop`)."""

    RUNNING = -1  #: internal only (the loop's live code)
    CONVERGED = 0  #: |x| + sqrt(y² + tan²θ) < tol
    TIMEOUT = 1  #: not converged by t_max (200 s)
    TOO_MANY_SWITCHES = 2  #: more than max_switches direction switches (the GA search's cut-off only)
    HEADING_LIMIT = 3  #: |θ| ≥ π/2, where the controller is undefined
    NONFINITE = 4  #: the state became NaN or infinite
    STUCK = 5  #: reversing repeatedly without progress (see :mod:`pfjax.parking.simulate`)
    START_OVERLAP = 6  #: the robot's rectangle meets an obstacle at the start pose (not simulated)


STATUS_NAMES = {int(s): s.name.lower() for s in Status if s is not Status.RUNNING}


class SwitchCause(IntEnum):
    NONE = 0
    OBSTACLE = 1  #: an obstacle entered the travel-side half of the rectangle
    SWITCH_POINT = 2  #: the garage rule, x ≤ X_s while backing


@dataclass(frozen=True)
class ParkingConfig:
    """Settings that fix shapes and loop lengths (static under jit); defaults from
    :mod:`pfjax.parking.defaults`.

    Attributes:
        t_max: timeout, s.
        max_switches: fail a run at its (max_switches + 1)-th reversal (``TOO_MANY_SWITCHES``);
            None: no cut-off. The GA search uses 10 (:data:`SEARCH_MAX_SWITCHES`).
        tol: stop when ``|x| + sqrt(y² + tan²θ) < tol``.
        n_sub: RK4 steps per scanner period (0.05 s at T_s = 0.1 s; n_sub = 10 agrees, see tests).
        max_samples: the loop's bound, scanner periods: at least :func:`periods_needed` of every
            run, so that each run ends by an event or at ``t_max`` (the default,
            ``MAX_PERIODS + 1``, covers every ``t_max / scan_period <= MAX_PERIODS`` the entry
            points accept; :func:`pfjax.parking.simulate.run_many` refuses a run that needs more).
        stuck_switches: the legs between reversals over which travel is measured (``stuck``,
            :mod:`pfjax.parking.simulate`); None disables the status.
        stuck_travel: m, travel over those legs below which a run is stuck (0.1 m: 2 s at the
            source's 0.05 m/s, against legs of 0.2-0.7 m when it parks).
        log_capacity: switches logged when there is no cut-off.
    """

    t_max: float = D.T_MAX
    max_switches: int | None = None
    tol: float = D.TOL
    n_sub: int = D.N_SUB
    max_samples: int = MAX_PERIODS + 1
    stuck_switches: int | None = D.STUCK_SWITCHES
    stuck_travel: float = D.STUCK_TRAVEL
    log_capacity: int = 32

    @property
    def log_len(self) -> int:
        return self.log_capacity if self.max_switches is None else self.max_switches + 1


def run_bytes(log_len: int) -> int:
    """An upper estimate of the bytes one run of a batch holds (float64): its :class:`RunResult`
    (8 numbers and a switch log of ``log_len`` entries of 5 numbers), and as much again three
    times for the loop's carry and the compiled program's temporaries."""
    return 4 * 8 * (8 + 5 * int(log_len))


def periods_needed(t_max: float, scan_period: float) -> int:
    """The most scanner periods a run of timeout ``t_max`` (s) at period ``scan_period`` (s) takes:
    ``ceil(t_max / scan_period)``, and one more for the rounding of the accumulated time."""
    return math.ceil(t_max / scan_period) + 1


#: The GA search's cut-off (docs/reproductions/parking.md §5): more than 10 switches and the candidate counts as failed.
SEARCH_MAX_SWITCHES = D.SEARCH_MAX_SWITCHES


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


def run_params(
    x0,
    direction=1,
    schedule=(1.0,),
    *,
    xs=None,
    front=None,
    scan_period=D.SCAN_PERIOD,
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
