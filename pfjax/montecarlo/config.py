"""Monte Carlo study configuration: a TOML file validated by pydantic, with ``--set`` overrides.

Every uncertain quantity is a *distribution*: a bare number (constant) or a table::

    beta_r_deg = {dist = "uniform", low = -10, high = 10}
    speed      = {dist = "normal", mean = 1.0, std = 0.05}
    L          = {dist = "truncnormal", mean = 0.2, std = 0.01, low = 0.18, high = 0.22}
    start_along_m    = {dist = "choice", values = [0.0, 1.0, 2.0]}

Angles are in degrees where the key says ``_deg``, everything else SI. Errors are
:class:`pfjax.config.ConfigError` with one line naming the dotted key, the value and what was
expected (with a "did you mean" for unknown keys).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any, ClassVar, Literal, get_args

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from pfjax.config import ConfigError, _short, nested, parse_override, read_toml
from pfjax.errors import MAX_MAGNITUDE, MAX_SEED, MIN_POSITIVE
from pfjax.provenance import config_hash
from pfjax.resources import check_steps


def _real(v: float) -> float:
    if not math.isfinite(v):
        raise ValueError(f"expected a finite number, got {v}")
    if abs(v) > MAX_MAGNITUDE:
        raise ValueError(f"expected a magnitude <= {MAX_MAGNITUDE:g}, got {v:g}")
    return v


#: A number as every study key takes it: finite, magnitude at most :data:`pfjax.errors.MAX_MAGNITUDE`
#: (booleans and strings are not numbers: the schema is strict).
Real = Annotated[float, AfterValidator(_real)]
#: A positive step, length or tolerance: at least :data:`pfjax.errors.MIN_POSITIVE`.
POSITIVE = MIN_POSITIVE


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)
    #: old key -> new key: an old spelling is read for one release, with a deprecation warning
    RENAMED: ClassVar[dict[str, str]] = {}

    @model_validator(mode="before")
    @classmethod
    def _renamed(cls, data):
        if cls.RENAMED and isinstance(data, dict) and any(k in data for k in cls.RENAMED):
            from pfjax.errors import deprecated

            data = dict(data)
            for old, new in cls.RENAMED.items():
                if old in data:
                    if new in data:
                        raise ValueError(f"{old}: the old name of {new}; give only {new}")
                    deprecated(old, new)
                    data[new] = data.pop(old)
        return data


Axis = Literal["rear", "front", "joint"]
"""A slipping axle in the slip-margin sweep: rear, front, or joint (both)."""


class Dist(_Model):
    """A distribution of one scalar (see module docstring)."""

    dist: Literal["constant", "uniform", "normal", "truncnormal", "choice"]
    value: Real | None = None
    low: Real | None = None
    high: Real | None = None
    mean: Real | None = None
    std: Real | None = None
    values: list[Real] | None = None

    @model_validator(mode="after")
    def _check(self):
        need = {
            "constant": ("value",),
            "uniform": ("low", "high"),
            "normal": ("mean", "std"),
            "truncnormal": ("mean", "std", "low", "high"),
            "choice": ("values",),
        }[self.dist]
        for f in need:
            if getattr(self, f) is None:
                raise ValueError(f"dist '{self.dist}' needs '{f}'")
        for f in ("value", "low", "high", "mean", "std", "values"):
            if f not in need and getattr(self, f) is not None:
                raise ValueError(f"dist '{self.dist}' does not use '{f}' (it takes {', '.join(need)})")
        for f in ("value", "low", "high", "mean", "std"):
            v = getattr(self, f)
            if v is not None and not math.isfinite(v):
                raise ValueError(f"'{f}' must be finite, got {v}")
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"needs low < high, got low={self.low:g}, high={self.high:g}")
        if self.std is not None and not self.std > 0:
            raise ValueError(f"needs std > 0, got {self.std:g}")
        if self.dist == "truncnormal" and not self.low <= self.mean <= self.high:
            raise ValueError(
                f"needs low <= mean <= high (the mean of the normal it truncates), got mean={self.mean:g} "
                f"outside [{self.low:g}, {self.high:g}]"
            )
        if self.values is not None and (not self.values or not all(math.isfinite(v) for v in self.values)):
            raise ValueError("'values' must be a non-empty list of finite numbers")
        return self

    def number(self, name: str) -> float:
        """The parameter ``name`` (``value``, ``low``, ``high``, ``mean`` or ``std``) of a distribution that
        uses it (the validator guarantees it is set)."""
        v = getattr(self, name)
        if v is None:
            raise ValueError(f"dist '{self.dist}' has no '{name}'")
        return float(v)

    def bounds(self) -> tuple[float, float]:
        """Support of the distribution (inf for the normal)."""
        if self.dist == "constant":
            return self.number("value"), self.number("value")
        if self.dist == "choice":
            values = self.values or []
            return min(values), max(values)
        if self.dist == "normal":
            return -math.inf, math.inf
        return self.number("low"), self.number("high")


def _as_dist(v: Any):
    if isinstance(v, bool):
        raise ValueError("expected a number or a distribution table")
    if isinstance(v, (int, float)):
        from pfjax.errors import number

        try:
            number("value", v)
        except ValueError as e:
            raise ValueError(str(e).removeprefix("value: ")) from None
        return Dist(dist="constant", value=float(v))
    return v


def dist_field(default: float, description: str | None = None):
    return Field(default_factory=lambda: Dist(dist="constant", value=default), description=description)


class SimSpec(_Model):
    dt: Real = Field(0.005, ge=POSITIVE, description="RK4 integrator step, s")
    horizon: Real = Field(20.0, ge=POSITIVE, description="simulated time per run, s")
    control_every: int = Field(
        1, ge=1, le=2_000_000, description="controller sampling period, integrator steps (zero-order hold)"
    )
    d_fail: Real = Field(10.0, ge=POSITIVE, description="|d| above which a run fails with status diverged, m")
    steady_window: Real = Field(5.0, ge=POSITIVE, description="final part of the run for the steady-state errors, s")
    settle_band: Real = Field(0.05, ge=POSITIVE, description="band on |d| for the settling time, m")

    @model_validator(mode="after")
    def _check(self):
        if self.dt > self.horizon:
            raise ValueError(f"dt: must be <= horizon ({self.horizon:g} s), got {self.dt:g}")
        if self.steady_window > self.horizon:
            raise ValueError(f"steady_window: must be <= horizon ({self.horizon:g} s), got {self.steady_window:g}")
        check_steps(self.horizon, self.dt)
        return self


class SuccessSpec(_Model):
    band: Real = Field(0.05, ge=POSITIVE, description="a run succeeds if |d| stays within this band from from_s on, m")
    from_s: Real = Field(15.0, ge=0, description="start of the success window, s")


#: Keys of ``[vehicle]`` that only the kinematic model reads, and those only the ST model reads.
KINEMATIC_ONLY = ("L", "delta_max_deg", "delta_rate_max_deg", "convention")
ST_ONLY = ("params", "mu", "tau_delta_s", "k_v")


class VehicleSpec(_Model):
    """The vehicle: ``model = "kinematic"`` (the slip model, slip declared by ``[slip]``;
    :mod:`pfjax.sim.simulate`), ``"st"`` (CommonRoad's single-track model, slip from linear tyre
    forces; :mod:`pfjax.sim.dynamic`) or ``"std"`` (its single-track drift model: Pacejka tyres and
    wheel speeds; CommonRoad's vehicles only) with its parameter set ``params``, friction ``mu``,
    steering actuator ``tau_delta_s`` and speed loop ``k_v``; its wheelbase and steering limit are the
    set's."""

    model: Literal["kinematic", "st", "std"] = Field(
        "kinematic",
        description="vehicle model: kinematic (declared slip), st (single-track, linear tyres) or std "
        "(single-track drift, Pacejka tyres)",
    )
    params: Literal["robot", "vehicle1", "vehicle2", "vehicle3"] = Field(
        "robot", description="st: parameter set: robot (the 0.2 m robot) or CommonRoad's vehicle1-3"
    )
    mu: Dist | None = Field(
        None, description="st: tyre-road friction coefficient (a distribution; default the parameter set's 1.0489)"
    )
    tau_delta_s: Real = Field(0.05, ge=POSITIVE, description="st: steering actuator time constant, s")
    k_v: Real = Field(5.0, ge=POSITIVE, description="st: speed loop gain, 1/s")
    speed: Dist = dist_field(1.0, "rear-axle speed, m/s (a distribution; st: the speed loop's reference)")
    L: Dist = dist_field(0.2, "wheelbase, m (a distribution)")
    delta_max_deg: Dist = dist_field(30.0, "steering limit, deg (a distribution)")
    delta_rate_max_deg: Real | None = Field(
        None, ge=POSITIVE, description="steering rate limit, deg/s (None or inf: none)"
    )
    convention: Literal["source", "lenain"] = Field(
        "source", description="front-slip sign convention: source or lenain"
    )

    _coerce = field_validator("speed", "L", "delta_max_deg", "mu", mode="before")(
        lambda v: v if v is None else _as_dist(v)
    )
    # "no limit" has one spelling, None, so the validated config is strict JSON (and hashes as such)
    _no_limit = field_validator("delta_rate_max_deg", mode="before")(
        lambda v: None if isinstance(v, float) and v == math.inf else v
    )

    @model_validator(mode="after")
    def _check(self):
        for name in ("speed", "L"):
            lo, _ = getattr(self, name).bounds()
            if not lo > 0:
                raise ValueError(f"{name}: must be > 0 over its whole range, got a lower bound {lo:g}")
        lo, hi = self.delta_max_deg.bounds()
        if not (lo > 0 and hi < 90):
            raise ValueError(f"delta_max_deg: must lie in (0, 90) deg, got range [{lo:g}, {hi:g}]")
        if self.mu is not None:
            lo, hi = self.mu.bounds()
            if not (lo > 0 and hi <= 10):
                raise ValueError(f"mu: must lie in (0, 10] over its whole range, got range [{lo:g}, {hi:g}]")
        other, theirs = (ST_ONLY, "st") if self.model == "kinematic" else (KINEMATIC_ONLY, "kinematic")
        for name in other:  # a value other than the default (a dumped config holds every key, at its default)
            if getattr(self, name) != type(self).model_fields[name].get_default(call_default_factory=True):
                why = (
                    "the ST model's wheelbase and steering limit are its parameter set's (vehicle.params)"
                    if theirs == "kinematic"
                    else 'it is a setting of model = "st"'
                )
                raise ValueError(f'{name}: not with model = "{self.model}" ({why}); remove it')
        if self.model == "std" and self.params == "robot":
            raise ValueError('params: model = "std" has no robot set (no magic-formula tyre); use vehicle1-3')
        return self

    def st_params(self):
        """The ST model's parameters (:class:`pfjax.models.single_track.STParams`, Python floats) of
        ``params``, with ``mu`` at its nominal value (the distribution's value, mean or midpoint)."""
        from pfjax.models.single_track import parameter_set

        p = parameter_set(self.params)
        return p if self.mu is None else p._replace(mu=nominal(self.mu))

    def model_params(self):
        """The parameters the simulator takes: :meth:`st_params` for ``"st"``, the drift model's
        :class:`pfjax.models.single_track.STDParams` (the same ``mu``) for ``"std"``."""
        from pfjax.models.single_track import model_parameter_set, with_mu

        return with_mu(model_parameter_set(self.model, self.params), self.st_params().mu)

    def wheelbase_bounds(self) -> tuple[float, float]:
        """The wheelbase's range, m (the kinematic model's ``L``, the ST set's ``l_f + l_r``)."""
        if self.model == "kinematic":
            return self.L.bounds()
        p = self.st_params()
        return p.l_f + p.l_r, p.l_f + p.l_r

    def delta_max_deg_bounds(self) -> tuple[float, float]:
        """The steering limit's range, deg."""
        if self.model == "kinematic":
            return self.delta_max_deg.bounds()
        d = math.degrees(self.st_params().delta_max)
        return d, d


def nominal(d: Dist) -> float:
    """A distribution's nominal value: its value, mean or midpoint."""
    if d.dist == "constant":
        return d.number("value")
    if d.mean is not None:
        return float(d.mean)
    return 0.5 * (d.number("low") + d.number("high"))


#: How far the Ornstein-Uhlenbeck slip term is taken to reach when the total slip is checked: its
#: stationary std times this (a 6-sigma excursion has probability about 2e-9 per sample).
OU_REACH = 6.0


class SlipSpec(_Model):
    """Slip per run: ``constant`` (beta_*), ``step`` (beta_* before, + step_* at step_time_s),
    ``sinusoid`` (beta_* mean + amp_* sin(2 pi freq_hz t + phase)), ``ou`` (Ornstein-Uhlenbeck around
    beta_* with stationary std ou_sigma_deg and time constant ou_tau_s, sampled every seq_dt)."""

    kind: Literal["constant", "step", "sinusoid", "ou"] = Field(
        "constant", description="slip profile: constant, step, sinusoid or ou (Ornstein-Uhlenbeck)"
    )
    beta_r_deg: Dist = dist_field(0.0, "rear slip angle (constant part, or the mean), deg")
    beta_f_deg: Dist = dist_field(0.0, "front slip angle (constant part, or the mean), deg")
    step_time_s: Dist = dist_field(5.0, "step: time of the step, s")
    step_r_deg: Dist = dist_field(0.0, "step: rear slip added at the step, deg")
    step_f_deg: Dist = dist_field(0.0, "step: front slip added at the step, deg")
    amp_r_deg: Dist = dist_field(0.0, "sinusoid: rear amplitude, deg")
    amp_f_deg: Dist = dist_field(0.0, "sinusoid: front amplitude, deg")
    freq_hz: Dist = dist_field(0.1, "sinusoid: frequency, Hz")
    ou_sigma_deg: Dist = dist_field(0.0, "ou: stationary standard deviation, deg")
    ou_tau_s: Dist = dist_field(1.0, "ou: time constant, s")
    seq_dt: Real = Field(0.05, ge=POSITIVE, description="ou: sampling period of the slip sequence, s")

    _coerce = field_validator(
        "beta_r_deg",
        "beta_f_deg",
        "step_time_s",
        "step_r_deg",
        "step_f_deg",
        "amp_r_deg",
        "amp_f_deg",
        "freq_hz",
        "ou_sigma_deg",
        "ou_tau_s",
        mode="before",
    )(lambda v: _as_dist(v))

    @model_validator(mode="after")
    def _check(self):
        added = {"constant": None, "step": "step", "sinusoid": "amp", "ou": "ou_sigma"}[self.kind]
        for axis in ("r", "f"):
            lo, hi = getattr(self, f"beta_{axis}_deg").bounds()
            reach = max(abs(lo), abs(hi))
            if reach >= 90:
                raise ValueError(
                    f"beta_{axis}_deg: slip magnitudes must stay below 90 deg over the distribution's "
                    f"support, got range [{lo:g}, {hi:g}]"
                )
            if added is None:
                continue
            name = f"{added}_{axis}_deg" if added != "ou_sigma" else "ou_sigma_deg"
            alo, ahi = getattr(self, name).bounds()
            if added == "step":  # before the step beta, after it beta + step
                total = max(reach, abs(lo + alo), abs(hi + ahi))
                rule = f"max |beta_{axis}_deg + {name}|"
            elif added == "amp":  # beta + amp sin(.) reaches |beta| + |amp|
                total = reach + max(abs(alo), abs(ahi))
                rule = f"max |beta_{axis}_deg| + max |{name}|"
            else:
                if alo < 0:
                    raise ValueError(f"{name}: must be >= 0, got a lower bound {alo:g}")
                total = reach + OU_REACH * ahi
                rule = f"max |beta_{axis}_deg| + {OU_REACH:g} max {name}"
            if not total < 90:
                raise ValueError(
                    f"{name}: the total slip must stay below 90 deg over the distributions' support, "
                    f"got {rule} = {total:g} deg"
                )
        for name in ("ou_tau_s", "freq_hz", "step_time_s"):
            lo, _ = getattr(self, name).bounds()
            if lo < 0 or (name == "ou_tau_s" and lo < POSITIVE):
                raise ValueError(f"{name}: must be {'> 0' if name == 'ou_tau_s' else '>= 0'}, got a lower bound {lo:g}")
        return self


class InitialSpec(_Model):
    """Start pose relative to the path's nominal start: along-path offset, lateral offset, heading error."""

    RENAMED: ClassVar[dict[str, str]] = {"start_s": "start_along_m"}
    start_along_m: Dist = dist_field(0.0, "start, m along the path from its nominal start")
    lateral_offset: Dist = dist_field(0.0, "start offset left of the path, m")
    heading_error_deg: Dist = dist_field(0.0, "start heading error, deg")

    _coerce = field_validator("start_along_m", "lateral_offset", "heading_error_deg", mode="before")(
        lambda v: _as_dist(v)
    )


class NoiseSpec(_Model):
    """White Gaussian sensor noise on the measured rear-axle pose, drawn afresh at every integrator
    step (:class:`pfjax.sim.simulate.SensorNoise`): the measured pose is the true one displaced by
    ``e_d ~ N(0, sigma_d^2)`` (m) along the path's left normal at the closest point and rotated by
    ``e_theta ~ N(0, sigma_theta_e_deg^2)`` (deg, converted to rad), so the measured lateral error
    is ``d + e_d`` and the measured heading error ``theta_e + e_theta``. Every controller sees this
    one noisy measurement: the state-feedback, PI, integral and rear-wheel controllers through
    ``(d, theta_e)``, Stanley and pure pursuit through the noisy pose. The metrics use the true
    errors. Both sigmas 0: no noise."""

    sigma_d: Real = Field(0.0, ge=0, description="standard deviation of the measured lateral position, m")
    sigma_theta_e_deg: Real = Field(0.0, ge=0, le=180, description="standard deviation of the measured heading, deg")


class PathSpec(_Model):
    """A registered path kind (:data:`pfjax.paths.PATHS`): ``line``, ``parabola``, ``sine`` (the
    source's), ``circle`` (radius), ``random`` (smooth random spline paths with |kappa| <=
    curvature_margin * tan(delta_max) / L), ``spline`` (a natural cubic spline through the user's
    ``points`` [[x, y], ...] in m, travelled from the first point), or any path registered with
    :func:`pfjax.paths.register`."""

    kind: str = Field(description="a registered path kind: line, parabola, sine, circle, random, spline, ...")
    name: str | None = Field(None, description="label in outputs (default: the kind)")
    radius: Dist = dist_field(2.0, "circle: radius, m")
    length: Real = Field(40.0, ge=POSITIVE, description="random paths: length, m")
    curvature_margin: Real = Field(
        0.5, ge=POSITIVE, le=1, description="random paths: fraction of the followable curvature"
    )
    n_waypoints: int = Field(41, ge=4, le=10_000, description="random paths: spline waypoints")
    points: list[list[Real]] | None = Field(None, description="spline: the points [[x, y], ...] it passes through, m")

    _coerce = field_validator("radius", mode="before")(lambda v: _as_dist(v))

    @field_validator("kind")
    @classmethod
    def _known_kind(cls, v):
        from pfjax.paths import PATHS

        if v not in PATHS:
            raise ValueError(f"unknown path kind {v!r}; expected one of {', '.join(PATHS)}")
        return v

    @field_validator("points")
    @classmethod
    def _points(cls, v):
        if v is None:
            return v
        if len(v) < 4:
            raise ValueError(f"a spline needs at least 4 points [x, y], got {len(v)}")
        for i, q in enumerate(v):
            if len(q) != 2:
                raise ValueError(f"[{i}]: expected a point [x, y], got {q}")
            if not all(math.isfinite(c) for c in q):
                raise ValueError(f"[{i}]: coordinates must be finite, got {q}")
        for i in range(1, len(v)):
            if math.dist(v[i], v[i - 1]) <= 0:
                raise ValueError(
                    f"[{i}]: repeats point [{i - 1}] {v[i]}; consecutive points must differ (arc length must increase)"
                )
            if i >= 2:
                a = (v[i - 1][0] - v[i - 2][0], v[i - 1][1] - v[i - 2][1])
                b = (v[i][0] - v[i - 1][0], v[i][1] - v[i - 1][1])
                if a[0] * b[0] + a[1] * b[1] <= 0:
                    raise ValueError(
                        f"[{i}]: the path turns back by 90 deg or more at point [{i - 1}]; points must advance along the path"
                    )
        return v

    @model_validator(mode="after")
    def _check(self):
        if self.kind == "circle" and not self.radius.bounds()[0] >= POSITIVE:
            raise ValueError(
                f"radius: must be > 0 m over its whole range, got a lower bound {self.radius.bounds()[0]:g}"
            )
        if (self.kind == "spline") != (self.points is not None):
            raise ValueError(
                "points: required for kind 'spline'"
                if self.kind == "spline"
                else f"points: only for kind 'spline', not {self.kind!r}"
            )
        return self

    @property
    def label(self) -> str:
        return self.name or self.kind


class MarginSpec(_Model):
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

    @model_validator(mode="after")
    def _check(self):
        if self.n_per_amplitude * len(self.amplitudes_deg) > 100_000_000:
            raise ValueError(
                f"n_per_amplitude: at most 1e8 runs per axis and path (n_per_amplitude x "
                f"{len(self.amplitudes_deg)} amplitudes), got {self.n_per_amplitude * len(self.amplitudes_deg):.3g}"
            )
        return self


class FalsifierSpec(_Model):
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


class RareEventSpec(_Model):
    """Small failure probabilities per controller (:mod:`pfjax.rare`): a run fails where its status is
    a failure or ``metric > threshold``; the estimator works on the margin ``threshold - metric``
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
        None, ge=0, description="failure where metric > threshold (metric's unit; default success.band, m)"
    )
    target_rel_error: Real = Field(
        0.1, gt=0, le=10, description="stop once the estimate's relative error (c.o.v.) is at most this"
    )
    max_rollouts: int = Field(100_000, ge=100, le=100_000_000, description="rollouts per controller at most")
    n_per_level: int = Field(
        2000, ge=100, le=10_000_000, description="is / subset: rollouts per cross-entropy or subset level"
    )
    n_components: int = Field(4, ge=1, le=64, description="is: Gaussians in the proposal mixture")
    batch: int = Field(2000, ge=32, le=1_000_000, description="runs simulated at once (one compiled shape)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="seed of the estimator's draws")

    @model_validator(mode="after")
    def _check(self):
        if self.method == "subset" and self.n_per_level % 10:
            raise ValueError(f"n_per_level: subset simulation needs a multiple of 10, got {self.n_per_level}")
        return self


class ControllerSpec(_Model):
    """A controller to compare. ``type``: a registered controller (state_feedback, pi, integral,
    stanley, pure_pursuit, rear_wheel, ...; :data:`pfjax.controllers.REGISTRY`) or a design
    (lmi: mixed H2/H-inf with ``alpha``, ``beta`` at the nominal speed and wheelbase; integral_lmi;
    paper_k: the source's published gain; :data:`pfjax.controllers.DESIGNS`). ``gains`` by name
    override the defaults or the design; ``K`` is the vector gain of state_feedback and integral."""

    name: str = Field(description="label in outputs")
    type: str = Field(
        description="a registered controller or design: lmi, paper_k, state_feedback, pi, integral, stanley, ..."
    )
    K: list[Real] | None = Field(
        None, description="vector gain of state_feedback [k_d rad/m, k_theta rad/rad] or integral"
    )
    gains: dict[str, Real] = Field(
        default_factory=dict, description="scalar gains by name (the others: defaults or the design's)"
    )
    alpha: Real = Field(10.0, ge=0, description="designs: weight on gamma_inf^2")
    beta: Real = Field(1.0, ge=0, description="designs: weight on gamma_2^2")

    @field_validator("type")
    @classmethod
    def _known(cls, v):
        from pfjax.controllers import controller_types

        if v not in controller_types():
            raise ValueError(f"unknown controller type {v!r}; expected one of {', '.join(controller_types())}")
        return v

    @model_validator(mode="after")
    def _check(self):
        from pfjax.controllers import resolve

        e, d = resolve(self.type)
        if self.K is not None:
            if d is not None or "K" not in e.labels:
                raise ValueError(
                    f"K is only for types with a vector gain K "
                    f"({', '.join(n for n, x in _registry().items() if 'K' in x.labels)}), not {self.type!r}"
                )
            if len(self.K) != len(e.labels["K"]):
                raise ValueError(f"{self.type} needs K = [{', '.join(e.labels['K'])}]")
        return self


def _registry():
    from pfjax.controllers import REGISTRY

    return REGISTRY


class StudySpec(_Model):
    name: str = Field(description="study name: the default output directory is results/<name>")
    n_runs: int = Field(ge=1, le=100_000_000, description="runs per controller and path")
    seed: int = Field(
        ge=0,
        le=MAX_SEED,
        description="seed of every random draw (run i of path p draws from fold_in(fold_in(seed, p), i))",
    )
    chunk_size: int = Field(4096, ge=1, le=10_000_000, description="runs simulated (and saved for resuming) at once")
    dtype: Literal["float32", "float64"] = Field("float32", description="floating-point precision of the simulation")
    f64_check_runs: int = Field(
        64, ge=0, le=4096, description="float32 studies: runs per controller re-simulated in float64"
    )
    sim: SimSpec = SimSpec()
    success: SuccessSpec = SuccessSpec()
    vehicle: VehicleSpec = VehicleSpec()
    slip: SlipSpec = SlipSpec()
    initial: InitialSpec = InitialSpec()
    noise: NoiseSpec = NoiseSpec()
    margin: MarginSpec = MarginSpec()
    falsifier: FalsifierSpec = FalsifierSpec()
    rare_event: RareEventSpec = RareEventSpec()
    paths: list[PathSpec] = Field(min_length=1)
    controllers: list[ControllerSpec] = Field(min_length=1)

    @field_validator("name")
    @classmethod
    def _name(cls, v):
        from pfjax.outputs import NAME_PATTERN

        if not NAME_PATTERN.match(v):
            raise ValueError(
                "expected 1-100 letters, digits, '_', '.' or '-' starting with a letter or digit "
                "(it names the output directory results/<name>)"
            )
        return v

    @model_validator(mode="after")
    def _check(self):
        if self.success.from_s > self.sim.horizon:
            raise ValueError(
                f"success.from_s: must be <= sim.horizon ({self.sim.horizon:g} s), got {self.success.from_s:g}"
            )
        if self.falsifier.path is not None and self.falsifier.path not in [p.label for p in self.paths]:
            raise ValueError(
                f"falsifier.path: no path labelled {self.falsifier.path!r}; paths are {[p.label for p in self.paths]}"
            )
        if self.vehicle.model in ("st", "std"):
            changed = [k for k, v in self.slip if v != SlipSpec.model_fields[k].get_default(call_default_factory=True)]
            if changed:
                key = changed[0]
                raise ValueError(
                    f'slip.{key}: not with vehicle.model = "{self.vehicle.model}" (its slip comes from the tyre '
                    "forces); remove it"
                )
            from pfjax.models.single_track import max_stable_step, with_mu

            veh = self.vehicle
            mu_hi = veh.st_params().mu if veh.mu is None else veh.mu.bounds()[1]
            v_lo = veh.speed.bounds()[0]
            dt_max = max_stable_step(with_mu(veh.model_params(), mu_hi), v_lo, veh.tau_delta_s, veh.k_v)
            if self.sim.dt > dt_max:
                raise ValueError(
                    f"sim.dt: the {veh.model.upper()} model at mu = {mu_hi:g} and speed {v_lo:g} m/s (the ranges' worst case) needs "
                    f"dt <= {dt_max:.3g} s for a stable RK4 step, got {self.sim.dt:g}"
                )
            for key, section, what in (
                ("margin.enabled", self.margin, "slip-margin sweep"),
                ("falsifier.enabled", self.falsifier, "worst-case search"),
            ):
                if section.enabled:
                    raise ValueError(
                        f'{key}: the {what} declares slip, not with vehicle.model = "{self.vehicle.model}"; set it to false'
                    )
        for what, items in (
            ("controllers", [c.name for c in self.controllers]),
            ("paths", [p.label for p in self.paths]),
        ):
            dup = {x for x in items if items.count(x) > 1}
            if dup:
                raise ValueError(f"{what}: names must be unique, repeated: {sorted(dup)}")
        return self


# ------------------------------------------------------------------------------- loading


def _loc(loc) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif part in ("constant", "uniform", "normal", "truncnormal", "choice", "function-after[_check(), Dist]"):
            continue
        else:
            out += ("." if out else "") + str(part)
    return out


def _model_at(loc) -> type[BaseModel] | None:
    model: Any = StudySpec
    for part in loc:
        if isinstance(part, int):
            continue
        field = getattr(model, "model_fields", {}).get(part)
        if field is None:
            return model
        ann = field.annotation
        args = getattr(ann, "__args__", ())
        nxt = next((a for a in (ann, *args) if isinstance(a, type) and issubclass(a, BaseModel)), None)
        if nxt is None:
            return model
        model = nxt
    return model


def _format(err: ValidationError) -> str:
    e = err.errors()[0]
    loc = [
        p
        for p in e["loc"]
        if not (isinstance(p, str) and ("[" in p or p in ("constant", "uniform", "normal", "truncnormal", "choice")))
    ]
    key = _loc(loc) or "config"
    if e["type"] == "extra_forbidden":
        parent = _model_at(loc[:-1])
        names = list(getattr(parent, "model_fields", {}))
        hint = difflib.get_close_matches(str(loc[-1]), names, n=1)
        prefix = _loc(loc[:-1])
        sug = f" (did you mean '{(prefix + '.') if prefix else ''}{hint[0]}'?)" if hint else ""
        return f"{key}: unknown key{sug}"
    msg = e["msg"].removeprefix("Value error, ")
    # model-level checks name their field first ("speed: must be ..."): join it to the key
    head, sep, rest = msg.partition(": ")
    if e["type"] == "value_error" and sep and " " not in head and "'" not in head:
        key = head if key == "config" else f"{key}{'' if head.startswith('[') else '.'}{head}"
        msg = rest
    if e["type"] == "missing":
        return f"{key}: required key is missing"
    bound = _BOUNDS.get(e["type"])
    if bound is not None:  # pydantic writes 1e-12 as 0.000000000001
        limit = e["ctx"][bound[1]]
        msg = f"must be {bound[0]} {limit:g}" if isinstance(limit, float) else f"must be {bound[0]} {limit}"
    return f"{key}: {msg} (got {_short(e.get('input'))})" if e["type"] != "value_error" else f"{key}: {msg}"


_BOUNDS = {
    "greater_than": (">", "gt"),
    "greater_than_equal": (">=", "ge"),
    "less_than": ("<", "lt"),
    "less_than_equal": ("<=", "le"),
}


def _set_nested(d: dict, update: dict) -> dict:
    for k, v in update.items():
        if "[" in k:  # controllers[0].gains.k style
            name, idx = k.split("[", 1)
            i = int(idx.rstrip("]"))
            lst = d.get(name)
            if not isinstance(lst, list) or not -len(lst) <= i < len(lst):
                raise ConfigError(
                    f"{k}: no such list element" if isinstance(lst, list) else f"{k}: {name} is not a list"
                )
            if isinstance(v, dict) and "dist" not in v and isinstance(lst[i], dict):
                _set_nested(lst[i], v)
            else:
                lst[i] = v
        elif isinstance(v, dict) and "dist" in v:  # a new distribution replaces the old one whole
            d[k] = v
        elif isinstance(v, dict) and isinstance(d.get(k), dict):
            _set_nested(d[k], v)
        else:
            d[k] = v
    return d


def load_study(
    path: str | Path | None = None, overrides: Sequence[str] = (), data: dict | None = None, values: dict | None = None
) -> tuple[StudySpec, dict]:
    """Read, override and validate a study. Returns ``(spec, raw_dict)``; raises ConfigError.

    Args:
        path: a TOML file (else ``data``, a dict).
        overrides: ``--set`` texts ``"key=value"`` (the value parsed as TOML).
        values: overrides as Python values by dotted key (``{"sim.horizon": 30, "paths": [...]}``).
    """
    import copy

    raw: dict = {} if data is None else copy.deepcopy(dict(data))
    if path is not None:
        raw = read_toml(path)
    for text in overrides:
        _set_nested(raw, parse_override(text))
    for key, value in (values or {}).items():
        _set_nested(raw, nested(key, value))
    try:
        spec = StudySpec.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_format(e)) from None
    return spec, raw


def study_hash(spec: StudySpec) -> str:
    """SHA-256 of the validated study (defaults filled in), so equivalent files hash alike."""
    return config_hash(spec.model_dump(mode="json"))
