"""Lint and types as habits: ``make lint`` (ruff lint, ruff format, mypy) is clean.

The rules live in pyproject.toml ([tool.ruff], [tool.mypy]); a failure prints the findings.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TARGETS = ["pfjax", "studies", "tests", "docs/hooks.py"]


def _tool(name: str) -> str:
    exe = Path(sys.executable).parent / name
    if exe.exists():
        return str(exe)
    found = shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed (pip install -e '.[test]')")
    return found


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_lint_is_clean():
    r = _run(_tool("ruff"), "check", "--no-cache", *TARGETS)
    assert r.returncode == 0, r.stdout + r.stderr


def test_ruff_format_is_clean():
    r = _run(_tool("ruff"), "format", "--check", "--no-cache", *TARGETS)
    assert r.returncode == 0, r.stdout + r.stderr


def test_mypy_is_clean():
    r = _run(_tool("mypy"), "--no-incremental")
    assert r.returncode == 0, r.stdout + r.stderr
