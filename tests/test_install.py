"""The installation: ``constraints.txt`` pins every dependency ``pyproject.toml`` declares, to a
version inside the declared range; ``make`` installs with it; and the project's ``.venv`` (the one
``make test`` runs in) holds exactly the pinned versions, so the tests and the README's numbers come
from the environment the file names."""

import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]


def pins() -> dict[str, str]:
    """``{canonical name: version}`` from constraints.txt (comment lines skipped)."""
    out = {}
    for n, line in enumerate((ROOT / "constraints.txt").read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        m = re.fullmatch(r"([A-Za-z0-9][A-Za-z0-9._-]*)==([^\s;]+)", line)
        assert m, f"constraints.txt:{n}: {line!r} is not name==version"
        name = canonicalize_name(m[1])
        assert name not in out, f"constraints.txt:{n}: {m[1]} pinned twice"
        out[name] = m[2]
    return out


#: The extras ``make install`` installs (and constraints.txt pins): the tests, the benchmark's Numba
#: reference and the documentation.
EXTRAS = ("test", "bench", "docs")


def declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    return [Requirement(r) for r in project["dependencies"] + [r for e in EXTRAS for r in extras[e]]]


def test_every_declared_dependency_is_pinned_inside_its_range():
    p = pins()
    assert "pfjax" not in p  # pfjax itself is installed from the working tree
    for req in declared():
        name = canonicalize_name(req.name)
        assert name in p, f"{req.name}: declared in pyproject.toml, not pinned in constraints.txt"
        assert req.specifier.contains(Version(p[name]), prereleases=True), (
            f"{req.name}: pinned {p[name]}, outside the declared {req.specifier}"
        )


def test_jax_and_jaxlib_are_pinned_together():
    p = pins()
    assert p["jax"] == p["jaxlib"]  # jax accepts only the jaxlib of its own release


def test_make_installs_with_the_constraints():
    make = (ROOT / "Makefile").read_text()
    stamp = re.search(r"^\$\(STAMP\):(.*)$", make, re.M)
    assert stamp and "constraints.txt" in stamp[1].split()  # editing the pins reinstalls
    extras = f'".[{",".join(EXTRAS)}]"'
    install = [ln for ln in make.splitlines() if "pip install" in ln and extras in ln and "-e" in ln]
    assert install and all("-c constraints.txt" in ln for ln in install), install
    lock = [ln for ln in make.splitlines() if "LOCK_VENV" in ln and "pip install" in ln and "upgrade" not in ln]
    assert lock and all(extras in ln for ln in lock), lock  # make lock pins what make install installs


def test_numba_is_the_bench_extra_not_a_core_dependency():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = {canonicalize_name(Requirement(r).name) for r in project["dependencies"]}
    assert "numba" not in core and "scipy" in core  # SciPy: the synthesis, the paths and the statistics use it
    assert [Requirement(r).name for r in project["optional-dependencies"]["bench"]] == ["numba"]


@pytest.mark.skipif(
    Path(sys.prefix).resolve() != (ROOT / ".venv").resolve(),
    reason="runs in the project's .venv only (make test); other environments may differ",
)
def test_the_project_venv_holds_the_pinned_versions():
    p = pins()
    wrong = {}
    for req in declared():
        name = canonicalize_name(req.name)
        have = metadata.version(req.name)
        if Version(have) != Version(p[name]):
            wrong[req.name] = (have, p[name])
    assert not wrong, f"installed vs pinned: {wrong}; run make install (or touch constraints.txt)"
