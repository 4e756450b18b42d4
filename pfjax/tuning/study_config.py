"""The tuning study's configuration schema (``studies/tuning_ga_vs_gradient.toml``).

Sections: ``sim`` (the step and horizon of every simulation: the paper-* problems, the training
sets and the held-out study), ``ga`` (the source's MATLAB ga),
``gradient`` (plain projected adam), ``multistart`` (the multi-start tuner,
:class:`pfjax.tuning.multistart.MultistartOptions`), ``compare`` (problems and the ablation) and
``robust`` (robust tuning, the held-out set, the polytopic designs). Every key is optional; the
defaults are the study's published sizes. Loaded by :func:`load` with the same ``--set key=value``
syntax and one-line :class:`pfjax.config.ConfigError` as the Monte Carlo study.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from pfjax import errors
from pfjax.config import POSITIVE, ConfigModel, Real, load_model
from pfjax.resources import MAX_GENERATIONS, MAX_POPULATION
from pfjax.tuning.multistart import MultistartOptions

#: The multi-start tuner with one ingredient changed, at about the same budget (``compare.ablation``).
ABLATION: dict[str, dict[str, int | float | str]] = {
    "no_screening": {"n_screen": 0},
    "uniform_screening": {"sampler": "uniform"},
    "latin_hypercube": {"sampler": "lhs"},
    "no_separation": {"separation": 0.0},
    "no_halving": {"rounds": 1, "steps": 35},
    "no_restarts": {"n_restarts": 0},
    "no_polish": {"polish_steps": 0},
    "fewer_gradient_steps": {"steps": 30, "restart_steps": 10, "polish_steps": 16},
    "adam": {"local": "adam", "learning_rate": 0.05},
    "smoothing": {"smoothing": 0.05},
    "single_start": {"n_starts": 1, "rounds": 1, "steps": 280},
}

#: Scenario sets a problem of ``compare.problems`` may name after its controller.
SCENARIOS = ("paper-line", "paper-all", "heldout-cvar")

#: ``--quick``: two seeds of few-step tuners on one problem, a small held-out set (tests, a first look)
QUICK = {
    "seeds": 2,
    "cli_seeds": 0,
    "sim": {"horizon": 16.0},
    "ga": {"population": 6, "generations": 2},
    # plain adam, the Table 3 descent and the GA's polish take the same 30 steps of 0.01 from one
    # start: one compiled step program serves the three
    "gradient": {"steps": 30, "starts": 1, "lr": 0.01, "table3_steps": 30},
    "multistart": {
        "n_screen": 4,
        "n_starts": 2,
        "steps": 2,
        "rounds": 2,  # two: the ablation's smoothing variant smooths the first
        "n_restarts": 0,
        "restart_steps": 1,
        "polish_steps": 0,
    },
    "compare": {"problems": "pi:paper-line", "ablate": False},
    "robust": {"train_runs": 1, "heldout_runs": 3, "margin_runs": 2},
}


#: Simulated time of the integral design's steady-state check (:func:`pfjax.tuning.study_parts.integral_steady`), s.
INTEGRAL_STEADY_HORIZON = 30.0


class TuneSim(ConfigModel):
    """Step and horizon of the paper-* problems (the source's tests at 5 deg slip), of the training
    sets drawn from the held-out study's distribution and of the held-out study itself."""

    dt: Real = Field(0.01, ge=POSITIVE, description="RK4 integration step [s]")
    horizon: Real = Field(20.0, gt=15.0, description="simulated time, > 15 s (success window from 15 s) [s]")

    @model_validator(mode="after")
    def _check(self):
        from pfjax.sim.settings import SimConfig

        if self.dt > self.horizon:
            raise ValueError(f"dt: must be <= horizon ({self.horizon:g}), got {self.dt:g}")
        # the simulator's own checks (the step count, whole steps), for the problems' horizon and the
        # integral design's steady-state runs (INTEGRAL_STEADY_HORIZON)
        SimConfig(dt=self.dt, horizon=self.horizon)
        try:
            SimConfig(dt=self.dt, horizon=INTEGRAL_STEADY_HORIZON)
        except ValueError as e:
            raise ValueError(f"dt: the integral design's {INTEGRAL_STEADY_HORIZON:g} s runs: {e}") from None
        return self


class TuneGA(ConfigModel):
    """The source's MATLAB ga settings (Table 2)."""

    population: int = Field(50, ge=2, le=MAX_POPULATION, description="individuals per generation [-]")
    generations: int = Field(
        100, ge=0, le=MAX_GENERATIONS, description="generations after the first population [-] (0: that one only)"
    )


#: The Adam step of the descent from the source's Table 3 gains (normalised box units): a short,
#: careful descent that tells a local minimum from a point beside one; ``[gradient] lr`` is the
#: plain tuner's.
TABLE3_LR = 0.01


class TuneGradient(ConfigModel):
    """Plain projected adam (``--method gradient-plain``) and the descent from the Table 3 gains."""

    steps: int = Field(100, ge=1, description="adam steps per seed [-]")
    starts: int = Field(4, ge=1, description="starts descended together [-]")
    lr: Real = Field(0.05, gt=0, description="gradient-plain's adam step [normalised box units]")
    table3_steps: int = Field(
        60,
        ge=1,
        description=f"adam steps from the Table 3 gains (local-optimum check; step {TABLE3_LR:g} box units) [-]",
    )


class TuneMultistart(ConfigModel):
    """The multi-start tuner (``--method gradient``; :class:`pfjax.tuning.multistart.MultistartOptions`)."""

    n_screen: int = Field(64, description="space-filling points screened by value [-]")
    sampler: str = Field("sobol", description="screening points: sobol | lhs | uniform [-]")
    n_starts: int = Field(8, description="best screened points descended together [-]")
    separation: Real = Field(0.1, description="least RMS distance between two starts [normalised box units]")
    steps: int = Field(60, description="cost-and-gradient evaluations of a chain that survives every round [-]")
    rounds: int = Field(
        3, description="successive-halving rounds (1: no halving; not given: 3, or steps when below 3) [-]"
    )
    local: str = Field("bfgs", description="local descent: bfgs | adam [-]")
    learning_rate: Real = Field(0.1, description="bfgs first trust radius / adam step [normalised box units]")
    smoothing: Real = Field(
        0.0, description="randomised-smoothing radius of the first round, at most 1 [normalised box units]"
    )
    n_restarts: int = Field(3, description="perturbations of the incumbent descended at the end [-]")
    restart_steps: int = Field(20, description="evaluations of a restart chain [-]")
    restart_scale: Real = Field(0.05, description="standard deviation of the perturbations [normalised box units]")
    polish_steps: int = Field(8, description="value-only compass iterations around the incumbent [-]")
    polish_scale: Real = Field(0.05, description="first compass step [normalised box units]")

    @model_validator(mode="before")
    @classmethod
    def _rounds(cls, data):
        """``rounds`` not given follows ``steps`` as the tuner's does (:class:`MultistartOptions`):
        3, or ``steps`` when below 3."""
        if isinstance(data, dict) and "rounds" not in data and errors.is_number(data.get("steps")):
            return {**data, "rounds": min(3, data["steps"])} if data["steps"] < 3 else data
        return data

    @model_validator(mode="after")
    def _check(self):
        check_multistart(self.model_dump())
        return self


def check_multistart(options: dict) -> MultistartOptions:
    """``options`` as :class:`MultistartOptions`, checked; ``ValueError`` naming the bad field."""
    from pfjax import errors

    try:
        return MultistartOptions(**options).check()
    except (TypeError, errors.InputError) as e:
        raise ValueError(str(e)) from None


def problem_list(text: str) -> list[str]:
    """A comma-separated ``CONTROLLER:SCENARIO`` list as a list."""
    return [p.strip() for p in text.split(",") if p.strip()]


class TuneCompare(ConfigModel):
    """The problems every tuner runs on, the CVaR problem and the ablation of the multi-start tuner."""

    problems: str = Field(
        "pi:paper-line, pi:paper-all, pi:heldout-cvar, state_feedback:paper-line, integral:paper-line, "
        "stanley:paper-line, pure_pursuit:paper-line, rear_wheel:paper-line",
        description="comma-separated CONTROLLER:SCENARIO, scenario paper-line | paper-all | heldout-cvar; "
        "must list pi:paper-line [-]",
    )
    cvar_level: Real = Field(0.9, gt=0, lt=1, description="heldout-cvar: CVaR level of the IAE [-]")
    cvar_runs: int = Field(3, ge=1, description="heldout-cvar: training runs per path [-]")
    ablate: bool = Field(True, description="run the ablation on every problem of ablate_problems [-]")
    ablate_problems: str = Field(
        "pi:paper-line, integral:paper-line", description="comma-separated problems of the ablation [-]"
    )
    ablation: dict[str, dict[str, int | float | str]] = Field(
        default_factory=lambda: {k: v.copy() for k, v in ABLATION.items()},
        description="variant name -> multistart keys changed [-]",
    )

    @model_validator(mode="after")
    def _check(self):
        from pfjax import controllers as C

        problems = problem_list(self.problems)
        for key, items in (("problems", problems), ("ablate_problems", problem_list(self.ablate_problems))):
            repeated = sorted({p for p in items if items.count(p) > 1})
            if repeated:  # a problem listed twice would run, and count, its seeds twice
                raise ValueError(f"{key}: each problem once, repeated: {', '.join(repeated)}")
        for name, over in self.ablation.items():
            unknown = [k for k in over if k not in MultistartOptions._fields]
            if unknown:
                raise ValueError(
                    f"ablation.{name}.{unknown[0]}: unknown key; expected one of {', '.join(MultistartOptions._fields)}"
                )
        for p in problems:
            c, _, sc = p.partition(":")
            if c not in C.REGISTRY or C.REGISTRY[c].box is None or sc not in SCENARIOS:
                raise ValueError(
                    f"problems: {p!r}, expected CONTROLLER:SCENARIO with a tunable controller and a scenario "
                    + " | ".join(SCENARIOS)
                )
        if "pi:paper-line" not in problems:
            raise ValueError("problems: must list pi:paper-line (the held-out part evaluates its answers)")
        if self.ablate and not set(problem_list(self.ablate_problems)) <= set(problems):
            raise ValueError("ablate_problems: every problem must be listed in compare.problems")
        return self


class TuneRobust(ConfigModel):
    """Robust tuning of K on a training sample of the held-out study's distribution, the held-out
    evaluation and the polytopic designs."""

    train_runs: int = Field(
        6, ge=1, description="training runs per path (x the held-out study's paths per cost evaluation) [-]"
    )
    heldout_runs: int = Field(200, ge=1, description="held-out runs per path [-]")
    margin_runs: int = Field(40, ge=1, description="runs per slip amplitude in the margin sweep [-]")
    v_lo: Real = Field(0.8, gt=0, description="polytope: lowest speed [m/s]")
    v_hi: Real = Field(1.2, gt=0, description="polytope: highest speed [m/s]")
    beta_r_max_deg: Real = Field(10.0, ge=0, lt=90, description="polytope: largest |beta_r| [deg]")

    @model_validator(mode="after")
    def _check(self):
        if self.v_hi < self.v_lo:
            raise ValueError(f"v_hi: must be >= v_lo ({self.v_lo:g}), got {self.v_hi:g}")
        return self


class TuningStudy(ConfigModel):
    """The tuning study (``studies/tuning_ga_vs_gradient.py``)."""

    heldout: str = Field(
        "heldout",
        description="the held-out set and training set: a Monte Carlo study TOML, or the name of a packaged "
        "example (`pfjax examples`; the default, the packaged copy of studies/tuning_heldout.toml) [-]",
    )
    seeds: int = Field(20, ge=1, description="seeds 0..seeds-1 of every method on every problem [-]")
    cli_seeds: int = Field(
        5,
        ge=0,
        description="seeds of `pfjax tune --method gradient` and `--method ga` on the command line's problem "
        "(5 ms step, 20 s) with the [ga] and [multistart] settings (the command line's defaults at the "
        "published sizes) [-]",
    )
    sim: TuneSim = TuneSim()
    ga: TuneGA = TuneGA()
    gradient: TuneGradient = TuneGradient()
    multistart: TuneMultistart = TuneMultistart()
    compare: TuneCompare = TuneCompare()
    robust: TuneRobust = TuneRobust()

    @model_validator(mode="after")
    def _check(self):
        if self.cli_seeds > self.seeds:
            raise ValueError(f"cli_seeds: must be in [0, seeds], got {self.cli_seeds}")
        base = self.multistart.model_dump()
        for name, over in self.compare.ablation.items():
            try:
                check_multistart({**base, **over})
            except ValueError as e:
                raise ValueError(f"compare.ablation.{name}: {e}") from None
        if not heldout_file(self.heldout).is_file():
            from pfjax import examples

            raise ValueError(
                f"heldout: file not found: {self.heldout} (a study TOML relative to the working directory, "
                f"or a packaged example's name: {', '.join(examples.names())})"
            )
        cfg = self.model_dump(mode="json")
        spec = heldout_study(cfg)
        check_sizes(cfg, len(spec.paths))
        return self


#: First run index of the training sets drawn from the held-out study's distribution (the held-out
#: runs are 0, 1, ...).
TRAINING_OFFSET = 1 << 20

#: The tunings of state feedback's K by the multi-start tuner (:func:`pfjax.tuning.study_parts.tune_K`),
#: by label: the scenario, and the study's key of its training runs per path (None: a paper set).
K_TUNINGS = {
    "K-gradient-single": ("paper-line", None),
    "K-gradient-robust": ("training", "robust.train_runs"),
}

#: The study's keys that set a held-out study's key (:func:`heldout_study`): its errors name them.
HELDOUT_KEYS = {
    "n_runs": "robust.heldout_runs",
    "margin.n_per_amplitude": "robust.margin_runs",
    "sim.horizon": "sim.horizon",
    "sim.dt": "sim.dt",
}
#: The slip-margin sweep whose margins the held-out part compares (the held-out study must sweep it).
MARGIN_AXIS = "joint"


def heldout_file(value: str) -> Path:
    """The held-out study's TOML: a packaged example's name or a path (:func:`pfjax.examples.study_file`)."""
    from pfjax.examples import study_file

    return study_file(value)


def heldout_study(cfg: dict):
    """The held-out Monte Carlo study (``cfg["heldout"]``) at the study's sizes (``robust``), step and
    horizon (``sim``); ``ValueError`` naming the study's key (:data:`HELDOUT_KEYS`), or ``heldout:
    <path>: `` and the held-out study's own key, or ``heldout`` if it has no :data:`MARGIN_AXIS`
    sweep."""
    from pfjax.config import ConfigError
    from pfjax.montecarlo.config import load_study

    sets = {
        "n_runs": cfg["robust"]["heldout_runs"],
        "margin.n_per_amplitude": cfg["robust"]["margin_runs"],
        "sim.horizon": cfg["sim"]["horizon"],
        "sim.dt": cfg["sim"]["dt"],
    }
    path = cfg["heldout"]
    try:
        spec, _ = load_study(heldout_file(path), [f"{k}={v}" for k, v in sets.items()])
    except ConfigError as e:
        head, _, rest = str(e).partition(": ")
        if head in HELDOUT_KEYS:
            raise ValueError(f"{HELDOUT_KEYS[head]}: {rest} (in the held-out study {path})") from None
        raise ValueError(f"heldout: {path}: {e}") from None
    if not spec.margin.enabled or MARGIN_AXIS not in spec.margin.axes:
        swept = spec.margin.axes if spec.margin.enabled else "none (margin.enabled = false)"
        raise ValueError(
            f"heldout: {path}: the held-out part compares slip margins of a {MARGIN_AXIS} sweep; "
            f"margin.axes must include {MARGIN_AXIS!r}, got {swept}"
        )
    return spec


def methods(cfg: dict, name: str, first: bool) -> dict[str, dict]:
    """Label -> :func:`pfjax.tuning.problem.tune` keywords of every method run on problem ``name``
    (the GA's options aside: :func:`ga_options`)."""
    ms = MultistartOptions(**cfg["multistart"])
    out: dict[str, dict] = {
        "ga": dict(method="ga"),
        "gradient": dict(method="gradient", multistart=ms),
        "gradient-plain": dict(
            method="gradient-plain",
            steps=cfg["gradient"]["steps"],
            n_starts=cfg["gradient"]["starts"],
            learning_rate=cfg["gradient"]["lr"],
        ),
    }
    if first:
        out["ga+gradient"] = dict(method="ga+gradient")
    if cfg["compare"]["ablate"] and name in problem_list(cfg["compare"]["ablate_problems"]):
        for k, v in cfg["compare"]["ablation"].items():
            out[f"gradient:{k}"] = dict(method="gradient", multistart=ms._replace(**v))
    return out


def ga_options(cfg: dict):
    """The GA's options of every GA run of the study (``[ga]``)."""
    from pfjax.tuning.ga import GAOptions

    return GAOptions(population_size=cfg["ga"]["population"], generations=cfg["ga"]["generations"])


def check_sizes(cfg: dict, n_paths: int) -> None:
    """Every tuning run of the study checked as :func:`pfjax.tuning.problem.make_problem` and
    :func:`~pfjax.tuning.problem.tune` check it (the training sets' runs per path, the memory
    budget of each method), before any work; ``ValueError`` naming the study's key: a training
    set's ``compare.cvar_runs`` or ``robust.train_runs``, else the setting (``ga.population``,
    ``multistart.<field>``, ``gradient.starts``). ``n_paths``: the held-out study's paths."""
    from pfjax import controllers as C
    from pfjax import errors
    from pfjax.sim import SimConfig
    from pfjax.tuning.problem import check_memory, check_runs, check_tune, scenario_sets

    n_steps = SimConfig(dt=cfg["sim"]["dt"], horizon=cfg["sim"]["horizon"]).n_steps
    problems = problem_list(cfg["compare"]["problems"])
    # (problem, key of its runs or None, rollouts per evaluation, labelled tune keywords)
    runs: list[tuple[str, str | None, int, dict[str, dict]]] = []
    for runs_key in ("compare.cvar_runs", "robust.train_runs"):  # the training sets' runs per path
        section, _, field = runs_key.partition(".")
        try:
            check_runs(cfg[section][field], TRAINING_OFFSET)
        except errors.InputError as e:
            raise ValueError(f"{runs_key}: {_body(e)}") from None
    for i, name in enumerate(problems):
        if name.endswith(":heldout-cvar"):
            n = cfg["compare"]["cvar_runs"] * n_paths
            runs.append((name, "compare.cvar_runs", n, methods(cfg, name, i == 0)))
        else:
            runs.append((name, None, len(scenario_sets()[name.partition(":")[2]]), methods(cfg, name, i == 0)))
    gradient = {"gradient": dict(method="gradient", multistart=MultistartOptions(**cfg["multistart"]))}
    for scenario, train_key in K_TUNINGS.values():
        section, _, field = (train_key or "").partition(".")
        n = len(scenario_sets()[scenario]) if train_key is None else cfg[section][field] * n_paths
        runs.append((f"state_feedback:{scenario}", train_key, n, gradient))
    for name, key, n, labelled in runs:
        box = C.REGISTRY[name.partition(":")[0]].box
        assert box is not None  # compare.problems lists tunable controllers (TuneCompare)
        D = int(np.size(box[1]))
        for label, kw in labelled.items():
            kw = dict(kw)
            try:
                check_tune(kw.pop("method"), n, D, n_steps, ga_options=ga_options(cfg), **kw)
                if name == problems[0]:  # the local check of the first problem's best answers
                    check_memory("check", n, D, n_steps)
            except errors.InputError as e:
                setting = _setting(label, e.key)
                raise ValueError(f"{key or setting}: {_body(e)} ({label} on {name})") from None


def _body(e) -> str:
    """An :class:`~pfjax.errors.InputError`'s message without its leading key."""
    text = str(e)
    return text[len(e.key) + 2 :] if e.key and text.startswith(f"{e.key}: ") else text


def _setting(label: str, key: str | None) -> str:
    """The study's key of a tuner's setting ``key`` (an error of the method ``label``)."""
    if key == "population_size":
        return "ga.population"
    if label == "gradient-plain":
        return {"n_starts": "gradient.starts", "steps": "gradient.steps"}.get(key or "", "gradient")
    if label.startswith("gradient:"):
        return f"compare.ablation.{label.partition(':')[2]}"
    return f"multistart.{key}" if key in MultistartOptions._fields else "compare.problems"


def load(path: str | Path | None = None, overrides: Sequence[str] = (), quick: bool = False) -> TuningStudy:
    """The validated study config: defaults <- ``path`` <- (``--quick``) <- ``overrides``; raises
    :class:`pfjax.config.ConfigError` naming the key."""
    return load_model(TuningStudy, path, overrides, presets=[QUICK] if quick else [])[0]


__all__ = [
    "ABLATION",
    "HELDOUT_KEYS",
    "K_TUNINGS",
    "MARGIN_AXIS",
    "QUICK",
    "SCENARIOS",
    "TRAINING_OFFSET",
    "TuneCompare",
    "TuneGA",
    "TuneGradient",
    "TuneMultistart",
    "TuneRobust",
    "TuneSim",
    "TuningStudy",
    "check_multistart",
    "check_sizes",
    "ga_options",
    "heldout_file",
    "heldout_study",
    "load",
    "methods",
    "problem_list",
]
