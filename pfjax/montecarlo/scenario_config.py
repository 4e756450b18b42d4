"""The scenario sections of a Monte Carlo study's config: simulation and success criterion,
vehicle, slip, initial condition, measurement noise and paths (:mod:`pfjax.montecarlo.config`)."""

from __future__ import annotations

import math
from typing import ClassVar, Literal, NamedTuple

from pydantic import Field, field_validator, model_validator

from pfjax.config import POSITIVE, ConfigModel, Label, Real
from pfjax.models import (
    DEFAULT_PARAMETER_SET,
    DYNAMIC_MODELS,
    MODELS,
    PARAMETER_SETS,
    check_setting,
    check_setting_range,
)
from pfjax.montecarlo.dists import Dist, as_dist, dist_field, nominal


class SimSpec(ConfigModel):
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
        from pfjax.sim.settings import SimConfig

        if self.dt > self.horizon:
            raise ValueError(f"dt: must be <= horizon ({self.horizon:g} s), got {self.dt:g}")
        if self.steady_window > self.horizon:
            raise ValueError(f"steady_window: must be <= horizon ({self.horizon:g} s), got {self.steady_window:g}")
        # the simulator's own checks of these settings (the step count, the sampling period), one home
        SimConfig(dt=self.dt, horizon=self.horizon, control_every=self.control_every)
        return self


class SuccessSpec(ConfigModel):
    band: Real = Field(0.05, ge=POSITIVE, description="a run succeeds if |d| stays within this band from from_s on, m")
    from_s: Real = Field(15.0, ge=0, description="start of the success window, s")


class ModelSetting(NamedTuple):
    """A setting that only one kind of vehicle model reads, under its name in each place that takes
    it (``None`` where that place does not): given with the other kind it is refused, naming it."""

    reader: Literal["kinematic", "dynamic"]  # the declared-slip model, or the single-track ones (st, std)
    key: str | None  # the study config's [vehicle] key
    argument: str | None  # pfjax.scenarios' argument
    flag: str | None  # pfjax simulate's flag
    reason: str  # why the other kind refuses it ({model}: the model it was given with)

    def refusal(self, model: str) -> str:
        """Why ``model`` does not take this setting, the words every refusal of it uses."""
        return self.reason.format(model=model)


_SLIP = "the {model} model's slip comes from its tyre forces"
_SET = "the {model} model's wheelbase and steering limits are its parameter set's"
_DYNAMIC = "a setting of the single-track models, st and std"
#: Which vehicle model reads which setting: the one table the study config (``[vehicle]``; the
#: whole ``[slip]`` section is the kinematic model's too), :func:`pfjax.scenarios` and
#: ``pfjax simulate`` refuse the other model's settings from.
MODEL_SETTINGS = (
    ModelSetting("kinematic", None, "beta_r_deg", "--beta-r-deg", _SLIP),
    ModelSetting("kinematic", None, "beta_f_deg", "--beta-f-deg", _SLIP),
    ModelSetting("kinematic", "L", "L", "--wheelbase", _SET),
    ModelSetting("kinematic", "delta_max_deg", "delta_max_deg", "--delta-max-deg", _SET),
    ModelSetting("kinematic", "delta_rate_max_deg", None, None, _SET),
    ModelSetting(
        "kinematic",
        "convention",
        "convention",
        "--convention",
        "the front-slip sign convention is the declared-slip model's; the {model} model's slip comes from its "
        "tyre forces",
    ),
    ModelSetting(
        "kinematic", None, None, "--continuous", "the {model} model takes a sampled controller, not a continuous one"
    ),
    ModelSetting("dynamic", "params", "vehicle_params", "--vehicle", _DYNAMIC),
    ModelSetting("dynamic", "mu", "mu", "--mu", _DYNAMIC),
    ModelSetting("dynamic", "tau_delta_s", "tau_delta_s", "--tau-delta", _DYNAMIC),
    ModelSetting("dynamic", "k_v", "k_v", "--k-v", _DYNAMIC),
)


def other_models_settings(model: str) -> tuple[ModelSetting, ...]:
    """The settings of :data:`MODEL_SETTINGS` that ``model`` (``kinematic``, ``st`` or ``std``) does
    not read."""
    reader = "kinematic" if model == "kinematic" else "dynamic"
    return tuple(s for s in MODEL_SETTINGS if s.reader != reader)


def slip_refusal(model: str) -> str:
    """Why ``model`` (a single-track one) refuses the ``[slip]`` section's keys."""
    return _SLIP.format(model=model)


class VehicleSpec(ConfigModel):
    """The vehicle: ``model = "kinematic"`` (the slip model, slip declared by ``[slip]``;
    :mod:`pfjax.sim.simulate`), ``"st"`` (CommonRoad's single-track model, slip from linear tyre
    forces; :mod:`pfjax.sim.dynamic`) or ``"std"`` (its single-track drift model: Pacejka tyres and
    wheel speeds; CommonRoad's vehicles only) with its parameter set ``params``, friction ``mu``,
    steering actuator ``tau_delta_s`` and speed loop ``k_v``; its wheelbase and steering limit are the
    set's."""

    model: Literal[MODELS] = Field(  # type: ignore[valid-type]
        "kinematic",
        description="vehicle model: kinematic (declared slip), st (single-track, linear tyres) or std "
        "(single-track drift, Pacejka tyres)",
    )
    params: Literal[PARAMETER_SETS] = Field(  # type: ignore[valid-type]
        "robot",
        description="st, std: parameter set: robot (the 0.2 m robot) or CommonRoad's vehicle1-3 (default "
        "robot; vehicle2 for std)",
    )
    mu: Dist | None = Field(
        None, description="st: tyre-road friction coefficient (a distribution; default the parameter set's 1.0489)"
    )
    tau_delta_s: Real = Field(0.05, description="st: steering actuator time constant, s")
    k_v: Real = Field(5.0, description="st: speed loop gain, 1/s")
    speed: Dist = dist_field(
        1.0, "rear-axle speed, m/s (a distribution; st, std: the reference of the centre of mass's speed loop)"
    )
    L: Dist = dist_field(0.2, "wheelbase, m (a distribution)")
    delta_max_deg: Dist = dist_field(30.0, "steering limit, deg (a distribution)")
    delta_rate_max_deg: Real | None = Field(
        None, ge=POSITIVE, description="steering rate limit, deg/s (None or inf: none)"
    )
    convention: Literal["source", "lenain"] = Field(
        "source", description="front-slip sign convention: source or lenain"
    )

    _coerce = field_validator("speed", "L", "delta_max_deg", "mu", mode="before")(
        lambda v: v if v is None else as_dist(v)
    )
    # "no limit" has one spelling, None, so the validated config is strict JSON (and hashes as such)
    _no_limit = field_validator("delta_rate_max_deg", mode="before")(
        lambda v: None if isinstance(v, float) and v == math.inf else v
    )

    @model_validator(mode="before")
    @classmethod
    def _model_default_set(cls, data):
        """``params`` not given: the model's :data:`pfjax.models.DEFAULT_PARAMETER_SET`."""
        if isinstance(data, dict) and data.get("params") is None and data.get("model") in DEFAULT_PARAMETER_SET:
            return {**data, "params": DEFAULT_PARAMETER_SET[data["model"]]}
        return data

    @model_validator(mode="after")
    def _check(self):
        # the rules of pfjax.scenarios' and the scenario builders' arguments (pfjax simulate's flags), one home
        for name in ("speed", "L", "delta_max_deg"):
            check_setting_range(name, name, *getattr(self, name).bounds())
        for name in ("tau_delta_s", "k_v"):
            check_setting(name, name, getattr(self, name))
        if self.mu is not None:
            lo, hi = self.mu.bounds()
            if not (lo > 0 and hi <= 10):
                raise ValueError(f"mu: must lie in (0, 10] over its whole range, got range [{lo:g}, {hi:g}]")
        for setting in other_models_settings(self.model):
            name = setting.key  # a value other than the default (a dumped config holds every key, at its default)
            if name is not None and getattr(self, name) != type(self).model_fields[name].get_default(
                call_default_factory=True
            ):
                raise ValueError(f'{name}: not with model = "{self.model}" ({setting.refusal(self.model)}); remove it')
        if self.model == "std" and self.params == "robot":
            raise ValueError('params: model = "std" has no robot set (no magic-formula tyre); use vehicle1-3')
        if self.model in DYNAMIC_MODELS:
            from pfjax.models.single_track import check_speed

            check_speed("speed", self.speed.bounds()[1], self.model_params())
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


OU_REACH = 6.0


class SlipSpec(ConfigModel):
    """Slip per run: ``constant`` (beta_*), ``step`` (beta_* before, + step_* at step_time_s),
    ``sinusoid`` (beta_* mean + amp_* sin(2 pi freq_hz t + phase)), ``ou`` (Ornstein-Uhlenbeck around
    beta_* with stationary std ou_sigma_deg and time constant ou_tau_s, sampled every seq_dt)."""

    #: The keys each profile adds to ``beta_*`` (the run table's columns of that kind); another
    #: kind's key is refused at any value but its default (a dumped config holds every key).
    KIND_KEYS: ClassVar[dict[str, tuple[str, ...]]] = {
        "constant": (),
        "step": ("step_time_s", "step_r_deg", "step_f_deg"),
        "sinusoid": ("amp_r_deg", "amp_f_deg", "freq_hz"),
        "ou": ("ou_sigma_deg", "ou_tau_s"),
    }

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
    )(lambda v: as_dist(v))

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
        for other, keys in self.KIND_KEYS.items():
            for name in keys if other != self.kind else ():
                if getattr(self, name) != type(self).model_fields[name].get_default(call_default_factory=True):
                    raise ValueError(
                        f'{name}: not with kind = "{self.kind}" (a setting of kind = "{other}", which this '
                        f'study\'s slip does not read); remove it, or set kind = "{other}"'
                    )
        return self


class InitialSpec(ConfigModel):
    """Start pose relative to the path's nominal start: along-path offset, lateral offset, heading error."""

    RENAMED: ClassVar[dict[str, str]] = {"start_s": "start_along_m"}
    start_along_m: Dist = dist_field(0.0, "start, m along the path from its nominal start")
    lateral_offset: Dist = dist_field(0.0, "start offset left of the path, m")
    heading_error_deg: Dist = dist_field(0.0, "start heading error, deg")

    _coerce = field_validator("start_along_m", "lateral_offset", "heading_error_deg", mode="before")(
        lambda v: as_dist(v)
    )


class NoiseSpec(ConfigModel):
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


class PathSpec(ConfigModel):
    """A registered path kind (:data:`pfjax.paths.PATHS`): ``line``, ``parabola``, ``sine`` (the
    source's), ``circle`` (radius), ``random`` (smooth random spline paths with |kappa| <=
    curvature_margin * tan(delta_max) / L), ``spline`` (a natural cubic spline through the user's
    ``points`` [[x, y], ...] in m, travelled from the first point), or any path registered with
    :func:`pfjax.paths.register`."""

    #: The keys only some kinds read, and those kinds (the parametric ones, built from these keys by
    #: :mod:`pfjax.montecarlo.sampling`); every other kind reads only ``kind`` and ``name``.
    KIND_KEYS: ClassVar[dict[str, tuple[str, ...]]] = {
        "radius": ("circle",),
        "length": ("random",),
        "curvature_margin": ("random",),
        "n_waypoints": ("random",),
        "points": ("spline",),
    }

    kind: str = Field(description="a registered path kind: line, parabola, sine, circle, random, spline, ...")
    name: Label | None = Field(None, description="label in outputs (default: the kind)")
    radius: Dist = dist_field(2.0, "circle: radius, m")
    length: Real = Field(40.0, ge=POSITIVE, description="random paths: length, m")
    curvature_margin: Real = Field(
        0.5, ge=POSITIVE, le=1, description="random paths: fraction of the followable curvature"
    )
    n_waypoints: int = Field(41, ge=4, le=10_000, description="random paths: spline waypoints")
    points: list[list[Real]] | None = Field(None, description="spline: the points [[x, y], ...] it passes through, m")

    _coerce = field_validator("radius", mode="before")(lambda v: as_dist(v))

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

    @classmethod
    def keys_of(cls, kind: str) -> list[str]:
        """The keys a path of ``kind`` reads (:data:`KIND_KEYS`), in the schema's order."""
        return [k for k in cls.model_fields if kind in cls.KIND_KEYS.get(k, (kind,))]

    @model_validator(mode="after")
    def _check(self):
        fields = type(self).model_fields
        for name, kinds in self.KIND_KEYS.items():
            # a value other than the default (a dumped config holds every key, at its default)
            if self.kind not in kinds and getattr(self, name) != fields[name].get_default(call_default_factory=True):
                raise ValueError(
                    f"{name}: not a key of a {self.kind} path; its keys are {', '.join(self.keys_of(self.kind))} "
                    f"({name} is a key of kind {' or '.join(map(repr, kinds))})"
                )
        if self.kind == "circle" and not self.radius.bounds()[0] >= POSITIVE:
            raise ValueError(
                f"radius: must be > 0 m over its whole range, got a lower bound {self.radius.bounds()[0]:g}"
            )
        if self.kind == "spline" and self.points is None:
            raise ValueError("points: required for kind 'spline'")
        return self

    @property
    def label(self) -> str:
        return self.name or self.kind
