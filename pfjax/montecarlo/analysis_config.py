"""The analysis sections of a Monte Carlo study's config: the slip-margin sweep, the worst-case
search (falsifier) and the rare-event estimate (:mod:`pfjax.montecarlo.config`)."""

from __future__ import annotations

from typing import Literal, get_args

from pydantic import Field, field_validator, model_validator

from pfjax.config import POSITIVE, ConfigModel, Real
from pfjax.errors import MAX_SEED

Axis = Literal["rear", "front", "joint"]
"""A slipping axle in the slip-margin sweep: rear, front, or joint (both)."""


class MarginSpec(ConfigModel):
    """Slip-margin sweep: at each amplitude A, ``n_per_amplitude`` runs per path with constant slip of
    magnitude A (random sign) on the rear axle, the front axle, or both (``axes``); everything else
    sampled as in the study. The margin is the largest A whose success rate (and every smaller A's)
    stays >= 1 - eps."""

    enabled: bool = Field(True, description="run the slip-margin sweep")
    amplitudes_deg: list[Real] = Field(
        default_factory=lambda: [0.0, 2.5, 5.0, 7.5, 10.0, 12.5, 15.0, 17.5, 20.0, 25.0, 30.0],
        description="slip amplitudes A swept, deg",
    )
    n_per_amplitude: int = Field(200, ge=1, le=100_000_000, description="runs per amplitude, path, controller and axis")
    eps: Real = Field(
        0.05,
        ge=POSITIVE,
        lt=1,
        description="tolerated failure rate: the margin is the largest A with success >= 1 - eps",
    )
    axes: list[Axis] = Field(
        default_factory=lambda: list(get_args(Axis)), description="slipping axles: rear, front, joint (both)"
    )

    @field_validator("amplitudes_deg")
    @classmethod
    def _amps(cls, v):
        if not v or any(not (0 <= a < 90) for a in v) or len(set(v)) != len(v):
            raise ValueError(f"must be distinct amplitudes in [0, 90) deg, got {v}")
        return sorted(v)

    @field_validator("axes")
    @classmethod
    def _axes(cls, v):
        if not v or len(set(v)) != len(v):  # a repeated axis would count its runs twice
            raise ValueError(f"must be distinct axes of {', '.join(get_args(Axis))}, at least one, got {v}")
        return v

    @model_validator(mode="after")
    def _check(self):
        if self.n_per_amplitude * len(self.amplitudes_deg) > 100_000_000:
            raise ValueError(
                f"n_per_amplitude: at most 1e8 runs per axis and path (n_per_amplitude x "
                f"{len(self.amplitudes_deg)} amplitudes), got {self.n_per_amplitude * len(self.amplitudes_deg):.3g}"
            )
        return self


class FalsifierSpec(ConfigModel):
    """Worst-case search per controller (pfjax.falsification): gradient ascent over slip profiles bounded by
    ``slip_bound_deg`` with frequencies up to ``f_max_hz`` and initial errors in the boxes
    +-``lateral_offset`` m, +-``heading_error_deg``, on one path (its run 0's shape and vehicle),
    against random search with the same number of rollouts."""

    enabled: bool = Field(False, description="run the worst-case search")
    path: str | None = Field(None, description="label of the path searched (default: the first path)")
    slip_bound_deg: Real = Field(10.0, ge=POSITIVE, lt=90, description="bound on each axle's slip, deg")
    f_max_hz: Real = Field(0.5, ge=0, le=10, description="slip bandwidth, Hz (0: constant slip)")
    lateral_offset: Real = Field(0.5, ge=0, description="start offsets searched within +-this, m")
    heading_error_deg: Real = Field(30.0, ge=0, lt=90, description="start heading errors searched within +-this, deg")
    objective: Literal["iae", "ise", "itae", "max_abs_d", "late_max_abs_d"] = Field(
        "iae", description="what the search maximises"
    )
    n_restarts: int = Field(8, ge=1, le=256, description="random starts of the gradient ascent")
    steps: int = Field(40, ge=1, le=10_000, description="adam steps per start")


class RareEventSpec(ConfigModel):
    """Small failure probabilities per controller (:mod:`pfjax.rare`): a run fails where its status is
    a failure or ``metric >= threshold`` (margin ``<= 0``); the estimator works on the margin ``threshold - metric``
    over the study's uncertain inputs mapped to the standard-normal space (choices and paths as
    strata, :mod:`pfjax.rare.transform`)."""

    enabled: bool = Field(False, description="estimate each controller's failure probability")
    method: Literal["is", "subset", "mc"] = Field(
        "is", description="is (cross-entropy importance sampling), subset (subset simulation) or mc (plain)"
    )
    metric: Literal["late_max_abs_d", "max_abs_d", "steady_abs_d", "iae", "ise", "overshoot"] = Field(
        "late_max_abs_d", description="per-run metric whose excess over threshold is a failure"
    )
    threshold: Real | None = Field(
        None,
        ge=0,
        description="failure where metric >= threshold (metric's unit); default success.band (m), for a metric "
        "in m only: iae and ise need one",
    )
    target_rel_error: Real = Field(
        0.1,
        gt=0,
        le=10,
        description="is, subset: stop once the estimate's relative error (c.o.v.) is at most this "
        "(mc runs all of max_rollouts, its strata's even shares)",
    )
    max_rollouts: int = Field(
        100_000,
        ge=100,
        le=100_000_000,
        description="rollouts per controller, split evenly over the strata (subset simulation completes a run it "
        "has started, the first one always)",
    )
    n_per_level: int = Field(
        2000, ge=100, le=10_000_000, description="is / subset: rollouts per cross-entropy or subset level"
    )
    n_components: int = Field(4, ge=1, le=64, description="is: Gaussians in the proposal mixture")
    starts: Literal["explore", "falsifier", "none"] = Field(
        "explore",
        description="is: the first proposal's centres: failure points of a widened input law (explore), "
        "of the gradient falsifier mapped to the inputs (falsifier), or none (N(0, I))",
    )
    check: Literal["none", "subset"] = Field(
        "none",
        description="is: a second estimate by subset simulation (same target and budget, its rollouts "
        "beside the estimate's); a disagreement beyond the two 95 % intervals, or one draw carrying "
        "over 10 % of the estimate, sets the controller's status and warning",
    )
    tie_break: Literal["iae", "ise", "itae", "max_abs_d", "steer_energy", "sat_fraction"] | None = Field(
        "iae", description="subset: metric that orders runs of equal margin (larger: nearer failure)"
    )
    margin_resolution: Real = Field(
        0.0, ge=0, description="subset: positive margins rounded up to multiples of this (metric's unit; ties)"
    )
    batch: int = Field(2000, ge=32, le=1_000_000, description="runs simulated at once (one compiled shape)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="seed of the estimator's draws")

    @model_validator(mode="after")
    def _check(self):
        from pfjax.tables import COLUMNS

        unit = COLUMNS[self.metric][0]
        if self.threshold is None and unit != "m":  # the default, success.band, is a distance
            raise ValueError(
                f"threshold: needed for metric = {self.metric!r} ({unit}); the default, success.band, is in m "
                "and serves only a metric in m"
            )
        if (self.method == "subset" or self.check == "subset") and self.n_per_level % 10:
            raise ValueError(f"n_per_level: subset simulation needs a multiple of 10, got {self.n_per_level}")
        return self
