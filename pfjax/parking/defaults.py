"""The parking subsystem's defaults and the source's fixed numbers, each written here once.

The simulator (:func:`pfjax.parking.model.control_params`, :class:`pfjax.parking.runs.ParkingConfig`,
:func:`pfjax.parking.runs.run_params`), the searches (:mod:`pfjax.parking.switch_search`), the entry
points (:func:`pfjax.parking.run`, :func:`pfjax.parking.search`, ``pfjax parking`` and
``pfjax parking-search``) and the study's config schema (:mod:`pfjax.parking.study_config`) read
them from here. Imports only :mod:`dataclasses`, so the entry points that read it stay cheap (no JAX).
"""

from __future__ import annotations

from dataclasses import dataclass

# The source's controller (docs/reproductions/parking.md §2).
#: 1/m², gain on y (with :data:`K2`, the roots −4 ± 4i)
K1 = 32.0
#: 1/m, gain on tan θ
K2 = 8.0
#: m/s, travel speed |v₁|
SPEED = 0.05
#: -, the experiments' yaw-rate PI loop: proportional gain k_P
KP = 0.8
#: 1/s, its integral gain k_I
KI = 16.0

# The source's robot (docs/reproductions/parking.md §3).
#: m, width L₁ of the robot's rectangle
L1_WIDTH = 0.370
#: m, length L₂ of the robot's rectangle
L2_LENGTH = 0.540
#: the garage's start pose (x m, y m, θ deg)
GARAGE_START = (-0.9, 0.6, -85.0)

# One run (:class:`pfjax.parking.runs.ParkingConfig`).
#: s, the scanner's sampling period (the source's hardware)
SCAN_PERIOD = 0.1
#: s, a run's timeout
T_MAX = 200.0
#: m (with tan θ's 1), stop when ``|x| + sqrt(y² + tan²θ) < TOL``
TOL = 0.02
#: -, RK4 steps per scanner period
N_SUB = 2
#: -, legs between reversals over which a run's travel is measured for ``stuck``
STUCK_SWITCHES = 4
#: m, travel over those legs below which a run is stuck (2 s at 0.05 m/s)
STUCK_TRAVEL = 0.1
#: runs per jitted batch of the searches, the Monte Carlo and the study
CHUNK = 1024

# The garage and its search (docs/reproductions/parking.md §4-5).
#: m, the source's garage tries of the switching point X_s; the first is the garage rule's default
GARAGE_TRIES = (-0.9, -1.2, -1.8)
#: m, X_s of a run on the built-in garage unless given
GARAGE_XS = GARAGE_TRIES[0]
#: s/m, weight w of the end error in the search's fitness J = 1 / (t_e + w e)
WEIGHT = 100.0
#: -, grid levels per schedule parameter of the grid search
GRID_N = 32
#: -, most grid levels per schedule parameter
MAX_GRID_N = 64
#: -, the GA's population size n (the source's)
POPULATION = 20
#: -, the GA's generations N (the source's)
GENERATIONS = 100
#: -, the GA search's cut-off: a candidate switching more often fails (the source's)
SEARCH_MAX_SWITCHES = 10

# The experiments and the assumptions sweep (docs/reproductions/parking.md §3).
#: s, the source's experiments stood still this long at each reversal
EXPERIMENT_PAUSE = 1.0
#: the open assumptions swept over cases A-D (:func:`pfjax.parking.assumptions.case_sweep`):
#: front m, zone, scan_period s, decision_delay, lag, pause s
ASSUMPTION_GRID: dict[str, tuple] = {
    "front": (0.10, 0.125, 0.15, 0.175, 0.20, 0.225, 0.25),
    "zone": ("middle", "axle", "whole"),
    "scan_period": (0.05, SCAN_PERIOD, 0.2),
    "decision_delay": (False, True),
    "lag": (False, True),
    "pause": (0.0, EXPERIMENT_PAUSE),
}


@dataclass(frozen=True)
class Scatter:
    """The robustness Monte Carlo's distributions (:mod:`pfjax.parking.montecarlo`), all uniform:
    start x₀, y₀ ± ``pos_scatter`` m, θ₀ ± ``theta_scatter_deg`` deg, scanner period in
    [``scan_lo``, ``scan_hi``] s, speed in [``speed_lo``, ``speed_hi``] m/s, and the yaw-rate PI loop
    on with probability ``lag_probability``."""

    pos_scatter: float = 0.05  # m
    theta_scatter_deg: float = 5.0  # deg
    scan_lo: float = 0.05  # s
    scan_hi: float = 0.2  # s
    speed_lo: float = 0.04  # m/s
    speed_hi: float = 0.06  # m/s
    lag_probability: float = 0.5  # -
