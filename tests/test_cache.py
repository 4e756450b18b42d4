"""The persistent compilation cache: which compilations it stores, and a warm command compiles nothing."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import jax
import pytest

from pfjax import cache

MIN = "jax_persistent_cache_min_compile_time_secs"


def _with_cache_dir(directory, fn):
    old_dir, old_min = jax.config.jax_compilation_cache_dir, getattr(jax.config, MIN)
    try:
        jax.config.update("jax_compilation_cache_dir", directory)
        jax.config.update(MIN, 0.5)
        return fn()
    finally:
        jax.config.update("jax_compilation_cache_dir", old_dir)
        jax.config.update(MIN, old_min)


def test_enable_sets_the_minimum_of_pfjax_own_cache_only(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.ENV, str(tmp_path))
    got = _with_cache_dir(str(tmp_path), lambda: (cache.enable(min_compile_s=0.0), getattr(jax.config, MIN)))
    assert got == (tmp_path, 0.0)
    # without a minimum, the one in use stays
    assert _with_cache_dir(str(tmp_path), lambda: (cache.enable(), getattr(jax.config, MIN))) == (tmp_path, 0.5)
    # a cache the user configured through JAX elsewhere keeps its own minimum
    other = str(tmp_path / "users")
    got = _with_cache_dir(other, lambda: (cache.enable(min_compile_s=0.0), getattr(jax.config, MIN)))
    assert got == (Path(other), 0.5)


#: ``python -m pfjax.cli`` (the interpreter's usual end), and the console script's entry point
#: (:func:`pfjax.cli.run`, which ends the process without the teardown)
LAUNCHERS = {"module": ["-m", "pfjax.cli"], "console-script": ["-c", "from pfjax.cli import run; run()"]}


def _compiles(env, args, launcher="module"):
    out = subprocess.run(
        [sys.executable, *LAUNCHERS[launcher], *args], env=env, capture_output=True, text=True, timeout=300, check=True
    )
    log = out.stderr
    return len(re.findall(r"Finished XLA compilation", log)), len(re.findall(r"Persistent compilation cache hit", log))


@pytest.mark.parametrize("launcher", LAUNCHERS)
def test_warm_simulate_command_loads_every_program_from_the_cache(tmp_path, launcher):
    # a fresh cache of pfjax's own (import pfjax set JAX's variables for this process: not inherited)
    env = {k: v for k, v in os.environ.items() if not k.startswith(("JAX_COMPILATION_CACHE", "JAX_PERSISTENT_CACHE"))}
    env.update({cache.ENV: str(tmp_path / "xla"), "JAX_LOG_COMPILES": "1"})
    args = ["simulate", "--path", "sine", "--controller", "pi", "--horizon", "0.2", "--json"]
    compiled, hits = _compiles(env, args, launcher)
    assert compiled - hits >= 2  # compiled: the simulator and the scenario's small host-side programs
    # each was stored before the process ended
    compiled_warm, hits_warm = _compiles(env, args, launcher)
    assert compiled_warm == hits_warm == compiled  # each one loaded, none compiled again
