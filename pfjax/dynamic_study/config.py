"""The kinematic-versus-dynamic study's configuration schema (``studies/kinematic_vs_dynamic.toml``).

Top-level keys set the arms (friction range, the high-friction arm, the kinematic slip ranges and
the throughput comparison); ``designs`` the LMI redesigns; ``car`` the passenger-car scale; ``study``
the Monte Carlo study config the robot arms share (keys of :class:`pfjax.montecarlo.config.StudySpec`,
given keys merged into :data:`STUDY` the way ``--set`` merges into a file; not the keys each arm sets
itself, :data:`ARM_KEYS`: the slip, the vehicle's model and its friction; ``study.vehicle`` is the
dynamic arms' vehicle, so its ``tau_delta_s`` and ``k_v`` are theirs). Every key is optional;
the defaults are the study's published sizes. Loaded by :func:`load` with the same ``--set
key=value`` syntax and one-line :class:`pfjax.config.ConfigError` as the Monte Carlo study.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, field_validator, model_validator

from pfjax.config import POSITIVE, ConfigModel, Real, format_error, load_model, set_nested
from pfjax.models.single_track import COMMONROAD_VEHICLES

#: The Monte Carlo study config the robot arms share (``name`` is the study's own).
STUDY: dict[str, Any] = {
    "n_runs": 400,
    "seed": 2026,
    "chunk_size": 400,
    "dtype": "float32",
    "f64_check_runs": 0,
    "sim": {"dt": 0.005, "horizon": 20.0, "steady_window": 5.0},
    "success": {"band": 0.05, "from_s": 15.0},
    "vehicle": {"speed": {"dist": "uniform", "low": 0.7, "high": 1.3}},
    "initial": {
        "start_along_m": {"dist": "uniform", "low": 0.0, "high": 2.0},
        "lateral_offset": {"dist": "uniform", "low": -0.5, "high": 0.5},
        "heading_error_deg": {"dist": "uniform", "low": -30.0, "high": 30.0},
    },
    "margin": {"enabled": False},
    "paths": [{"kind": "line"}, {"kind": "parabola"}, {"kind": "sine"}],
    "controllers": [
        {"name": "mixed-lmi", "type": "lmi", "alpha": 10.0, "beta": 1.0},
        {"name": "pi-table3", "type": "pi"},
        {"name": "stanley", "type": "stanley"},
    ],
}

#: ``--quick``: a small sample and short runs (tests, a first look)
QUICK = {
    "study": {
        "n_runs": 16,
        "chunk_size": 16,
        "sim": {"horizon": 4.0, "steady_window": 2.0},
        "success": {"from_s": 2.0},
    },
    "slip_ranges_deg": [10.0, 0.0],
    "bench_runs": 32,
    "bench_repeats": 1,
    "car": {"n_runs": 8},
}


class Designs(ConfigModel):
    """The mixed, integral and polytopic gains designed on the kinematic model and redesigned on the
    dynamic model's linearised lateral-yaw dynamics."""

    enabled: bool = Field(True, description="run the designs' arms [-]")
    alpha: Real = Field(10.0, ge=0, description="weight on gamma_inf^2 of the mixed H2/H-inf criterion [-]")
    beta: Real = Field(1.0, ge=0, description="weight on gamma_2^2 of the mixed H2/H-inf criterion [-]")
    polytope_slip_deg: Real = Field(10.0, ge=0, lt=90, description="the kinematic polytopic design's slip range [deg]")


class Car(ConfigModel):
    """The passenger-car scale: lengths x S = l_car / 0.2 m, speeds and times x sqrt(S)."""

    enabled: bool = Field(True, description="run the passenger-car arms [-]")
    params: str = Field(
        "vehicle2", description=f"CommonRoad parameter set, one of {', '.join(COMMONROAD_VEHICLES)} [-]"
    )
    n_runs: int = Field(
        200, ge=1, le=10_000_000, description="runs per controller and path (one chunk: at most 10^7) [-]"
    )
    dt: Real = Field(0.01, ge=POSITIVE, description="integration step of the car's runs [s]")

    @field_validator("params")
    @classmethod
    def _params(cls, v):
        if v not in COMMONROAD_VEHICLES:
            raise ValueError(f"expected one of {', '.join(COMMONROAD_VEHICLES)}, got {v!r}")
        return v


class KinematicVsDynamic(ConfigModel):
    """The kinematic-versus-dynamic study (``studies/kinematic_vs_dynamic.py``)."""

    name: str = Field("kinematic_vs_dynamic", description="output folder name under results/ [-]")
    mu_low: Real = Field(0.3, gt=0, le=10, description="the dynamic arms' friction: uniform from mu_low to mu_high [-]")
    mu_high: Real = Field(1.0, gt=0, le=10, description="upper end of the dynamic arms' friction [-]")
    mu_grip: Real = Field(3.0, gt=0, le=10, description="friction of a high-friction arm (little slip) [-]")
    slip_ranges_deg: list[Real] = Field(
        [10.0, 7.5, 5.0, 3.0, 2.0, 1.0, 0.0],
        min_length=1,
        description="kinematic arms: constant slip uniform on +-A per axle, one arm per A in [0, 90) [deg]",
    )
    bench: bool = Field(True, description="time the kinematic, ST and STD models in the same loop (throughput) [-]")
    bench_runs: int = Field(256, ge=1, le=1_000_000, description="runs per batch of the throughput comparison [-]")
    bench_repeats: int = Field(7, ge=1, le=1000, description="timed repeats, interleaved (the best is reported) [-]")
    designs: Designs = Designs()
    car: Car = Car()
    study: dict[str, Any] = Field(
        default_factory=lambda: copy.deepcopy(STUDY),
        description="the Monte Carlo study config the robot arms share: keys of a study config, given keys "
        "replacing those of pfjax.dynamic_study.config.STUDY (the [study] tables of "
        "studies/kinematic_vs_dynamic.toml); study.vehicle is the dynamic arms' vehicle (model st): "
        "vehicle.tau_delta_s (s) and vehicle.k_v (1/s) set their steering actuator and speed loop (and the "
        "designs' operating point; Froude-scaled for the car), the kinematic model's keys (vehicle.L, "
        "vehicle.delta_max_deg, vehicle.delta_rate_max_deg, vehicle.convention) are refused; not slip, "
        "vehicle.model, vehicle.mu or vehicle.params, which the arms set [-]",
    )

    @field_validator("study", mode="before")
    @classmethod
    def _merge_study(cls, v):
        if not isinstance(v, dict):
            raise ValueError(f"expected a table, got {v!r}")
        return set_nested(copy.deepcopy(STUDY), copy.deepcopy(v))

    @model_validator(mode="after")
    def _check(self):
        from pfjax.montecarlo.config import StudySpec, VehicleSpec
        from pfjax.outputs import NAME_PATTERN

        if not NAME_PATTERN.match(self.name):
            raise ValueError(f"name: expected 1-100 letters, digits, '_', '.' or '-' starting with a letter or digit, got {self.name!r}")  # fmt: skip
        if not self.mu_low < self.mu_high:
            raise ValueError(f"mu_high: must be > mu_low ({self.mu_low:g}), got {self.mu_high:g}")
        bad = [a for a in self.slip_ranges_deg if not 0 <= a < 90]
        if bad:
            raise ValueError(f"slip_ranges_deg: expected angles in [0, 90) deg, got {bad[0]:g}")
        names = [kinematic_arm(a) for a in self.slip_ranges_deg]
        repeated = sorted({x for x in names if names.count(x) > 1})
        if repeated:
            raise ValueError(
                f"slip_ranges_deg: each range names its arm (kinematic_<A:g>deg, 6 significant digits), and "
                f"{self.slip_ranges_deg} names {', '.join(repeated)} more than once; give distinct ranges"
            )
        _refuse_arm_keys(self.study)
        # the vehicle as the dynamic arms' (its own keys), the rest as the kinematic arms' study config;
        # the arms' full study configs (the simulation step at their friction) are checked before the
        # runs, naming the arm (pfjax.dynamic_study.arms.check)
        for schema, data, prefix in (
            (VehicleSpec, dynamic(self.study, self.dynamic_mu())["vehicle"], "study.vehicle."),
            (StudySpec, {**kinematic(self.study), "name": self.name}, "study."),
        ):
            try:
                schema.model_validate(data)
            except ValidationError as e:
                message = format_error(e, schema).replace("did you mean '", f"did you mean '{prefix}")
                if f'model = "{DYNAMIC_MODEL}"' in message:
                    message += " (study.vehicle is the dynamic arms' vehicle)"
                raise ValueError(prefix + message) from None
        return self

    def dynamic_vehicle(self):
        """The dynamic arms' vehicle (:class:`pfjax.montecarlo.scenario_config.VehicleSpec` of
        ``study.vehicle`` with ``model`` = :data:`DYNAMIC_MODEL`): its speed range (m/s), steering
        actuator ``tau_delta_s`` (s) and speed loop ``k_v`` (1/s), the schema's defaults where not given."""
        from pfjax.montecarlo.config import VehicleSpec

        return VehicleSpec.model_validate(dynamic(self.study)["vehicle"])  # valid: _check validated it

    def dynamic_mu(self) -> dict:
        """The dynamic arm's friction (a distribution table): uniform on ``[mu_low, mu_high]``."""
        return {"dist": "uniform", "low": self.mu_low, "high": self.mu_high}

    @property
    def grip_arm(self) -> str:
        """The high-friction arm's name (``dynamic_mu<mu_grip:g>``)."""
        return f"dynamic_mu{self.mu_grip:g}"


#: The dynamic arms' vehicle model (:class:`pfjax.montecarlo.scenario_config.VehicleSpec`'s ``model``).
DYNAMIC_MODEL = "st"


def dynamic(spec: dict, mu=None) -> dict:
    """A copy of the study config ``spec`` with the dynamic arms' vehicle model (:data:`DYNAMIC_MODEL`)
    and, if given, the friction ``mu`` (a number or a distribution table)."""
    vehicle = {**spec.get("vehicle", {}), "model": DYNAMIC_MODEL}
    return {**spec, "vehicle": vehicle if mu is None else {**vehicle, "mu": mu}}


def kinematic(spec: dict) -> dict:
    """A copy of the study config ``spec`` without the dynamic model's vehicle keys
    (``tau_delta_s``, ``k_v``: the actuator and speed loop, :data:`pfjax.montecarlo.scenario_config.MODEL_SETTINGS`),
    which the kinematic arms do not take."""
    from pfjax.montecarlo.scenario_config import other_models_settings

    drop = {m.key for m in other_models_settings("kinematic")}
    vehicle = {k: v for k, v in spec.get("vehicle", {}).items() if k not in drop}
    return {**copy.deepcopy(spec), "vehicle": copy.deepcopy(vehicle)}


def kinematic_arm(a: float, prefix: str = "kinematic_") -> str:
    """The name of the kinematic arm with constant slip uniform on ``+-a`` deg per axle."""
    return f"{prefix}{a:g}deg"


#: The ``study`` keys each arm sets itself (:mod:`pfjax.dynamic_study.arms`), and where they come from.
ARM_KEYS = {
    ("slip",): "the arms set the slip (the kinematic arms from slip_ranges_deg, the dynamic arms from the tyre forces)",
    ("vehicle", "model"): "the arms set the model (st in the dynamic arms, kinematic in the kinematic arms)",
    ("vehicle", "mu"): "the arms set the friction (mu_low, mu_high, mu_grip)",
    ("vehicle", "params"): "the arms set the parameter set (the robot's in the robot arms, car.params in the car arms)",
}


def _refuse_arm_keys(study: dict) -> None:
    """A ``ValueError`` naming the first key of ``study`` that the arms set themselves (:data:`ARM_KEYS`)."""
    for path, why in ARM_KEYS.items():
        table: Any = study
        for part in path:
            if not isinstance(table, dict) or part not in table:
                break
            table = table[part]
        else:
            key = ".".join(("study", *path))
            if isinstance(table, dict) and table:  # the key the user set under it
                key += "." + next(iter(table))
            raise ValueError(f"{key}: {why}; remove it")


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> KinematicVsDynamic:
    """The validated study config: defaults <- ``path`` <- (``--quick``) <- ``overrides``; raises
    :class:`pfjax.config.ConfigError` naming the key."""
    return load_model(KinematicVsDynamic, path, overrides, presets=[QUICK] if quick else [])[0]


__all__ = [
    "ARM_KEYS",
    "DYNAMIC_MODEL",
    "QUICK",
    "STUDY",
    "Car",
    "Designs",
    "KinematicVsDynamic",
    "dynamic",
    "kinematic",
    "kinematic_arm",
    "load",
]
