"""The parking study's config (``studies/parking.toml``): one pydantic schema of the
:class:`pfjax.config.ConfigModel` family, read by :func:`load` with ``--set key=value`` overrides and
the ``--quick`` preset :data:`QUICK`. A bad key or value raises :class:`pfjax.config.ConfigError`,
one line naming the key. Its defaults are :mod:`pfjax.parking.defaults`'s (the simulator's and the
entry points')."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from pfjax.config import POSITIVE, ConfigModel, Real, load_model
from pfjax.errors import MAX_SEED
from pfjax.parking import defaults as D
from pfjax.parking.limits import MAX_SCAN_PERIOD
from pfjax.resources import MAX_GENERATIONS, MAX_POPULATION

#: a part of the robot's rectangle checked toward the travel direction (pfjax.parking.assumptions.ZONES)
Zone = Literal["middle", "axle", "whole"]
#: the assumptions sweep's and the Monte Carlo's defaults
_GRID, S = D.ASSUMPTION_GRID, D.Scatter


class Controller(ConfigModel):
    """The source's controller: gains k1, k2 (roots -4 ± 4i) and travel speed |v1|."""

    k1: Real = Field(D.K1, ge=POSITIVE, description="gain on the lateral error [1/m²]")
    k2: Real = Field(D.K2, ge=POSITIVE, description="gain on the heading error [1/m]")
    speed: Real = Field(D.SPEED, ge=POSITIVE, description="travel speed |v1| [m/s]")


class Sim(ConfigModel):
    """Single runs: scanner period, timeout, tolerance, integration and the stuck test."""

    scan_period: Real = Field(D.SCAN_PERIOD, ge=POSITIVE, le=MAX_SCAN_PERIOD, description="scanner sampling period [s]")
    t_max: Real = Field(D.T_MAX, ge=POSITIVE, description="timeout of a run [s]")
    tol: Real = Field(D.TOL, ge=POSITIVE, description="stop when |x| + sqrt(y² + tan²θ) < tol [m]")
    n_sub: int = Field(D.N_SUB, ge=1, le=100, description="RK4 steps per scanner period, at most 100 [-]")
    front: Real = Field(0.0, ge=0, lt=D.L2_LENGTH, description="a_f, reach ahead of the axle; 0 = calibrated [m]")
    chunk: int = Field(D.CHUNK, ge=1, le=10_000_000, description="runs per jitted batch (memory-checked) [-]")
    stuck_switches: int = Field(
        D.STUCK_SWITCHES, ge=1, le=1000, description="legs over which stuck_travel is measured, at most 1000 [-]"
    )
    stuck_travel: Real = Field(
        D.STUCK_TRAVEL, ge=0, description="stuck: less travel than this over stuck_switches legs [m]"
    )

    @model_validator(mode="after")
    def _steps(self):
        from pfjax.parking.limits import check_periods

        if 0 < self.front < POSITIVE:  # 0 is the calibrated reach; any other as pfjax parking --front takes it
            raise ValueError(f"front: must be 0 (calibrated) or at least {POSITIVE:g} m, got {self.front:g}")
        check_periods("scan_period", self.t_max, self.scan_period, "sim.t_max")
        return self


class Assumptions(ConfigModel):
    """The open assumptions of docs/reproductions/parking.md §3, swept over cases A-D (every combination)."""

    fronts: list[Real] = Field(list(_GRID["front"]), min_length=1, description="reach ahead of the axle [m]")
    zones: list[Zone] = Field(list(_GRID["zone"]), min_length=1, description="part checked ahead [-]")
    scan_periods: list[Real] = Field(list(_GRID["scan_period"]), min_length=1, description="scanner periods [s]")
    decision_delays: list[bool] = Field(
        list(_GRID["decision_delay"]), min_length=1, description="decide on the pose one period old [-]"
    )
    lags: list[bool] = Field(list(_GRID["lag"]), min_length=1, description="the experiments' yaw-rate PI loop [-]")
    pauses: list[Real] = Field(list(_GRID["pause"]), min_length=1, description="time standing at each reversal [s]")

    @model_validator(mode="after")
    def _ranges(self):
        for key, vals, hi in (("fronts", self.fronts, D.L2_LENGTH), ("scan_periods", self.scan_periods, 1)):
            for i, f in enumerate(vals):  # positive: at least 1e-12, as every positive length and step
                if not POSITIVE <= f <= hi or (key == "fronts" and f >= hi):
                    close = ")" if key == "fronts" else "]"
                    raise ValueError(f"{key}[{i}]: must be in [{POSITIVE:g}, {hi}{close}, got {f}")
        for i, p in enumerate(self.pauses):
            if p < 0:
                raise ValueError(f"pauses[{i}]: must be >= 0 s, got {p}")
        return self


class Experiment(ConfigModel):
    """The source's experiments, as pfjax models them."""

    pause: Real = Field(
        D.EXPERIMENT_PAUSE,
        ge=0,
        description="pfjax's stop at each reversal in the experiments' runs (the source: 1 s) [s]",
    )


class Garage(ConfigModel):
    """The garage tries."""

    xs_values: list[Real] = Field(list(D.GARAGE_TRIES), min_length=1, description="switch abscissae X_s tried [m]")


class Search(ConfigModel):
    """docs/reproductions/parking.md §5: 24-bit GA and a grid on the chromosome lattice."""

    weight: Real = Field(D.WEIGHT, ge=0, description="weight w of the end error in the fitness J = 1/(t_e + w e) [s/m]")
    population: int = Field(D.POPULATION, ge=2, le=MAX_POPULATION, description="GA population size [-]")
    generations: int = Field(D.GENERATIONS, ge=1, le=MAX_GENERATIONS, description="GA generations [-]")
    grid_n: int = Field(D.GRID_N, ge=2, le=D.MAX_GRID_N, description="grid points per schedule parameter [-]")
    ga_seeds: int = Field(3, ge=1, le=1000, description="independent GA runs (work-checked) [-]")
    max_switches: int = Field(
        D.SEARCH_MAX_SWITCHES, ge=1, le=1000, description="a candidate switching more often fails, at most 1000 [-]"
    )


class StartMap(ConfigModel):
    """Other starts (y0 = 0.6): best (X_s, α1, α2) on a grid_n³ grid per start."""

    x0: list[Real] = Field([-1.5, -1.3, -1.1, -0.9, -0.7], min_length=1, description="start abscissae [m]")
    theta0_deg: list[Real] = Field(
        [-80.0, -40.0, 0.0, 40.0, 80.0], min_length=1, description="start headings, magnitude < 90 [deg]"
    )
    grid_n: int = Field(10, ge=2, le=D.MAX_GRID_N, description="grid points per schedule parameter [-]")

    @model_validator(mode="after")
    def _headings(self):
        for i, th in enumerate(self.theta0_deg):
            if abs(th) >= 90:
                raise ValueError(f"theta0_deg[{i}]: magnitude must be < 90, got {th}")
        return self


class MonteCarlo(ConfigModel):
    """Garage robustness: fixed schedule vs the GA's and the grid's best on the same sampled runs."""

    n_runs: int = Field(1000, ge=1, description="sampled runs per schedule (work-checked) [-]")
    pos_scatter: Real = Field(S.pos_scatter, ge=0, description="half-width of the uniform scatter of x0 and y0 [m]")
    theta_scatter_deg: Real = Field(
        S.theta_scatter_deg, ge=0, description="half-width of the uniform scatter of θ0 [deg]"
    )
    scan_lo: Real = Field(S.scan_lo, ge=POSITIVE, description="smallest scanner period [s]")
    scan_hi: Real = Field(S.scan_hi, ge=POSITIVE, le=MAX_SCAN_PERIOD, description="largest scanner period [s]")
    speed_lo: Real = Field(S.speed_lo, ge=POSITIVE, description="smallest travel speed [m/s]")
    speed_hi: Real = Field(S.speed_hi, ge=POSITIVE, description="largest travel speed [m/s]")
    lag_probability: Real = Field(S.lag_probability, ge=0, le=1, description="probability of the yaw-rate lag [-]")

    @model_validator(mode="after")
    def _ranges(self):
        if self.scan_lo > self.scan_hi:
            raise ValueError(f"scan_lo: must be <= scan_hi, got {self.scan_lo} > {self.scan_hi}")
        if self.speed_lo > self.speed_hi:
            raise ValueError(f"speed_lo: must be <= speed_hi, got {self.speed_lo} > {self.speed_hi}")
        return self


class ParkingStudy(ConfigModel):
    """The parking study (docs/reproductions/parking.md): cases, assumptions sweep, garage tries,
    searches, start map and Monte Carlo."""

    name: str = Field("parking", description="output folder name under results/ [-]")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="PRNG seed of the GA and the Monte Carlo [-]")
    controller: Controller = Field(default_factory=Controller, description="controller gains and speed")
    sim: Sim = Field(default_factory=Sim, description="single runs")
    assumptions: Assumptions = Field(default_factory=Assumptions, description="assumptions sweep")
    garage: Garage = Field(default_factory=Garage, description="garage tries")
    experiment: Experiment = Field(default_factory=Experiment, description="the source's experiments")
    search: Search = Field(default_factory=Search, description="GA and grid searches")
    start_map: StartMap = Field(default_factory=StartMap, description="start-pose map")
    montecarlo: MonteCarlo = Field(default_factory=MonteCarlo, description="robustness Monte Carlo")

    @model_validator(mode="after")
    def _work(self):
        """Every scanner period the study simulates within the loop's bound, and the searches' size
        within the API's (:func:`pfjax.parking.api.check_search_work`), each named by its key."""
        from pfjax.parking.api import check_search_work
        from pfjax.parking.limits import check_periods
        from pfjax.parking.runs import ParkingConfig, run_bytes
        from pfjax.resources import check_memory

        t_max = self.sim.t_max
        periods = [(f"assumptions.scan_periods[{i}]", p) for i, p in enumerate(self.assumptions.scan_periods)]
        mc = [("montecarlo.scan_lo", self.montecarlo.scan_lo), ("montecarlo.scan_hi", self.montecarlo.scan_hi)]
        for key, period in [*periods, *mc]:
            check_periods(key, t_max, period, "sim.t_max")
        se, sm, scan = self.search, self.start_map, self.sim.scan_period
        n = se.grid_n
        check_search_work("search.grid_n", n**3, f"grid_n^3 = {n}^3 = {n**3}", t_max, scan)
        runs = se.population * (se.generations + 1)
        how = f"population x (generations + 1) = {se.population} x {se.generations + 1} = {runs}"
        check_search_work("search.population/search.generations", runs, how, t_max, scan)
        how = f"ga_seeds x population x (generations + 1) = {se.ga_seeds} x {runs} = {se.ga_seeds * runs}"
        check_search_work("search.ga_seeds", se.ga_seeds * runs, how, t_max, scan, "the GA runs together")
        # the Monte Carlo's three schedules, each n_runs runs, at its shortest scanner period
        mc = self.montecarlo
        how = f"3 schedules x n_runs = 3 x {mc.n_runs} = {3 * mc.n_runs}"
        check_search_work("montecarlo.n_runs", 3 * mc.n_runs, how, t_max, mc.scan_lo, "the Monte Carlo")
        starts, m = len(sm.x0) * len(sm.theta0_deg), sm.grid_n
        how = f"starts x grid_n^3 = {starts} x {m}^3 = {starts * m**3}"
        check_search_work("start_map.grid_n", starts * m**3, how, t_max, scan)
        # one jitted batch of sim.chunk runs, each with a switch log of the searches' length or the default's
        log_len = max(se.max_switches + 1, ParkingConfig().log_capacity)
        check_memory(
            "sim.chunk",
            self.sim.chunk * run_bytes(log_len),
            f"a batch of sim.chunk = {self.sim.chunk} runs",
            f"lower sim.chunk ({D.CHUNK} by default)",
        )
        return self


#: the ``--quick`` sizes (tests)
QUICK: dict = {
    "sim": {"chunk": 32},
    "search": {"population": 4, "generations": 2, "grid_n": 3, "ga_seeds": 2},
    "start_map": {"grid_n": 2, "x0": [-1.3, -0.9], "theta0_deg": [-80.0, 40.0]},
    "montecarlo": {"n_runs": 16},
    "assumptions": {
        "fronts": [0.15, 0.2],
        "scan_periods": [0.1],
        "decision_delays": [False],
        "lags": [False],
        "pauses": [0.0],
    },
}


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> ParkingStudy:
    """The validated study config from a TOML ``path`` (else the defaults), ``--set`` ``overrides``
    and, with ``quick``, the :data:`QUICK` sizes. Raises :class:`pfjax.config.ConfigError`."""
    return load_model(ParkingStudy, path, overrides, presets=[QUICK] if quick else [])[0]
