"""Vehicle tracking with a focus point (docs/reproductions/vehicle-tracking.md; source: Ge & Lewis, ch. 8, eq. 8.4-8.7, Lemma 8.1).

Rooms: :mod:`~pfjax.tracking.model` (car-like follower with steering state, optional slip),
:mod:`~pfjax.tracking.leader` (leader motions), :mod:`~pfjax.tracking.geometry` (focus point,
virtual connection, tracking error, input matrix), :mod:`~pfjax.tracking.controller`
(input-output linearisation with limits), :mod:`~pfjax.tracking.simulate` (one scan, batched),
:mod:`~pfjax.tracking.lemma` (Lemma 8.1 checks), :mod:`~pfjax.tracking.api` (:func:`run`: one checked run
from plain arguments, the library behind ``pfjax track``).
"""

from pfjax.tracking import leader
from pfjax.tracking.api import run
from pfjax.tracking.controller import FocusGains, focus_control
from pfjax.tracking.geometry import (
    connection,
    focus_point,
    input_det,
    input_matrix,
    invertibility_factor,
    lemma_bound,
    p_bound,
    reference_point,
    tracking_error,
)
from pfjax.tracking.model import Follower, FollowerParams, follower_rhs
from pfjax.tracking.simulate import (
    TRACK_STATUS_NAMES,
    SensorNoise,
    TrackConfig,
    TrackScenario,
    TrackStatus,
    initial_state,
    initial_states,
    scenario,
    simulate,
    simulate_batch,
    simulate_one,
    stack,
    unstack,
)

__all__ = [
    "TRACK_STATUS_NAMES",
    "FocusGains",
    "Follower",
    "FollowerParams",
    "SensorNoise",
    "TrackConfig",
    "TrackScenario",
    "TrackStatus",
    "connection",
    "focus_control",
    "focus_point",
    "follower_rhs",
    "initial_state",
    "initial_states",
    "input_det",
    "input_matrix",
    "invertibility_factor",
    "leader",
    "lemma_bound",
    "p_bound",
    "reference_point",
    "run",
    "scenario",
    "simulate",
    "simulate_batch",
    "simulate_one",
    "stack",
    "tracking_error",
    "unstack",
]
