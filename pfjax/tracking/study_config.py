"""The vehicle-tracking study's configuration schema (``studies/vehicle_tracking.toml``).

Three sections: ``sim`` (step, horizon and the limits' tolerances of one run), ``lemma`` (the grid of
Lemma 8.1 runs and the geometric check) and ``mc`` (the robustness Monte Carlo). Every key is
optional; the defaults are the study's published sizes. Loaded by :func:`load` with the same
``--set key=value`` syntax and one-line :class:`pfjax.config.ConfigError` as the Monte Carlo study.
The quantities ``pfjax track`` also takes are checked by its checks (:func:`pfjax.tracking.api.check_time`,
:func:`pfjax.tracking.api.nonzero`), and the sizes against the memory budget (:func:`check_resources`),
before any work.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

from pydantic import Field, model_validator

from pfjax.config import POSITIVE, ConfigError, ConfigModel, Real, load_model
from pfjax.errors import MAX_SEED, InputError
from pfjax.resources import check_memory
from pfjax.tracking.api import MAX_STEPS, check_offset, check_time, nonzero
from pfjax.tracking.controller import FocusGains
from pfjax.tracking.model import FollowerParams
from pfjax.tracking.simulate import TrackConfig

#: an (along, left) offset in metres
Pair = Annotated[list[Real], Field(min_length=2, max_length=2)]
#: a positive length (at least :data:`pfjax.config.POSITIVE`)
Positive = Annotated[Real, Field(ge=POSITIVE)]

#: Bytes the study holds per run of the Lemma grid (its scenario, row and metrics), per random state
#: of the geometric check (two rows of the geometry table and the draws' temporaries) and per Monte
#: Carlo run (its sampled leader, slip and key, row and metrics), until the tables are written.
#: Measured (peak resident memory of ``studies/vehicle_tracking.py`` against the size): 1.2 kB per
#: grid run (10^4 to 1.7 x 10^5 runs), 0.52 kB per state (3 x 10^5 to 9 x 10^6 states), 5.9 kB per
#: Monte Carlo run (4 x 10^4 to 1.2 x 10^5 runs).
LEMMA_RUN_BYTES = 2000
GEOMETRY_STATE_BYTES = 800
MC_RUN_BYTES = 8000

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
    """One run: fixed-step integration and the limits checked over the final window. The defaults are
    :class:`pfjax.tracking.simulate.TrackConfig`'s, ``FocusGains.k`` and ``FollowerParams.a``
    (those of :func:`pfjax.tracking.run`)."""

    dt: Real = Field(TrackConfig.dt, ge=POSITIVE, description="integration step, in (0, horizon] [s]")
    horizon: Real = Field(
        TrackConfig.horizon,
        ge=POSITIVE,
        description=f"simulated time per run, a whole number of steps dt, at most {MAX_STEPS:.0e} of them [s]",
    )
    window: Real = Field(
        TrackConfig.window,
        ge=POSITIVE,
        description="final window over which the limits are checked, in (0, horizon] [s]",
    )
    tol_z: Real = Field(
        TrackConfig.tol_z, ge=POSITIVE, description="z~ -> 0 when max |z~| over the window <= tol_z [m]"
    )
    tol_phi: Real = Field(
        TrackConfig.tol_phi,
        ge=POSITIVE,
        description="phi - p gamma -> 0 when its max magnitude over the window <= tol_phi [rad]",
    )
    band: Real = Field(
        TrackConfig.band, ge=POSITIVE, description="Monte Carlo success band on max |z~| over the window [m]"
    )
    k: Real = Field(float(FocusGains().k), ge=POSITIVE, description="error decay rate of the controller [1/s]")
    a: Real = Field(float(FollowerParams().a), ge=POSITIVE, description="wheelbase of the follower [m]")

    @model_validator(mode="after")
    def _check(self):
        check_time(self.horizon, self.dt, self.window)  # the checks of pfjax.tracking.run
        return self


class TrackLemma(ConfigModel):
    """The Lemma 8.1 grid (every combination, six leader motions, forward and backward) and the
    geometric check on random states."""

    p: list[Real] = Field(
        [-3.5, -2.0, -1.0, -0.5, 0.5, 1.0, 2.0, 3.5, 4.5], min_length=1, description="focus gains p, nonzero [-]"
    )
    l_abs: list[Positive] = Field(
        [0.5, 1.5], min_length=1, description="focus distances |l|, > 0; l = f |l| ahead in travel [m]"
    )
    gamma_max_deg: list[Real] = Field(
        [20.0, 30.0, 45.0], min_length=1, description="steering limits gamma_max, in (0, 90) [deg]"
    )
    offsets: list[Pair] = Field(
        [[0.0, 0.3], [-1.0, 1.0], [0.5, -1.5]], min_length=1, description="initial (along, left) offsets [m]"
    )
    circle_radius: Real = Field(2.5, ge=POSITIVE, description="radius of the circling leader [m]")
    n_geometry: int = Field(
        4000,
        ge=1,
        description="random states per p, gamma_max, mode and |l| for the geometric check (memory-checked) [-]",
    )

    @model_validator(mode="after")
    def _check(self):
        for v in self.p:
            nonzero("p", v, "p")
        if not all(0 < g < 90 for g in self.gamma_max_deg):
            raise ValueError(f"gamma_max_deg: expected values in (0, 90) deg, got {self.gamma_max_deg}")
        for i, (along, left) in enumerate(self.offsets):
            check_offset(f"offsets[{i}]", math.hypot(along, left))
        return self


class TrackMC(ConfigModel):
    """The robustness Monte Carlo: random offsets, headings, slip, sensor noise and speeds."""

    n_runs: int = Field(2000, ge=1, description="runs per mode (forward, backward; memory-checked) [-]")
    p_forward: Real = Field(1.0, description="focus gain p of forward tracking, nonzero [-]")
    p_backward: Real = Field(-1.0, description="focus gain p of backward tracking, nonzero [-]")
    l_abs: Positive = Field(1.0, description="focus distance |l|, > 0 [m]")
    gamma_max_deg: Real = Field(30.0, gt=0, lt=90, description="steering limit gamma_max [deg]")
    offset_max: Real = Field(1.0, ge=0, description="initial offset uniform in +-offset_max on each axis [m]")
    heading_error_max_deg: Real = Field(20.0, ge=0, description="initial heading error uniform in +- [deg]")
    slip_max_deg: Real = Field(3.0, ge=0, lt=90, description="constant rear and front slip uniform in +-, < 90 [deg]")
    sigma_pos: Real = Field(0.01, ge=0, description="position sensor noise, standard deviation [m]")
    sigma_theta_deg: Real = Field(0.5, ge=0, description="heading sensor noise, standard deviation [deg]")
    sigma_gamma_deg: Real = Field(0.5, ge=0, description="steering sensor noise, standard deviation [deg]")
    speed_low: Positive = Field(0.5, description="leader speed, lower end of the uniform range, > 0 [m/s]")
    speed_high: Positive = Field(1.5, description="leader speed, upper end of the uniform range, >= speed_low [m/s]")

    @model_validator(mode="after")
    def _check(self):
        nonzero("p_forward", self.p_forward, "p")
        nonzero("p_backward", self.p_backward, "p")
        o = self.offset_max  # the sample's farthest start: the corner (o, o)
        check_offset("offset_max", math.hypot(o, o), f" for the sample's corner ({o:g}, {o:g}) m")
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


def sizes(config: TrackingStudy) -> dict[str, int]:
    """The study's sizes: runs of the Lemma grid (both modes, six leaders), random states of the
    geometric check (``n_geometry`` per distinct ``p``, ``gamma_max``, mode and ``|l|``) and Monte Carlo
    runs (both modes)."""
    g = config.lemma
    return {
        "lemma_runs": 2 * 6 * len(g.p) * len(g.l_abs) * len(g.gamma_max_deg) * len(g.offsets),
        "geometry_states": g.n_geometry * len(set(g.p)) * len(g.gamma_max_deg) * 2 * len(g.l_abs),
        "mc_runs": 2 * config.mc.n_runs,
    }


def check_resources(config: TrackingStudy) -> None:
    """:class:`pfjax.config.ConfigError` when the study's tables, held together until they are
    written, would not fit in :func:`pfjax.resources.memory_budget`; it names the key of the
    largest part: ``lemma.n_geometry``, ``mc.n_runs`` or the longest list of the Lemma grid
    (``lemma.p``, ``lemma.l_abs``, ``lemma.gamma_max_deg``, ``lemma.offsets``). The step count of
    one run is checked with the ``sim`` section (``sim.horizon/dt``)."""
    n = sizes(config)
    g = config.lemma
    grid_key = "lemma." + max(("p", "l_abs", "gamma_max_deg", "offsets"), key=lambda k: len(getattr(g, k)))
    parts = {
        grid_key: n["lemma_runs"] * LEMMA_RUN_BYTES,
        "lemma.n_geometry": n["geometry_states"] * GEOMETRY_STATE_BYTES,
        "mc.n_runs": n["mc_runs"] * MC_RUN_BYTES,
    }
    key = max(parts, key=parts.__getitem__)
    what = (
        f"holding the study's tables ({n['lemma_runs']:.3g} Lemma grid runs, {n['geometry_states']:.3g} geometry "
        f"states, {n['mc_runs']:.3g} Monte Carlo runs)"
    )
    try:
        check_memory(key, sum(parts.values()), what, f"lower {key}")
    except InputError as e:
        raise ConfigError(str(e)) from None


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> TrackingStudy:
    """The validated study config: defaults <- ``path`` <- (``--quick``) <- ``overrides``; raises
    :class:`pfjax.config.ConfigError` naming the key, also when the study would not fit in memory
    (:func:`check_resources`)."""
    config = load_model(TrackingStudy, path, overrides, presets=[QUICK] if quick else [])[0]
    check_resources(config)
    return config


__all__ = [
    "GEOMETRY_STATE_BYTES",
    "LEMMA_RUN_BYTES",
    "MC_RUN_BYTES",
    "QUICK",
    "TrackLemma",
    "TrackMC",
    "TrackSim",
    "TrackingStudy",
    "check_resources",
    "load",
    "sizes",
]
