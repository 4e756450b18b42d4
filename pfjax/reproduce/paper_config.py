"""The paper-reproduction study's configuration schema (``studies/paper_reproduction.toml``).

Sections: ``model`` (the source's Table 1 and its slip angles), ``sim`` (the integration and the
metrics' windows), ``synthesis`` (the mixed H2/Hinf objective), ``source`` (the source's published
values, compared against and never used to tune), ``stability`` (the (beta_r, beta_f) grid and
its simulation cross-check), ``long_horizon`` and ``ga`` (Table 2's GA readings). Every key is
optional; the defaults are the study's published settings. Loaded by :func:`load` with the same
``--set key=value`` syntax and one-line :class:`pfjax.config.ConfigError` as the Monte Carlo study;
every simulation setting, synthesis weight, GA option and size the study uses is checked there,
and the study's two LMI problems are solved there (:func:`check_synthesis`), before any work.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from pfjax.config import POSITIVE, ConfigError, ConfigModel, Real, load_model
from pfjax.errors import MAX_SEED, InputError, renamed
from pfjax.resources import check_memory, check_steps, run_bytes

#: ``--quick``: a 6 s horizon (the sine analysis needs > 5 s), 10 ms steps, the controller sampled
#: every step, a 3 x 3 stability grid, no trackers and a tiny GA (tests, a first look)
QUICK = {
    "sim": {"horizon": 6.0, "dt": 0.01, "control_every": 1, "steady_window": 1.0},
    "stability": {"n": 3, "horizon": 6.0, "eig_n": 11},
    "trackers": False,
    "long_horizon": 8.0,
    "ga": {"population": 6, "generations": 2, "seeds": 2},
}


class PaperModel(ConfigModel):
    """The vehicle of the source (Table 1, §6) and the direction its paths are travelled;
    ``delta_max_deg`` and ``direction`` are assumed."""

    v: Real = Field(1.0, ge=POSITIVE, description="forward speed [m/s]")
    L: Real = Field(0.2, ge=POSITIVE, description="wheelbase [m]")
    delta_max_deg: Real = Field(30.0, gt=0, lt=90, description="steering limit (assumed) [deg]")
    convention: Literal["source", "lenain"] = Field(
        "source", description="front-slip sign: 'source' tan(delta - beta_f) or 'lenain' tan(delta + beta_f) [-]"
    )
    beta_r_deg: Real = Field(5.0, gt=-90, lt=90, description="constant rear slip angle [deg]")
    beta_f_deg: Real = Field(5.0, gt=-90, lt=90, description="constant front slip angle [deg]")
    direction: Literal["increasing_x", "decreasing_x"] = Field(
        "increasing_x",
        description="direction of travel along the source's paths (assumed); 'decreasing_x' starts from the same "
        "point with the heading mirrored in the path's normal (pfjax.reproduce.paper_runs.source_test) [-]",
    )


class PaperSim(ConfigModel):
    """The integration of one run and the windows of its metrics."""

    dt: Real = Field(0.005, ge=POSITIVE, description="RK4 step [s]")
    horizon: Real = Field(20.0, gt=5.0, description="simulated time; > 5 s (the sine-error analysis uses t >= 5 s) [s]")
    control_every: int = Field(
        0, ge=0, description="0: controller inside every RK4 stage; n: sampled every n steps [steps]"
    )
    settle_band: Real = Field(0.05, ge=POSITIVE, description="|d| band of the settling time [m]")
    steady_window: Real = Field(5.0, ge=POSITIVE, description="final window of the steady-state errors [s]")


class PaperSynthesis(ConfigModel):
    """The msfsyn objective alpha gamma_inf^2 + beta gamma_2^2 (source eq. 13)."""

    alpha: Real = Field(10.0, ge=0, description="weight of gamma_inf^2 [-]")
    beta: Real = Field(1.0, ge=0, description="weight of gamma_2^2 [-]")


class PaperSource(ConfigModel):
    """The source's published values (compared against, never used to tune; ``K`` and ``table3`` are
    also the gains the source's controllers run with: the "source's K" and the Table 3 PI, in the
    adopted reading of :data:`pfjax.controllers.PAPER_PI`, and its 24 readings). Each is checked
    where a value would make its comparison meaningless: ``K`` stabilising (both gains < 0, the
    only sign for which ``A + B_u K`` of the design model is Hurwitz, docs §7), the bounds and
    errors positive, the eigenvalue maxima nonzero (each is compared within a relative tolerance)."""

    K: list[Real] = Field(
        [-2.7381, -2.0772], min_length=2, max_length=2, description="state feedback, both < 0 [1/m, -]"
    )
    gamma_inf: Real = Field(1.1, gt=0, description="published Hinf bound [-]")
    gamma_2: Real = Field(4.07, gt=0, description="published H2 bound [-]")
    table3: list[Real] = Field(
        [1.6390, 0.0230, 39.5204, 11.6124], min_length=4, max_length=4, description="Table 3 PI gains [-]"
    )
    line_ss_mixed_mm_below: Real = Field(3.0, gt=0, description="line test: mixed steady-state error below [mm]")
    line_ss_pi_mm: Real = Field(8.0, gt=0, description="line test: PI steady-state error [mm]")
    line_delta_deg: Real = Field(10.0, gt=-90, lt=90, description="line test: steering reading [deg]")
    eig_max_re: list[Real] = Field(
        [-1.3185, -5.1930],
        min_length=2,
        max_length=2,
        description="largest real parts, slow and fast, nonzero, attributed to Figs. 4-5 (assumed: the "
        "reconstructed source gives no number) [1/s]",
    )

    @model_validator(mode="after")
    def _check(self):
        if not all(k < 0 for k in self.K):
            raise ValueError(
                f"K: both gains must be < 0 (A + B_u K is Hurwitz only for K_d, K_theta < 0), got {_values(self.K)}"
            )
        if 0 in self.eig_max_re:
            raise ValueError(f"eig_max_re: both values must be nonzero, got {_values(self.eig_max_re)}")
        # the readings are labelled by their values to 6 significant digits (controllers.table3_label):
        # values equal there would give fewer than 24 readings
        if len({f"{v:g}" for v in self.table3}) != len(self.table3):
            raise ValueError(
                f"table3: the four values must differ in their first 6 significant digits (24 readings), "
                f"got {self.table3}"
            )
        return self


def _values(values) -> str:
    return "[" + ", ".join(f"{v:g}" for v in values) + "]"


class PaperStability(ConfigModel):
    """The (beta_r, beta_f) stability grid and its simulation cross-check."""

    grid_max_deg: Real = Field(60.0, gt=0, lt=90, description="grid half-width in each slip angle [deg]")
    n: int = Field(31, ge=2, description="grid points per axis [-]")
    horizon: Real = Field(40.0, ge=POSITIVE, description="simulated time of the cross-check runs [s]")
    tol_d: Real = Field(
        0.001, ge=POSITIVE, description="converged when |d - d*| < tol_d at the end (d* the true equilibrium) [m]"
    )
    tol_theta_deg: Real = Field(
        0.1, ge=POSITIVE, description="converged when |theta_e - theta_e*| < tol_theta_deg at the end [deg]"
    )
    eig_grid_max_deg: Real = Field(89.9, gt=0, lt=90, description="half-width of the eigenvalue scan [deg]")
    eig_n: int = Field(721, ge=2, description="points of the eigenvalue scan per axis [-]")


class PaperGA(ConfigModel):
    """Table 2's GA readings: the PI tuned with and without crossover on the same seeds."""

    seeds: int = Field(3, ge=1, description="GA runs per reading [-]")
    scenario: str = Field("paper-line", description="tuning scenario [-]")
    population: int = Field(50, ge=2, description="population size [-]")
    generations: int = Field(100, ge=1, description="generations (assumed: Table 2 gives no generation count) [-]")
    cost: Literal["iae", "ise", "itae"] = Field(
        "iae", description="the tuning cost of eq. 15, whose exact form was lost (assumed, docs §5) [-]"
    )


class PaperStudy(ConfigModel):
    """The paper-reproduction study (``studies/paper_reproduction.py``)."""

    name: str = Field("paper_reproduction", description="output folder name under results/ [-]")
    seed: int = Field(
        0,
        ge=0,
        le=MAX_SEED,
        description="the first of the GA readings' seeds (seed, seed + 1, ...: ga.seeds of them); the rest of the "
        "study draws nothing [-]",
    )
    model: PaperModel = PaperModel()
    sim: PaperSim = PaperSim()
    synthesis: PaperSynthesis = PaperSynthesis()
    trackers: bool = Field(True, description="also run Stanley, pure pursuit and rear-wheel feedback [-]")
    source: PaperSource = PaperSource()
    stability: PaperStability = PaperStability()
    long_horizon: Real = Field(300.0, ge=POSITIVE, description="the PI's line test run until it settles [s]")
    ga: PaperGA = PaperGA()

    @model_validator(mode="after")
    def _check(self):
        s, st = self.sim, self.stability
        if self.seed + self.ga.seeds - 1 > MAX_SEED:  # the GA readings' last seed
            raise ValueError(
                f"seed: at most {MAX_SEED - self.ga.seeds + 1} with ga.seeds = {self.ga.seeds}, got {self.seed}"
            )
        if s.steady_window > s.horizon:
            raise ValueError(f"sim.steady_window: must be in (0, sim.horizon], got {s.steady_window:g}")
        sim = self.model_dump(mode="json")
        # every simulation setting the study builds, built here: a bad horizon or step is named now
        for key, horizon in (
            ("sim.horizon", s.horizon),
            ("stability.horizon", st.horizon),
            ("long_horizon", self.long_horizon),
        ):
            try:
                sim_config(sim, horizon=horizon)
            except InputError as e:
                raise ValueError(str(_named(e, key))) from None
        from pfjax.synthesis.lmi import check_weights

        try:
            check_weights(self.synthesis.alpha, self.synthesis.beta)
        except InputError as e:
            raise ValueError(str(renamed(renamed(e, "alpha", "synthesis.alpha"), "beta", "synthesis.beta"))) from None
        _check_ga(self.ga)
        return self


def _named(e: InputError, horizon_key: str) -> InputError:
    """A :class:`pfjax.sim.SimConfig` error told by the study's key: the horizon (or the step count
    ``horizon / dt``) as ``horizon_key``, any other setting as ``sim.<setting>``."""
    if e.key in ("horizon", "dt"):
        return renamed(e, e.key, horizon_key)
    return renamed(e, e.key, f"sim.{e.key}") if e.key else e


def _check_ga(ga: PaperGA) -> None:
    """``ga.scenario`` names a tuning scenario and the GA's options are valid (named ``ga.<key>``)."""
    from pfjax.tuning.ga import GAOptions, validate_options
    from pfjax.tuning.problem import scenario_sets

    sets = scenario_sets()
    if ga.scenario not in sets and not (Path(ga.scenario).suffix == ".toml" and Path(ga.scenario).is_file()):
        raise ValueError(
            f"ga.scenario: value {ga.scenario!r}, expected one of {', '.join(sets)} or an existing study .toml"
        )
    try:
        validate_options(GAOptions(population_size=ga.population, generations=ga.generations))
    except InputError as e:
        raise ValueError(
            str(renamed(renamed(e, "population_size", "ga.population"), "generations", "ga.generations"))
        ) from None


def sim_config(cfg: dict, **changes):
    """The :class:`pfjax.sim.SimConfig` of the study's runs from its config ``cfg`` (a dumped
    :class:`PaperStudy`): its ``sim`` section, ``control_every = 0`` as continuous, ``changes`` applied."""
    from pfjax.sim.settings import SimConfig

    s = cfg["sim"]
    base = dict(
        dt=s["dt"],
        horizon=s["horizon"],
        control_every=None if s["control_every"] == 0 else s["control_every"],
        settle_band=s["settle_band"],
        steady_window=s["steady_window"],
    )
    base.update(changes)
    return SimConfig(**base)


#: Bytes one point of the eigenvalue scan (``stability.eig_n`` squared points) takes at its peak:
#: the slip grid, the equilibrium and both linearisations with their eigenvalues, XLA's temporaries
#: and the sorted real parts. Measured: 290-345 B per point at 2.3-9 x 10^6 points.
EIG_POINT_BYTES = 400
#: Recorded runs held at once by the source tests: the 24 readings of Table 3 on the three tests
#: (one batch per test), their 24 line traces and the 3 x 6 runs of the controllers.
RECORDED_RUNS = 3 * 24 + 24 + 3 * 6


def check_resources(config: PaperStudy) -> None:
    """:class:`pfjax.config.ConfigError` naming the key whose size would not fit in memory:
    ``stability.n`` (the simulated grid), ``stability.eig_n`` (the eigenvalue scan), ``sim.horizon``
    (the recorded runs of the source tests), ``long_horizon`` (the PI's recorded long run) and
    ``ga.population`` (a GA generation on a named scenario set)."""
    dt = config.sim.dt
    n = config.stability.n
    n_steps = check_steps(config.stability.horizon, dt)
    check_memory(
        "stability.n", 2 * n**2 * run_bytes(n_steps), f"a stability grid of {n**2:.3g} runs", "lower stability.n"
    )
    m = config.stability.eig_n
    check_memory(
        "stability.eig_n", m**2 * EIG_POINT_BYTES, f"an eigenvalue scan of {m**2:.3g} points", "lower stability.eig_n"
    )
    check_memory(
        "sim.horizon",
        2 * RECORDED_RUNS * run_bytes(check_steps(config.sim.horizon, dt), record=True),
        f"{RECORDED_RUNS} recorded runs of {config.sim.horizon:g} s",
        "lower sim.horizon or raise sim.dt",
    )
    check_memory(
        "long_horizon",
        2 * run_bytes(check_steps(config.long_horizon, dt), record=True),
        f"a recorded run of {config.long_horizon:g} s",
        "lower long_horizon",
    )
    _check_ga_memory(config.ga)


def _check_ga_memory(ga: PaperGA) -> None:
    """A GA generation simulates the whole population on every path of the scenario set at once
    (:func:`pfjax.tuning.problem.tune` refuses more than the budget); a study .toml's runs are
    sized by that study and checked when it is read."""
    from pfjax.sim.settings import SimConfig
    from pfjax.tuning.problem import scenario_sets

    sets = scenario_sets()
    if ga.scenario in sets:
        runs = ga.population * len(sets[ga.scenario])
        check_memory(
            "ga.population",
            2 * runs * run_bytes(SimConfig(record=False).n_steps),
            f"a GA population of {ga.population} x {len(sets[ga.scenario])} runs",
            "lower ga.population",
        )


def check_synthesis(config: PaperStudy) -> None:
    """:class:`pfjax.config.ConfigError` when one of the study's two LMI problems has no solution
    (both solved here, in a fraction of a second): the mixed design (named ``synthesis``, with the
    values of ``model.v``, ``model.L`` and the weights) or the certificate of the source's gain
    (``source.K``). Each fails where the solver cannot meet its strictness margins: speeds or
    wheelbases orders of magnitude from the source's, a gain near 0 or very large."""
    import numpy as np

    from pfjax.errors import SynthesisError
    from pfjax.synthesis import mixed_bounds_for_gain, mixed_h2_hinf, slip_design_plant

    m, a, b = config.model, config.synthesis.alpha, config.synthesis.beta
    plant = slip_design_plant(v=m.v, L=m.L)
    at = f"model.v = {m.v:g} m/s, model.L = {m.L:g} m"
    try:
        mixed_h2_hinf(plant, alpha=a, beta=b)
    except SynthesisError as e:
        raise ConfigError(
            f"synthesis: no mixed H2/Hinf design at {at}, synthesis.alpha = {a:g}, synthesis.beta = {b:g} ({e})",
            "synthesis",
        ) from None
    try:
        mixed_bounds_for_gain(plant, np.reshape(config.source.K, (1, 2)), a, b)
    except SynthesisError as e:
        raise ConfigError(
            f"source.K: no LMI certificate of the gain {_values(config.source.K)} at {at} ({e})"
        ) from None


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> PaperStudy:
    """The validated study config: defaults <- ``path`` <- (``--quick``) <- ``overrides``; raises
    :class:`pfjax.config.ConfigError` naming the key."""
    return check(load_model(PaperStudy, path, overrides, presets=[QUICK] if quick else [])[0])


def check(config: PaperStudy) -> PaperStudy:
    """``config`` if the study can run it: its sizes fit in memory (:func:`check_resources`) and its
    LMI problems have solutions (:func:`check_synthesis`); :class:`pfjax.config.ConfigError`
    naming the key otherwise. :func:`load` and :func:`pfjax.reproduce.paper_study.run` both check,
    so a config built in Python is refused as the command refuses its file."""
    try:
        check_resources(config)
    except ConfigError:
        raise
    except InputError as e:
        raise ConfigError(str(e)) from None
    check_synthesis(config)
    return config


__all__ = [
    "QUICK",
    "PaperGA",
    "PaperModel",
    "PaperSim",
    "PaperSource",
    "PaperStability",
    "PaperStudy",
    "PaperSynthesis",
    "check",
    "check_resources",
    "check_synthesis",
    "load",
    "sim_config",
]
