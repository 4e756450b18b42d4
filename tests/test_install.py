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


def declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["test"]]


def test_every_declared_dependency_is_pinned_inside_its_range():
    p = pins()
    assert "pfjax" not in p  # pfjax itself is installed from the working tree
    for req in declared():
        name = canonicalize_name(req.name)
        assert name in p, f"{req.name}: declared in pyproject.toml, not pinned in constraints.txt"
        assert req.specifier.contains(Version(p[name]), prereleases=True), \
            f"{req.name}: pinned {p[name]}, outside the declared {req.specifier}"


def test_jax_and_jaxlib_are_pinned_together():
    p = pins()
    assert p["jax"] == p["jaxlib"]  # jax accepts only the jaxlib of its own release


def test_make_installs_with_the_constraints():
    make = (ROOT / "Makefile").read_text()
    stamp = re.search(r"^\$\(STAMP\):(.*)$", make, re.M)
    assert stamp and "constraints.txt" in stamp[1].split()  # editing the pins reinstalls
    install = [ln for ln in make.splitlines() if "pip install" in ln and '".[test]"' in ln and "-e" in ln]
    assert install and all("-c constraints.txt" in ln for ln in install), install


@pytest.mark.skipif(Path(sys.prefix).resolve() != (ROOT / ".venv").resolve(),
                    reason="runs in the project's .venv only (make test); other environments may differ")
def test_the_project_venv_holds_the_pinned_versions():
    p = pins()
    wrong = {}
    for req in declared():
        name = canonicalize_name(req.name)
        have = metadata.version(req.name)
        if Version(have) != Version(p[name]):
            wrong[req.name] = (have, p[name])
    assert not wrong, f"installed vs pinned: {wrong}; run make install (or touch constraints.txt)"
