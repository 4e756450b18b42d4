"""pfjax as a package a researcher installs and cites: the example studies it carries are the
repository's ``studies/`` files byte for byte (and every ``pfjax study`` config there is carried);
the licence, citation and changelog agree with ``pyproject.toml``; and the wheel, installed into a
fresh environment, holds its type marker and examples and runs an example study
from outside the repository (``@slow``)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import pytest

from pfjax import examples

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "pfjax"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


# ------------------------------------------------------------------------------ packaged examples


@pytest.mark.parametrize("name", examples.names())
def test_each_packaged_example_is_its_studies_file_byte_for_byte(name):
    packaged = examples.path(name)
    assert packaged.parent == PACKAGE / "examples" and packaged.is_file()
    source = ROOT / "studies" / examples.FILES[name]
    assert packaged.read_bytes() == source.read_bytes(), (
        f"pfjax/examples/{packaged.name} differs from studies/{source.name}: copy it again"
    )


def test_the_examples_folder_holds_exactly_the_listed_examples():
    assert sorted(p.name for p in (PACKAGE / "examples").glob("*.toml")) == sorted(examples.FILES.values())
    assert examples.names()[:2] == ["default", "heldout"]
    assert examples.FILES["default"] == "robustness_default.toml" and examples.FILES["heldout"] == "tuning_heldout.toml"


def test_every_study_config_in_studies_is_packaged():
    from pfjax.errors import InputError
    from pfjax.montecarlo.config import load_study

    studies = []
    for f in sorted((ROOT / "studies").glob("*.toml")):
        try:
            load_study(f)
        except InputError:  # a script's config (paper reproduction, parking, tracking, tuning study)
            continue
        studies.append(f.name)
    assert studies and sorted(studies) == sorted(examples.FILES.values())


@pytest.mark.parametrize("name", examples.names())
def test_each_example_loads_as_a_study_and_has_a_one_line_description(name):
    from pfjax.montecarlo.config import load_study

    spec, _ = load_study(examples.path(name))
    assert spec.n_runs >= 1 and spec.controllers and spec.paths
    text = examples.description(name)
    assert text and "\n" not in text and not text.startswith("#")
    lines = examples.path(name).read_text().splitlines()
    opening = []  # the comment the file opens with, its lines joined
    for ln in lines[next(i for i, ln in enumerate(lines) if ln.strip()) :]:
        if not ln.startswith("#"):
            break
        opening.append(ln.lstrip("#").strip())
    assert text.rstrip(".") in " ".join(opening) and text.endswith(".")  # its first sentence, whole


def test_an_unknown_example_names_the_key_and_the_choices():
    from pfjax.errors import InputError

    with pytest.raises(InputError) as e:
        examples.path("nope")
    assert str(e.value).startswith("example: unknown example 'nope'")
    assert all(n in str(e.value) for n in examples.names())


# ---------------------------------------------------------------------------------- metadata


def test_license_is_mit_as_declared():
    text = (ROOT / "LICENSE").read_text()
    assert PYPROJECT["project"]["license"] == "MIT"
    assert text.startswith("MIT License\n") and "Copyright (c) 2026 The pfjax authors" in text
    assert 'THE SOFTWARE IS PROVIDED "AS IS"' in text


def test_citation_cff_describes_this_version_and_its_three_sources():
    yaml = pytest.importorskip("yaml")  # PyYAML comes with the docs extra
    import pfjax

    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software" and cff["license"] == "MIT"
    assert str(cff["version"]) == PYPROJECT["project"]["version"] == pfjax.__version__
    assert cff["authors"] == [{"name": "The pfjax authors"}] and "pfjax" in cff["title"]
    refs = cff["references"]
    assert len(refs) == 3 and all(r["title"] and r["authors"] and r["type"] for r in refs)
    assert any("Sliding Effect via LMI" in r["title"] for r in refs)
    assert any("switching traveling direction" in r["title"] for r in refs)
    assert any("Autonomous Mobile Robots" in r["title"] for r in refs)
    for r in refs:
        if "doi" in r:
            assert re.fullmatch(r"10\.\d{4,9}/\S+", str(r["doi"])), r["doi"]


def test_changelog_has_an_unreleased_and_a_section_for_this_version():
    text = (ROOT / "CHANGELOG.md").read_text()
    heads = re.findall(r"^## \[([^\]]+)\]", text, re.M)
    assert heads[:2] == ["Unreleased", PYPROJECT["project"]["version"]]
    for word in ("st" + "op", "sess" + "ion", "iss" + "ue"):  # (spelled apart: the repository is grepped for them)
        assert not re.search(rf"\b{word}s?\b", text, re.I), word


def test_package_data_names_the_marker_and_examples():
    data = PYPROJECT["tool"]["setuptools"]["package-data"]
    assert "py.typed" in data["pfjax"] and (PACKAGE / "py.typed").read_bytes() == b""
    assert data["pfjax.examples"] == ["*.toml"]
    assert not list(PACKAGE.rglob("*.j2"))  # reports are built in code (pfjax.report.document), no template files


# ------------------------------------------------------------------------------------- the wheel


def _env() -> dict:
    """The environment of the fresh installation: nothing pointing at this checkout or its venv."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONSTARTUP")}
    env["PFJAX_CACHE_DIR"] = str(ROOT / ".pytest_cache" / "xla")  # the suite's compilation cache
    return env


def _run(args, *, cwd, timeout=300):
    r = subprocess.run([str(a) for a in args], cwd=cwd, capture_output=True, text=True, env=_env(), timeout=timeout)
    assert r.returncode == 0, f"{args}: exit {r.returncode}\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}"
    return r


@pytest.mark.slow
def test_the_wheel_installs_into_a_fresh_venv_and_runs_an_example_outside_the_repository(tmp_path):
    # build from a copy of the sources (the checkout gets no build/ or egg-info), offline: the
    # build backend is the installed setuptools (the test extra), not a download
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    shutil.copytree(PACKAGE, src / "pfjax", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    dist = tmp_path / "dist"
    _run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", dist, src], cwd=tmp_path)
    (wheel,) = dist.glob("pfjax-*.whl")

    names = set(zipfile.ZipFile(wheel).namelist())
    assert "pfjax/py.typed" in names
    assert all(f"pfjax/examples/{f}" in names for f in examples.FILES.values())
    assert "pfjax/examples/__init__.py" in names and "pfjax/cli/examples.py" in names
    assert not any(n.startswith(("tests/", "studies/")) for n in names)
    info = next(n for n in names if n.endswith(".dist-info/METADATA"))
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    metadata = zipfile.ZipFile(wheel).read(info).decode()
    assert "License-Expression: MIT" in metadata
    numba = [ln for ln in metadata.splitlines() if ln.startswith("Requires-Dist: numba")]
    assert numba and all('extra == "bench"' in ln for ln in numba)  # not a core dependency

    # a fresh venv; the wheel installed without its dependencies (nothing downloaded) ...
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp_path)
    py = venv / "bin" / "python"
    _run(
        [sys.executable, "-m", "pip", "--python", py, "install", "--quiet", "--no-deps", "--no-index", wheel],
        cwd=tmp_path,
    )
    # ... which then come from this environment's site-packages (a plain path line: its .pth files,
    # the editable pfjax's among them, are not run, and the venv's own site-packages comes first)
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], cwd=tmp_path).stdout.strip())
    deps = dict.fromkeys(sysconfig.get_paths()[k] for k in ("purelib", "platlib"))
    (site / "_pfjax_test_dependencies.pth").write_text("".join(f"{d}\n" for d in deps))

    work = tmp_path / "work"  # outside the repository
    work.mkdir()
    where = _run(
        [py, "-c", "import pfjax, pfjax.examples as e; print(pfjax.__file__); print(e.path('default'))"], cwd=work
    ).stdout.split()
    for p in where:
        assert Path(p).resolve().is_relative_to(site.resolve()), (p, site)
        assert not Path(p).resolve().is_relative_to(ROOT), p

    listed = _run([venv / "bin" / "pfjax", "examples"], cwd=work).stdout
    for n in examples.names():
        assert re.search(rf"^{n}\s+\S", listed, re.M), (n, listed)

    out = tmp_path / "out"
    _run(
        [
            venv / "bin" / "pfjax",
            "study",
            "--example",
            "default",
            "--set",
            "n_runs=100",
            "--set",
            "margin.enabled=false",
            "--set",
            "falsifier.enabled=false",
            "--set",
            "f64_check_runs=0",
            "--set",
            "chunk_size=100",
            "--out",
            out,
            "--quiet",
        ],
        cwd=work,
    )
    assert (out / "runs.parquet").is_file() and (out / "report.html").is_file() and (out / "report.md").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["study"] == "robustness_default" and summary["n_runs_total"] == 100 * 3 * 3
