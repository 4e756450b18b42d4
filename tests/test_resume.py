"""Interrupted studies resume: finished chunks are reused (counted), the result equals an
uninterrupted run, a changed config is refused, ``--fresh`` starts over; and a real SIGKILL of a
``pfjax study`` subprocess mid-run, then the same command again."""

import json
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pyarrow.parquet as pq
import pytest

from pfjax.config import ConfigError
from pfjax.montecarlo import chunk_runs as runner  # the chunk loop reads simulate_chunk from its home
from pfjax.montecarlo.chunks import chunk_key, partial_dir
from pfjax.montecarlo.config import load_study
from pfjax.montecarlo.study import run

STUDY = """name = "resume"
n_runs = 40
seed = 7
chunk_size = 8
f64_check_runs = 0
[sim]
horizon = 2.0
steady_window = 1.0
[success]
from_s = 1.0
band = 0.2
[slip]
beta_r_deg = { dist = "uniform", low = -5, high = 5 }
[initial]
lateral_offset = { dist = "uniform", low = -0.3, high = 0.3 }
[margin]
amplitudes_deg = [0.0, 10.0]
n_per_amplitude = 8
axes = ["joint"]
[[paths]]
kind = "line"
[[controllers]]
name = "st"
type = "stanley"
[[controllers]]
name = "pp"
type = "pure_pursuit"
"""
# runs: 5 chunks x 2 controllers; margin: 16 runs in 2 chunks x 2 controllers  ->  14 chunks
N_CHUNKS = 14


class Interrupt(BaseException):
    """Stands for a kill (not an Exception, like KeyboardInterrupt)."""


@pytest.fixture(scope="module")
def spec(tmp_path_factory):
    p = tmp_path_factory.mktemp("cfg") / "s.toml"
    p.write_text(STUDY)
    return load_study(p)[0], p


@pytest.fixture(scope="module")
def reference(spec, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "out"
    summary = run(spec[0], out, progress=False, report=False)
    return out, summary


def _frames(out):
    return pd.read_parquet(out / "runs.parquet"), pd.read_parquet(out / "margin.parquet")


def test_uninterrupted_run_leaves_no_partial_directory(reference):
    out, summary = reference
    assert summary["chunks"] == {"simulated": N_CHUNKS, "resumed": 0}
    assert not partial_dir(out).exists()
    assert sorted(p.name for p in out.parent.iterdir()) == ["out"]


def test_interrupted_study_resumes_without_recomputing(spec, reference, tmp_path, monkeypatch):
    out = tmp_path / "out"
    real, calls = runner.simulate_chunk, []

    def dies_after_6(*a, **k):
        if len(calls) == 6:
            raise Interrupt
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(runner, "simulate_chunk", dies_after_6)
    with pytest.raises(Interrupt):
        run(spec[0], out, progress=False, report=False)
    monkeypatch.undo()
    assert not out.exists()  # nothing half-written at the output
    chunks = sorted(p.name for p in partial_dir(out).glob("*.parquet"))
    assert len(chunks) == 6 and json.loads((partial_dir(out) / "manifest.json").read_text())["seed"] == 7

    # a changed config is refused, naming the flag that starts over
    other = spec[0].model_copy(update={"seed": 8})
    with pytest.raises(ConfigError, match=r"^--out: .* interrupted study with a different config .* add --fresh"):
        run(other, out, progress=False, report=False)
    import pfjax  # the Python API names its own arguments: out, and fresh=True

    with pytest.raises(
        ConfigError, match=r"^out: .* interrupted study with a different config .* pass fresh=True"
    ) as e:
        pfjax.run_study(other, out, progress=False, report=False)
    assert e.value.key == "out"

    summary = run(spec[0], out, progress=False, report=False)
    assert summary["chunks"] == {"simulated": N_CHUNKS - 6, "resumed": 6}
    assert not partial_dir(out).exists()
    for a, b in zip(_frames(out), _frames(reference[0])):
        pd.testing.assert_frame_equal(a, b)
    assert pq.read_schema(out / "runs.parquet").metadata == pq.read_schema(reference[0] / "runs.parquet").metadata


def test_fresh_discards_an_interrupted_run(spec, tmp_path, monkeypatch):
    out = tmp_path / "out"
    monkeypatch.setattr(runner, "simulate_chunk", lambda *a, **k: (_ for _ in ()).throw(Interrupt))
    with pytest.raises(Interrupt):
        run(spec[0], out, progress=False, report=False)
    monkeypatch.undo()
    other = spec[0].model_copy(update={"seed": 8, "margin": spec[0].margin.model_copy(update={"enabled": False})})
    summary = run(other, out, progress=False, report=False, fresh=True)
    assert summary["chunks"] == {"simulated": 10, "resumed": 0} and summary["seed"] == 8


@pytest.mark.slow
def test_sigkill_mid_run_then_same_command_resumes(spec, reference, tmp_path):
    """A real kill: the subprocess is SIGKILLed once it has finished a chunk; re-running the same
    command reuses every finished chunk and writes the uninterrupted result."""
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "pfjax.cli",
        "study",
        str(spec[1]),
        "--out",
        str(out),
        "--quiet",
        "--no-report",
        "--json",
    ]
    # the second process reuses the first one's compilations (persistent cache; the first compiles before any chunk)
    env = {
        **os.environ,
        "JAX_COMPILATION_CACHE_DIR": str(tmp_path / "jax_cache"),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
        "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0",
    }
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True, env=env)
    t0 = time.time()
    while time.time() - t0 < 120 and proc.poll() is None:
        if len(list(partial_dir(out).glob("*.parquet"))) >= 2:
            break
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()
    done = len(list(partial_dir(out).glob("*.parquet")))
    assert 2 <= done < N_CHUNKS and not out.exists()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    assert r.returncode == 0, r.stderr
    head = json.loads(r.stdout)
    assert head["chunks"]["resumed"] == done and head["chunks"]["simulated"] == N_CHUNKS - done
    for a, b in zip(_frames(out), _frames(reference[0])):
        pd.testing.assert_frame_equal(a, b)
    assert not partial_dir(out).exists() and sorted(p.name for p in tmp_path.iterdir()) == ["jax_cache", "out"]


def test_a_chunk_of_another_table_layout_is_simulated_again(tmp_path):
    """A finished chunk without this run-table layout's stamp (written before the sampled inputs
    were kept in the study's precision) is not resumed: its config, seed and version match, but it
    would be merged with chunks of other column types."""
    from pfjax.montecarlo.chunks import TABLE_FORMAT, ChunkStore

    data = {"name": "t", "n_runs": 4, "seed": 0, "paths": [{"kind": "line"}]}
    spec, _ = load_study(data=data | {"controllers": [{"name": "sf", "type": "state_feedback"}]})
    out = tmp_path / "out"
    store = ChunkStore(out, spec)
    k0 = chunk_key("runs", 0, 0, 0)
    store.get(k0, lambda: pd.DataFrame({"speed": [1.0, 2.0]}))
    assert store.finished() == [k0]
    f = store.path(k0)
    table = pq.read_table(f)
    old = {k: v for k, v in table.schema.metadata.items() if k not in TABLE_FORMAT}
    pq.write_table(table.replace_schema_metadata(old), f)
    again = ChunkStore(out, spec)
    assert again.finished() == []
    recomputed = again.get(k0, lambda: pd.DataFrame({"speed": [3.0, 4.0]}))
    assert list(recomputed.speed) == [3.0, 4.0] and again.computed == 1


@pytest.mark.parametrize("fresh", [True, False], ids=["fresh", "resume"])
def test_a_users_copy_of_a_chunk_in_the_partial_directory_is_never_removed(tmp_path, fresh):
    """A Parquet file carrying a study's identity (a user's copy of a chunk or of runs.parquet) under a
    name pfjax does not give its chunks is the user's: the partial directory is refused, with --fresh
    too, and left as it is."""
    import shutil

    from pfjax.config import ConfigError
    from pfjax.montecarlo.chunks import ChunkStore

    data = {"name": "t", "n_runs": 4, "seed": 0, "paths": [{"kind": "line"}]}
    spec, _ = load_study(data=data | {"controllers": [{"name": "sf", "type": "state_feedback"}]})
    out = tmp_path / "out"
    store = ChunkStore(out, spec)
    store.get(chunk_key("margin-joint", 0, 1, 4096), lambda: pd.DataFrame({"speed": [1.0]}))
    shutil.copy(store.path(chunk_key("margin-joint", 0, 1, 4096)), store.dir / "my_backup.parquet")
    before = sorted(p.name for p in store.dir.iterdir())
    with pytest.raises(ConfigError, match=r"^--out: .* holds 'my_backup.parquet', which pfjax did not write"):
        ChunkStore(out, spec, fresh=fresh)
    assert sorted(p.name for p in store.dir.iterdir()) == before
