"""The vehicle-tracking study's configuration schema (``studies/vehicle_tracking.toml``).

Three sections: ``sim`` (step, horizon and the limits' tolerances of one run), ``lemma`` (the grid of
Lemma 8.1 runs and the geometric check) and ``mc`` (the robustness Monte Carlo). Every key is
optional; the defaults are the study's published sizes. Loaded by :func:`load` with the same
``--set key=value`` syntax and one-line :class:`pfjax.config.ConfigError` as the Monte Carlo study.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

from pydantic import Field, model_validator

from pfjax.config import POSITIVE, ConfigModel, Real, load_model
from pfjax.errors import MAX_SEED

#: an (along, left) offset in metres
Pair = Annotated[list[Real], Field(min_length=2, max_length=2)]

#: ``--quick``: a small grid and sample (tests, a first look)
QUICK = {
    "lemma": {
        "p": [-1.0, 1.0, 4.5],
        "l_abs": [1.0],
        "gamma_max_deg": [30.0],
        "offsets": [[-1.0, 1.0]],
        "n_geometry": 200,
    },
    "mc": {"n_runs": 24},
    "sim": {"horizon": 15.0, "dt": 0.02},
}


class TrackSim(ConfigModel):
    """One run: fixed-step integration and the limits checked over the final window."""

    dt: Real = Field(0.01, ge=POSITIVE, description="integration step [s]")
    horizon: Real = Field(30.0, ge=POSITIVE, description="simulated time per run [s]")
    window: Real = Field(5.0, ge=POSITIVE, description="final window over which the limits are checked [s]")
    tol_z: Real = Field(0.01, ge=POSITIVE, description="z~ -> 0 when max |z~| over the window <= tol_z [m]")
    tol_phi: Real = Field(
        0.02, ge=POSITIVE, description="phi - p gamma -> 0 when its max magnitude over the window <= tol_phi [rad]"
    )
    band: Real = Field(0.1, ge=POSITIVE, description="Monte Carlo success band on max |z~| over the window [m]")
    k: Real = Field(1.0, ge=POSITIVE, description="error decay rate of the controller [1/s]")
    a: Real = Field(1.0, ge=POSITIVE, description="wheelbase of the follower [m]")


class TrackLemma(ConfigModel):
    """The Lemma 8.1 grid (every combination, six leader motions, forward and backward) and the
    geometric check on random states."""

    p: list[Real] = Field(
        [-3.5, -2.0, -1.0, -0.5, 0.5, 1.0, 2.0, 3.5, 4.5], min_length=1, description="focus gains p, nonzero [-]"
    )
    l_abs: list[Real] = Field(
        [0.5, 1.5], min_length=1, description="focus distances |l|, nonzero; l = f |l| ahead in travel [m]"
    )
    gamma_max_deg: list[Real] = Field(
        [20.0, 30.0, 45.0], min_length=1, description="steering limits gamma_max, in (0, 90) [deg]"
    )
    offsets: list[Pair] = Field(
        [[0.0, 0.3], [-1.0, 1.0], [0.5, -1.5]], min_length=1, description="initial (along, left) offsets [m]"
    )
    circle_radius: Real = Field(2.5, ge=POSITIVE, description="radius of the circling leader [m]")
    n_geometry: int = Field(4000, ge=1, description="random states per p for the geometric check [-]")

    @model_validator(mode="after")
    def _check(self):
        for key in ("p", "l_abs"):
            if any(v == 0 for v in getattr(self, key)):
                raise ValueError(f"{key}: values must be nonzero, got {getattr(self, key)}")
        if not all(0 < g < 90 for g in self.gamma_max_deg):
            raise ValueError(f"gamma_max_deg: expected values in (0, 90) deg, got {self.gamma_max_deg}")
        return self


class TrackMC(ConfigModel):
    """The robustness Monte Carlo: random offsets, headings, slip, sensor noise and speeds."""

    n_runs: int = Field(2000, ge=1, description="runs per mode (forward, backward) [-]")
    p_forward: Real = Field(1.0, description="focus gain p of forward tracking [-]")
    p_backward: Real = Field(-1.0, description="focus gain p of backward tracking [-]")
    l_abs: Real = Field(1.0, gt=0, description="focus distance |l| [m]")
    gamma_max_deg: Real = Field(30.0, gt=0, lt=90, description="steering limit gamma_max [deg]")
    offset_max: Real = Field(1.0, ge=0, description="initial offset uniform in +-offset_max on each axis [m]")
    heading_error_max_deg: Real = Field(20.0, ge=0, description="initial heading error uniform in +- [deg]")
    slip_max_deg: Real = Field(3.0, ge=0, description="constant rear and front slip uniform in +- [deg]")
    sigma_pos: Real = Field(0.01, ge=0, description="position sensor noise, standard deviation [m]")
    sigma_theta_deg: Real = Field(0.5, ge=0, description="heading sensor noise, standard deviation [deg]")
    sigma_gamma_deg: Real = Field(0.5, ge=0, description="steering sensor noise, standard deviation [deg]")
    speed_low: Real = Field(0.5, description="leader speed, lower end of the uniform range [m/s]")
    speed_high: Real = Field(1.5, description="leader speed, upper end of the uniform range [m/s]")

    @model_validator(mode="after")
    def _check(self):
        if self.speed_high < self.speed_low:
            raise ValueError(f"speed_high: must be >= speed_low ({self.speed_low:g}), got {self.speed_high:g}")
        return self


class TrackingStudy(ConfigModel):
    """The vehicle-tracking study (``studies/vehicle_tracking.py``)."""

    name: str = Field("vehicle_tracking", description="output folder name under results/ [-]")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="random seed of every sample [-]")
    sim: TrackSim = TrackSim()
    lemma: TrackLemma = TrackLemma()
    mc: TrackMC = TrackMC()


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> TrackingStudy:
    """The validated study config: defaults <- ``path`` <- (``--quick``) <- ``overrides``; raises
    :class:`pfjax.config.ConfigError` naming the key."""
    return load_model(TrackingStudy, path, overrides, presets=[QUICK] if quick else [])[0]


__all__ = ["QUICK", "TrackLemma", "TrackMC", "TrackSim", "TrackingStudy", "load"]
