"""Run status codes: a failed run is data, never an exception (diffrax ``RESULTS`` style).

The first failure wins; from that sample on the state is frozen and the metrics stop
accumulating, so the metrics describe the run up to its failure (:mod:`pfjax.sim.loop`, whose
docstring has the one status table of every system on the loop).
"""

from __future__ import annotations

from enum import IntEnum

import jax.numpy as jnp

from pfjax.numerics import elementary as E
from pfjax.numerics.layout import first_true

#: A sample is ``singular`` when ``1 - kappa d <= SINGULAR_TOL`` (dimensionless; ``kappa`` in 1/m,
#: ``d`` in m): the Frenet model's valid region ends at or past the bend's centre, where ``1 - kappa d = 0``.
SINGULAR_TOL = 1e-6


class Status(IntEnum):
    OK = 0  #: ran the whole horizon
    NONFINITE = 1  #: a state or measurement became NaN or infinite
    DIVERGED = 2  #: |d| exceeded ``SimConfig.d_fail``
    SINGULAR = 3  #: left the Frenet model's valid region, 1 - kappa d <= SINGULAR_TOL (at or past the bend's centre)
    PATH_END = 4  #: the closest point reached an end of the path's valid domain


STATUS_NAMES = {int(s): s.name.lower() for s in Status}


def classify(finite, abs_d, one_minus_kd, at_end, d_fail: float):
    """Status of one sample (int32), the first that holds winning: non-finite; the path's end (the
    closest point held at the end of the path's domain, where ``d`` is the distance to that end
    point and ``kappa`` the end's, no longer Frenet quantities: a start beyond the end is
    ``path_end``, not a divergence); diverged; singular (``one_minus_kd = 1 - kappa d <= SINGULAR_TOL``)."""
    return first_true(
        [~finite, at_end, abs_d > d_fail, one_minus_kd <= SINGULAR_TOL],
        [Status.NONFINITE, Status.PATH_END, Status.DIVERGED, Status.SINGULAR],
        jnp.int32(Status.OK),
    )


def first_failure(status, fail_time, now, t, live=Status.OK):
    """``(status, fail_time)`` after a sample whose own status is ``now`` (time ``t``, s): the first
    status other than ``live`` wins, and ``fail_time`` keeps its sample time. ``live`` is the code of
    a run still going: ``OK`` (0) for :class:`Status` and the tracking simulator's ``TrackStatus``,
    ``RUNNING`` (-1) for the parking robot's ``pfjax.parking.simulate.Status``.

    ``status`` is carried as a *float* code (``Status`` values are small integers, exact in any float
    type; convert to int32 for output) so that it can be computed once
    (:func:`pfjax.numerics.elementary.computed_once`): every value a simulator step freezes or
    accumulates reads whether the run is still live, and XLA's CPU backend would otherwise recompute
    the status checks (finiteness, distances, the Frenet singularity, the path's end) in each kernel
    that reads it, and the failure time from the checks again. Measured on the benchmark (README, Performance): float32 about 5 %
    more rollout-steps/s. Values are exact.
    """
    ok = status == live
    new = E.computed_once(jnp.where(ok, jnp.asarray(now).astype(status.dtype), status))
    return new, jnp.where(ok & (new != live), t, fail_time)
