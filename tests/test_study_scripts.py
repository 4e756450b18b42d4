"""The study scripts' command lines (``studies/*.py``) from any directory: a ``--help`` that shows the
docstring's whole first paragraph and a help text for every option; the config beside the script,
so a bad flag is named from another directory too. Also ``pfjax study``'s ``--coordinator`` port
range and the path keys a path's kind does not read."""

from __future__ import annotations

import argparse
import ast
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pfjax.errors import InputError
from pfjax.montecarlo.config import load_study

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
SCRIPTS = {
    "paper_reproduction": True,  # has --config and --set
    "rare_events": False,
    "tuning_ga_vs_gradient": True,
    "vehicle_tracking": True,
    "kinematic_vs_dynamic": True,
    "parking": True,
}


def _env() -> dict:
    return {**os.environ, "PFJAX_CACHE_DIR": str(ROOT / ".pytest_cache" / "xla")}


def _every_script(cwd, *args, extra=None) -> dict[str, subprocess.CompletedProcess]:
    """Every script run with ``args`` (and its ``extra`` arguments) from ``cwd``, in parallel."""
    procs = {
        name: subprocess.Popen(
            [sys.executable, str(STUDIES / f"{name}.py"), *args, *(extra or {}).get(name, [])],
            cwd=cwd,
            env=_env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for name in SCRIPTS
    }
    out = {}
    for name, p in procs.items():
        stdout, stderr = p.communicate(timeout=300)
        out[name] = subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)
    return out


@pytest.fixture(scope="module")
def helps(tmp_path_factory) -> dict[str, subprocess.CompletedProcess]:
    """Every script's ``--help``, run from an empty directory that is not the checkout (in parallel)."""
    cwd = tmp_path_factory.mktemp("elsewhere")
    out = _every_script(cwd, "--help")
    assert not list(cwd.iterdir())  # --help writes nothing
    return out


def _words(text: str) -> list[str]:
    """The words of a text, without reST roles (``:mod:``) and punctuation."""
    return re.findall(r"[\w§'-]+", re.sub(r":\w+:", "", text))


def _options(help_text: str) -> dict[str, str]:
    """``--flag`` -> its help text, from argparse's ``options:`` section."""
    section = help_text.split("\noptions:\n", 1)[1]
    out: dict[str, str] = {}
    flag = None
    for line in section.splitlines():
        m = re.match(r"^  (-\S+(?:, -\S+)*)(?: [A-Z=_]+)?(?:\s{2,}(.*))?$", line)
        if m:
            flag = m.group(1).split(", ")[-1]
            out[flag] = m.group(2) or ""
        elif flag and line.startswith("    "):
            out[flag] = (out[flag] + " " + line.strip()).strip()
    return out


@pytest.mark.parametrize("name", list(SCRIPTS))
def test_help_from_another_directory_shows_the_whole_first_paragraph(helps, name):
    r = helps[name]
    assert r.returncode == 0, r.stderr[-2000:]
    doc = ast.get_docstring(ast.parse((STUDIES / f"{name}.py").read_text()))
    first = re.split(r"\n\s*\n", doc, maxsplit=1)[0]
    description = r.stdout.split("\n\n")[1]  # usage, blank line, description, blank line, options
    assert _words(description) == _words(first), description
    assert description.rstrip().endswith((".", "?")), description


@pytest.mark.parametrize("name", list(SCRIPTS))
def test_help_gives_every_option_a_help_text(helps, name):
    options = _options(helps[name].stdout)
    expected = {"--help", "--out", "--quick", "--overwrite"} | ({"--config", "--set"} if SCRIPTS[name] else set())
    assert set(options) == expected, options
    for flag, text in options.items():
        assert len(text.split()) >= 3, (flag, text)
    assert "results/" in options["--out"] and "current directory" in options["--out"], options["--out"]
    if SCRIPTS[name]:
        assert f"{name}.toml" in options["--config"], options["--config"]


def test_tuning_study_from_another_directory_names_a_bad_flag(tmp_path):
    r = subprocess.run(
        [
            sys.executable,
            str(STUDIES / "tuning_ga_vs_gradient.py"),
            "--quick",
            "--set",
            "ga.populaton=3",
            "--out",
            str(tmp_path / "out"),
        ],
        cwd=tmp_path,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr[-2000:]
    assert "ga.populaton" in lines[0] and "not found" not in lines[0], lines[0]
    assert not list(tmp_path.iterdir())


STUDY = """
name = "coordinator"
n_runs = 2
seed = 0
margin = { enabled = false }
sim = { horizon = 2.0, steady_window = 1.0 }
success = { from_s = 1.0 }
paths = [{ kind = "line" }]
controllers = [{ name = "st", type = "stanley" }]
"""


@pytest.mark.parametrize("coordinator", ["h:99999", "127.0.0.1:0", "h:65536"])
def test_coordinator_port_out_of_range_is_refused_before_jax_sees_it(tmp_path, monkeypatch, capsys, coordinator):
    from pfjax.cli import main
    from pfjax.sim import sharding

    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(STUDY)
    joined = []
    monkeypatch.setattr(sharding, "initialize_distributed", lambda *a, **k: joined.append(a))
    argv = ["study", "s.toml", "--coordinator", coordinator, "--num-processes", "1", "--process-id", "0"]
    code = main(argv + ["--out", "out", "--quiet"])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and out == "" and len(lines) == 1, err
    assert lines[0].startswith("pfjax study: error: --coordinator: ") and "65535" in lines[0], lines[0]
    assert joined == []  # refused by the flag's own check, not by the distributed runtime
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


BASE = {
    "name": "keys",
    "n_runs": 2,
    "seed": 0,
    "margin": {"enabled": False},
    "paths": [{"kind": "line"}],
    "controllers": [{"name": "st", "type": "stanley"}],
}


@pytest.mark.parametrize(
    "path, key",
    [
        ({"kind": "line", "radius": 0.1}, "radius"),
        ({"kind": "circle", "length": 10.0}, "length"),
        ({"kind": "sine", "n_waypoints": 10}, "n_waypoints"),
        ({"kind": "spline", "points": [[0, 0], [1, 0], [2, 0], [3, 0]], "radius": 3.0}, "radius"),
    ],
)
def test_a_path_key_of_another_kind_is_refused_naming_it(path, key):
    with pytest.raises(InputError) as e:
        load_study(data={**BASE, "paths": [path]})
    text = str(e.value)
    assert text.startswith(f"paths[0].{key}: not a key of a {path['kind']} path; its keys are kind, name"), text
    assert "\n" not in text


def test_a_set_of_another_kinds_key_is_refused_and_defaults_still_load():
    with pytest.raises(InputError, match=r"^paths\[0\]\.radius: not a key of a line path; its keys are kind, name"):
        load_study(data=BASE, overrides=["paths[0].radius=0.1"])
    # a validated config's dump holds every key at its default: it loads again, to the same config
    spec, _ = load_study(data={**BASE, "paths": [{"kind": "line"}, {"kind": "circle", "radius": 3.0}]})
    again, _ = load_study(data=spec.model_dump(mode="json"))
    assert again == spec


#: What a script needs to run from another directory (the held-out set by its packaged name).
ELSEWHERE = {"tuning_ga_vs_gradient": ["--set", "heldout=heldout"]}


def test_an_empty_out_is_refused_by_every_script_never_read_as_the_default(tmp_path):
    """``--out ''`` (an unset shell variable) is refused naming ``--out``, exit code 2, as ``pfjax
    study`` refuses it: the default ``results/<name>`` under the working directory is not written."""
    for name, r in _every_script(tmp_path, "--quick", "--out", "", extra=ELSEWHERE).items():
        err = r.stderr
        assert r.returncode == 2, (name, err)
        assert len(err.strip().splitlines()) == 1 and "--out: '' does not name a new directory" in err, (name, err)
    assert list(tmp_path.iterdir()) == []


def test_every_output_marker_command_names_a_pfjax_subcommand_or_a_study_script():
    """An output's refusal names what wrote it (``pfjax.outputs.SCRIPTS``): each ``command=`` an
    output is written under is a ``pfjax`` subcommand or a study script that exists."""
    from pfjax.cli import build_parser
    from pfjax.outputs import SCRIPTS as WRITERS
    from pfjax.outputs import _describe

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    found = set()
    for path in [*ROOT.joinpath("pfjax").rglob("*.py"), *STUDIES.glob("*.py")]:
        found |= set(re.findall(r'command="([\w+-]+)"', path.read_text()))
    assert found - set(sub.choices) == set(WRITERS), found
    assert all((ROOT / script).is_file() for script in WRITERS.values())
    assert _describe({"command": "parking-study", "config_sha256": "c" * 64}) == (
        "the output of `python studies/parking.py` (config cccccccccccc)"
    )
