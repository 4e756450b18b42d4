"""The vehicle models' names, the dynamic ones, their default parameter sets and the parameter
sets' names have one home, :mod:`pfjax.models`: the study config's schema, the command line's
choices, tuning, the benchmark and the scenario builders read it, and no module that takes a model
spells the names out again."""

import argparse
import re
from pathlib import Path

import pytest

import pfjax
from pfjax import models

ROOT = Path(pfjax.__file__).parent

#: The modules that take a vehicle model or a parameter set by name.
READERS = (
    "montecarlo/scenario_config.py",
    "montecarlo/sampling.py",
    "montecarlo/config.py",
    "tuning/problem.py",
    "api/runs.py",
    "api/simulation.py",
    "sim/scenario.py",
    "report/study_setup.py",
    "bench/run.py",
    "cli/simulate.py",
)


def test_the_home_holds_the_names():
    from pfjax.models.single_track import COMMONROAD_VEHICLES

    assert models.MODELS == ("kinematic", "st", "std")
    assert models.DYNAMIC_MODELS == ("st", "std")
    assert set(models.DEFAULT_PARAMETER_SET) == set(models.DYNAMIC_MODELS)
    assert set(models.DEFAULT_PARAMETER_SET.values()) <= set(models.PARAMETER_SETS)
    assert ("robot", *COMMONROAD_VEHICLES) == models.PARAMETER_SETS


def test_the_study_config_schema_reads_the_home():
    from pfjax.montecarlo import scenario_config
    from pfjax.montecarlo.scenario_config import VehicleSpec

    props = VehicleSpec.model_json_schema()["properties"]
    assert props["model"]["enum"] == list(models.MODELS)
    assert props["params"]["enum"] == list(models.PARAMETER_SETS)
    assert scenario_config.DEFAULT_PARAMETER_SET is models.DEFAULT_PARAMETER_SET
    for model, name in models.DEFAULT_PARAMETER_SET.items():
        assert VehicleSpec(model=model).params == name


def test_the_command_line_choices_read_the_home():
    from pfjax.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    actions = {a.dest: a for a in sub.choices["simulate"]._actions}
    assert actions["model"].choices is models.MODELS
    assert actions["vehicle"].choices is models.PARAMETER_SETS


def test_tuning_and_the_benchmark_read_the_home():
    from pfjax.bench.run import BenchConfig
    from pfjax.tuning import problem

    assert problem.MODELS is models.MODELS
    assert not hasattr(problem, "DYNAMIC_PARAMS")  # the default sets are DEFAULT_PARAMETER_SET's
    assert BenchConfig().models is models.MODELS


@pytest.mark.parametrize("module", READERS)
def test_no_reader_spells_the_names_out(module):
    text = (ROOT / module).read_text(encoding="utf-8")
    code = "\n".join(line.split("#", 1)[0] for line in text.splitlines())  # code, not comments
    for pattern in (
        r"""\(\s*["']kinematic["'],\s*["']st["'],\s*["']std["']\s*\)""",
        r"""\(\s*["']st["'],\s*["']std["']\s*\)""",
        r"""Literal\[\s*["']kinematic["'],\s*["']st["']""",
        r"""Literal\[\s*["']robot["']""",
        r"""\{\s*["']st["']:\s*["']robot["']""",
    ):
        assert not re.search(pattern, code), (module, pattern)
