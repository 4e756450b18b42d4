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

import contextlib
import contextvars
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator, model_validator

from pfjax.config import ConfigModel, Label, Real, load_model
from pfjax.errors import MAX_SEED
from pfjax.models import DYNAMIC_MODELS
from pfjax.montecarlo.analysis_config import Axis, FalsifierSpec, MarginSpec, RareEventSpec
from pfjax.montecarlo.dists import Dist, dist_field, nominal
from pfjax.montecarlo.scenario_config import (
    MODEL_SETTINGS,
    OU_REACH,
    InitialSpec,
    NoiseSpec,
    PathSpec,
    SimSpec,
    SlipSpec,
    SuccessSpec,
    VehicleSpec,
    slip_refusal,
)
from pfjax.provenance import config_hash
from pfjax.resources import MAX_STEPS

__all__ = [
    "MODEL_SETTINGS",
    "OU_REACH",
    "Axis",
    "ControllerSpec",
    "Dist",
    "FalsifierSpec",
    "InitialSpec",
    "MarginSpec",
    "NoiseSpec",
    "PathSpec",
    "RareEventSpec",
    "SimSpec",
    "SlipSpec",
    "StudySpec",
    "SuccessSpec",
    "VehicleSpec",
    "dist_field",
    "load_study",
    "nominal",
    "study_hash",
]


class ControllerSpec(ConfigModel):
    """A controller to compare. ``type``: a registered controller (state_feedback, pi, integral,
    stanley, pure_pursuit, rear_wheel, ...; :data:`pfjax.controllers.REGISTRY`) or a design
    (lmi: mixed H2/H-inf with ``alpha``, ``beta`` at the nominal speed and wheelbase; integral_lmi;
    paper_k: the source's published gain; :data:`pfjax.controllers.DESIGNS`). ``gains`` by name
    override the defaults or the design; ``K`` is the vector gain of state_feedback and integral."""

    name: Label = Field(description="label in outputs")
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
        from pfjax.controllers.registry import check_gain_names

        e, d = resolve(self.type)
        check_gain_names(
            e, self.gains, called=self.type
        )  # as it loads, like every other key (before --out is looked at)
        if self.K is not None:
            if d is not None or "K" not in e.labels:
                raise ValueError(
                    f"K is only for types with a vector gain K "
                    f"({', '.join(n for n, x in _registry().items() if 'K' in x.labels)}), not {self.type!r}"
                )
            if len(self.K) != len(e.labels["K"]):
                raise ValueError(f"{self.type} needs K = [{', '.join(e.labels['K'])}]")
        if d is not None and self.alpha + self.beta == 0:  # the synthesis's own check and message
            from pfjax.synthesis.lmi import check_weights

            check_weights(self.alpha, self.beta)
        return self


def _registry():
    from pfjax.controllers import REGISTRY

    return REGISTRY


class StudySpec(ConfigModel):
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
        if self.slip.kind == "ou" and self.sim.horizon / self.slip.seq_dt > MAX_STEPS:
            raise ValueError(
                f"slip.seq_dt: sim.horizon / seq_dt (the slip samples per run) may be at most {MAX_STEPS:.0e}, "
                f"got {self.sim.horizon:g} / {self.slip.seq_dt:g} = {self.sim.horizon / self.slip.seq_dt:.3g}"
            )
        if self.falsifier.path is not None and self.falsifier.path not in [p.label for p in self.paths]:
            raise ValueError(
                f"falsifier.path: no path labelled {self.falsifier.path!r}; paths are {[p.label for p in self.paths]}"
            )
        if self.vehicle.model in DYNAMIC_MODELS:
            changed = [k for k, v in self.slip if v != SlipSpec.model_fields[k].get_default(call_default_factory=True)]
            if changed:
                key = changed[0]
                raise ValueError(
                    f'slip.{key}: not with vehicle.model = "{self.vehicle.model}" '
                    f"({slip_refusal(self.vehicle.model)}); remove it"
                )
            from pfjax.models.single_track import check_step, with_mu

            veh = self.vehicle
            mu_hi = veh.st_params().mu if veh.mu is None else veh.mu.bounds()[1]
            params = with_mu(veh.model_params(), mu_hi)
            v_lo = veh.speed.bounds()[0]
            if _CHECK_STEP.get():
                check_step(
                    "sim.dt", self.sim.dt, params, v_lo, veh.tau_delta_s, veh.k_v, worst_case="the ranges' worst case"
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

#: Whether a :class:`StudySpec` being validated checks ``sim.dt`` against the single-track models'
#: tyre modes (off only inside :func:`step_checked_by_simulate`).
_CHECK_STEP: contextvars.ContextVar[bool] = contextvars.ContextVar("pfjax_check_step", default=True)


@contextlib.contextmanager
def step_checked_by_simulate() -> Iterator[None]:
    """Validate study configs without the single-track models' step check (``sim.dt`` against the
    tyre modes, :func:`pfjax.models.single_track.check_step`): for :func:`pfjax.scenarios`, whose
    ``sim`` section only sizes the slip sequences; :func:`pfjax.simulate` checks the step its runs
    take (``config.dt``) against the same worst case."""
    token = _CHECK_STEP.set(False)
    try:
        yield
    finally:
        _CHECK_STEP.reset(token)


def load_study(
    path: str | Path | None = None, overrides: Sequence[str] = (), data: dict | None = None, values: dict | None = None
) -> tuple[StudySpec, dict]:
    """Read, override and validate a study. Returns ``(spec, raw_dict)``; raises ConfigError.

    Args:
        path: a TOML file (else ``data``, a dict).
        overrides: ``--set`` texts ``"key=value"`` (the value parsed as TOML).
        values: overrides as Python values by dotted key (``{"sim.horizon": 30, "paths": [...]}``).
    """
    return load_model(StudySpec, path, overrides, data=data, values=values)


def study_hash(spec: StudySpec) -> str:
    """SHA-256 of the validated study (defaults filled in), so equivalent files hash alike."""
    return config_hash(spec.model_dump(mode="json"))
