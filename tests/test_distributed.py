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

import pandas as pd
import pytest

from pfjax.cli import EXIT_USAGE, main

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
    return subprocess.Popen([sys.executable, "-m", "pfjax.cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def test_two_processes_give_the_runs_of_two_devices_and_only_process_0_writes(tmp_path):
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "PFJAX_FIGURE_WORKER": "0", "TMPDIR": str(scratch)}
    coord = f"127.0.0.1:{_free_port()}"
    procs = [_cli(["study", str(cfg), "--out", str(tmp_path / f"p{i}"), "--quiet", "--json", "--coordinator", coord,
                   "--num-processes", "2", "--process-id", str(i)], {**env, "PFJAX_HOST_DEVICES": "1"}) for i in (0, 1)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [o[1][-2000:] for o in outs]
    lead, other = (json.loads(o[0]) for o in outs)  # stdout is one JSON object each (Gloo's lines went to stderr)
    assert other == {"process_index": 1, "process_count": 2, "written_by": "process 0"}
    assert lead["process_count"] == 2 and lead["out"] == str(tmp_path / "p0")
    assert not (tmp_path / "p1").exists() and not list(scratch.iterdir())  # process 1 kept nothing
    one = _cli(["study", str(cfg), "--out", str(tmp_path / "one"), "--quiet", "--json"], {**env, "PFJAX_HOST_DEVICES": "2"})
    out, err = one.communicate(timeout=600)
    assert one.returncode == 0, err[-2000:]
    for f in ("runs.parquet", "margin.parquet"):
        pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "p0" / f), pd.read_parquet(tmp_path / "one" / f),
                                      check_exact=True)
    strip = lambda s: {k: v for k, v in s.items() if k not in ("wall_s", "timings_s")}
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("p0", "one"))
    assert strip(a) == strip(b)  # worst-case search and float64 check included (process 0's own device)
    assert a["controllers"]["lmi"]["worst_case"]["n_rollouts"] == 4 and a["float64_check"]["checked"]


@pytest.mark.parametrize("flags, flag", [
    (["--coordinator", "127.0.0.1:1234"], "--num-processes"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2"], "--process-id"),
    (["--num-processes", "2", "--process-id", "0"], "--coordinator"),
    (["--coordinator", "nohostport", "--num-processes", "2", "--process-id", "0"], "--coordinator"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "0", "--process-id", "0"], "--num-processes"),
    (["--coordinator", "127.0.0.1:1234", "--num-processes", "2", "--process-id", "2"], "--process-id"),
])
def test_bad_distributed_flags_are_one_line_naming_the_flag(flags, flag, tmp_path, capsys):
    cfg = tmp_path / "dist.toml"
    cfg.write_text(STUDY)
    assert main(["study", str(cfg), "--out", str(tmp_path / "x"), *flags]) == EXIT_USAGE
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"pfjax study: error: {flag}:"), err
    assert not (tmp_path / "x").exists()
