"""A study over several processes (``pfjax study --coordinator/--num-processes/--process-id``):
two processes of one CPU device each, joined by ``jax.distributed`` on this machine, give the same
runs, bit for bit, as one process with two devices (the same per-device program), and only process 0
writes. Bad flags: one line naming the flag, exit code 2, before any process waits for the others.
"""

import json
import os
import socket
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from pfjax.cli import EXIT_USAGE, main
from pfjax.montecarlo import chunk_runs as runner  # the chunk loop reads simulate_chunk from its home
from pfjax.montecarlo.chunks import partial_dir
from pfjax.montecarlo.config import load_study
from pfjax.montecarlo.study import run

STUDY = """name = "dist"
n_runs = 20
seed = 11
chunk_size = 12
dtype = "float32"
f64_check_runs = 8
[sim]
horizon = 1.0
steady_window = 0.5
[success]
from_s = 0.5
band = 0.2
[initial]
lateral_offset = { dist = "uniform", low = -0.3, high = 0.3 }
[margin]
n_per_amplitude = 4
amplitudes_deg = [0.0, 10.0]
[[paths]]
kind = "sine"
[[controllers]]
name = "lmi"
type = "lmi"
[falsifier]
enabled = true
path = "sine"
n_restarts = 2
steps = 2
"""  # the falsifier and the float64 check run on process 0's own device while both processes simulate


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _cli(args, env):
    return subprocess.Popen(
        [sys.executable, "-m", "pfjax.cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )


def test_two_processes_give_the_runs_of_two_devices_and_only_process_0_writes(tmp_path):
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "PFJAX_FIGURE_WORKER": "0", "TMPDIR": str(scratch)}
    coord = f"127.0.0.1:{_free_port()}"
    procs = [
        _cli(
            [
                "study",
                str(cfg),
                "--out",
                str(tmp_path / f"p{i}"),
                "--quiet",
                "--json",
                "--coordinator",
                coord,
                "--num-processes",
                "2",
                "--process-id",
                str(i),
            ],
            {**env, "PFJAX_HOST_DEVICES": "1"},
        )
        for i in (0, 1)
    ]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    lead, other = (json.loads(o[0]) for o in outs)  # stdout is one JSON object each (Gloo's lines went to stderr)
    assert other == {"process_index": 1, "process_count": 2, "written_by": "process 0", "chunks": lead["chunks"]}
    assert lead["chunks"] == {"simulated": 5, "resumed": 0}  # 2 chunks of runs, 3 of the margin sweep (one per axis)
    assert lead["process_count"] == 2 and lead["out"] == str(tmp_path / "p0")
    assert not (tmp_path / "p1").exists() and not list(scratch.iterdir())  # process 1 kept nothing
    one = _cli(
        ["study", str(cfg), "--out", str(tmp_path / "one"), "--quiet", "--json", "--no-report"],
        {**env, "PFJAX_HOST_DEVICES": "2"},
    )
    out, err = one.communicate(timeout=600)
    assert one.returncode == 0, err[-2000:]
    for f in ("runs.parquet", "margin.parquet"):
        pd.testing.assert_frame_equal(
            pd.read_parquet(tmp_path / "p0" / f), pd.read_parquet(tmp_path / "one" / f), check_exact=True
        )
    strip = lambda s: {k: v for k, v in s.items() if k not in ("wall_s", "timings_s", "machine")}
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("p0", "one"))
    assert strip(a) == strip(b)  # worst-case search and float64 check included (process 0's own device)
    assert "2 cpu device(s) over 2 processes" in a["machine"] and "process" not in b["machine"]
    assert a["controllers"]["lmi"]["worst_case"]["n_rollouts"] == 4 and a["float64_check"]["checked"]


def _pair(cfg, out, env, *extra, out1=None, extra1=()):
    """Processes 0 and 1 of one study; process 1 writes nothing, so its ``--out`` (``out1``, default
    ``out``) matters only for the checks, as on another host; ``extra1``: process 1's own flags."""
    coord = f"127.0.0.1:{_free_port()}"
    procs = [
        _cli(
            [
                "study",
                str(cfg),
                "--out",
                str(out if i == 0 or out1 is None else out1),
                "--quiet",
                "--json",
                "--no-report",
                "--coordinator",
                coord,
                "--num-processes",
                "2",
                "--process-id",
                str(i),
                *extra,
                *(extra1 if i == 1 else ()),
            ],
            {**env, "PFJAX_HOST_DEVICES": "1"},
        )
        for i in (0, 1)
    ]
    return procs, [p.communicate(timeout=600) for p in procs]


class Interrupt(BaseException):
    """Stands for a kill."""


def test_two_processes_resume_process_0s_interrupted_run(tmp_path, monkeypatch):
    """Process 0 finds 3 of the 5 chunks finished in its partial directory (an interrupted run) and
    tells process 1, which skips the same chunks (else their sharded programs would fall out of
    step); the LMI gains come from process 0. The resumed study equals an uninterrupted one."""
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY.replace('dtype = "float32"', 'dtype = "float64"').replace("enabled = true", "enabled = false"))
    spec = load_study(cfg)[0]
    out = tmp_path / "out"
    real, calls = runner.simulate_chunk, []

    def dies_after_3(*a, **k):
        if len(calls) == 3:
            raise Interrupt
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(runner, "simulate_chunk", dies_after_3)
    with pytest.raises(Interrupt):
        run(spec, out, progress=False, report=False)
    monkeypatch.undo()
    assert len(list(partial_dir(out).glob("*.parquet"))) == 3 and not out.exists()
    run(spec, tmp_path / "ref", progress=False, report=False)

    procs, outs = _pair(cfg, out, {**os.environ, "PFJAX_FIGURE_WORKER": "0"})
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    lead, other = (json.loads(o[0]) for o in outs)
    assert lead["chunks"] == other["chunks"] == {"simulated": 2, "resumed": 3}
    assert not partial_dir(out).exists()
    for f in ("runs.parquet", "margin.parquet"):
        a, b = pd.read_parquet(out / f), pd.read_parquet(tmp_path / "ref" / f)
        num = [c for c in a.columns if a[c].dtype.kind == "f"]
        pd.testing.assert_frame_equal(a.drop(columns=num), b.drop(columns=num), check_exact=True)
        # one device here, two there: other vector code for the blocks, float64 rounding at most
        np.testing.assert_allclose(a[num].to_numpy(), b[num].to_numpy(), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("case", ["other config's chunks", "a user directory"])
def test_a_refused_resume_stops_every_process_with_one_line(case, tmp_path):
    """Process 0 refuses its --out (its partial directory holds another config's chunks, or --out is
    a directory pfjax did not write): one line naming --out, exit 2, and it sends the error, so
    process 1 stops with it instead of waiting."""
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    out = tmp_path / "out"
    if case == "a user directory":
        out.mkdir()
        (out / "thesis.tex").write_text("data")
    else:
        import pyarrow as pa
        import pyarrow.parquet as pq

        partial_dir(out).mkdir()  # as pfjax writes it, for another config
        manifest = {"study": "dist", "config_sha256": "0" * 64, "seed": 0, "pfjax_version": "0"}
        (partial_dir(out) / "manifest.json").write_text(json.dumps(manifest))
        chunk = pa.table({"x": [1.0]}).replace_schema_metadata({b"pfjax.config_sha256": b"0" * 64})
        pq.write_table(chunk, partial_dir(out) / "runs-p000-c000-0000000000.parquet")
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    # process 1's --out as on another host (its own, empty): only process 0 refuses, and tells it at once
    procs, outs = _pair(
        cfg, out, {**os.environ, "PFJAX_FIGURE_WORKER": "0"}, "--coordinator-timeout", "300", out1=tmp_path / "p1"
    )
    assert [p.returncode for p in procs] == [EXIT_USAGE, EXIT_USAGE], [o[1][-2000:] for o in outs]
    for _, err in outs:
        line = [x for x in err.strip().splitlines() if x.startswith("pfjax study:")]
        assert len(line) == 1 and line[0].startswith("pfjax study: error: --out: "), err[-2000:]
        assert ("--fresh" in line[0]) == (case != "a user directory"), line
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before


def test_processes_given_other_studies_stop_alike_before_any_run(tmp_path):
    """Process 1 given another --set: every process stops with the same line naming the config
    (each would otherwise simulate its share with its own settings, and process 0 would write the
    mixture under its own hash); nothing is written."""
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    procs, outs = _pair(cfg, tmp_path / "out", {**os.environ, "PFJAX_FIGURE_WORKER": "0"}, extra1=("--set", "seed=12"))
    assert [p.returncode for p in procs] == [EXIT_USAGE, EXIT_USAGE], [o[1][-2000:] for o in outs]
    lines = [[x for x in err.strip().splitlines() if x.startswith("pfjax study:")] for _, err in outs]
    assert lines[0] == lines[1] and len(lines[0]) == 1, lines
    assert lines[0][0].startswith("pfjax study: error: config: process 1's study differs from process 0's"), lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dist.toml"]


@pytest.mark.parametrize(
    "flags, flag",
    [
        (["--coordinator", "127.0.0.1:1234"], "--num-processes"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2"], "--process-id"),
        (["--num-processes", "2", "--process-id", "0"], "--coordinator"),
        (["--coordinator", "nohostport", "--num-processes", "2", "--process-id", "0"], "--coordinator"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "0", "--process-id", "0"], "--num-processes"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"], "--process-id"),
        (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "-1"], "--process-id"),
        (["--coordinator-timeout", "nan"], "--coordinator-timeout"),
    ],
)
def test_bad_distributed_flags_are_one_line_naming_the_flag(flags, flag, tmp_path, capsys):
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    assert main(["study", str(cfg), "--out", str(tmp_path / "x"), *flags]) == EXIT_USAGE
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"pfjax study: error: {flag}:"), err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    "args, key",
    [
        (("127.0.0.1:1234", 2, 5), "process_id"),
        (("127.0.0.1:1234", 2, -1), "process_id"),
        (("127.0.0.1:1234", 0, 0), "num_processes"),
        (("nohostport", 2, 0), "coordinator"),
        (("127.0.0.1:70000", 2, 0), "coordinator"),
        (("127.0.0.1:1234", 2, 1.5), "process_id"),
    ],
)
def test_the_library_checks_the_distributed_settings_as_the_command_line(args, key, monkeypatch):
    """``initialize_distributed`` refuses bad settings at once, naming them (the command line maps
    the names onto its flags), before waiting for anything."""
    from pfjax.errors import InputError
    from pfjax.sim import sharding

    monkeypatch.setattr(sharding, "reach_coordinator", lambda *a: pytest.fail("waited"))
    with pytest.raises(InputError) as e:
        sharding.initialize_distributed(*args)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ")
    with pytest.raises(InputError, match=r"^timeout_s: "):
        sharding.initialize_distributed("127.0.0.1:1234", 2, 0, timeout_s=-1)
    assert not sharding.joined()


def test_a_failed_command_in_a_joined_process_ends_without_the_shutdown_barrier(tmp_path, monkeypatch, capsys):
    """JAX's exit handler waits (minutes) for every process at a shutdown barrier; a process whose
    command failed or was interrupted ends at once with its exit code instead."""
    from pfjax.sim import sharding

    class Ended(BaseException):
        pass

    def exit_now(code):
        raise Ended(code)

    monkeypatch.setattr(sharding, "joined", lambda: True)
    monkeypatch.setattr(os, "_exit", exit_now)
    with pytest.raises(Ended) as e:
        main(["study", str(tmp_path / "missing.toml")])
    assert e.value.args == (EXIT_USAGE,) and "missing.toml" in capsys.readouterr().err


UNPAD_CHILD = """
import sys
import pfjax
import jax
import numpy as np
from pfjax.sim import sharding

sharding.initialize_distributed(sys.argv[1], 2, int(sys.argv[2]))
tree = {"a": np.arange(9.0, dtype=np.float32)}  # 9 runs over 2 processes' devices: padded to 10
placed, n, _ = sharding.plan_batch(tree, None, block=None)
assert placed["a"].shape[0] > n and not placed["a"].is_fully_addressable
print(np.asarray(sharding.gather(sharding.unpad(placed, n))["a"]).tolist())
"""


def test_a_padded_batch_over_two_processes_is_cut_and_gathered():
    """unpad of a padded batch that spans two processes' devices (which no process can read whole)
    cuts it in a program, and gather gives every process the runs."""
    coord = f"127.0.0.1:{_free_port()}"
    env = {**os.environ, "PFJAX_HOST_DEVICES": "1"}
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", UNPAD_CHILD, coord, str(i)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for i in (0, 1)
    ]
    outs = [p.communicate(timeout=300) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    for out, _ in outs:
        assert out.strip().splitlines()[-1] == str([float(i) for i in range(9)])
