"""Peak memory of a large streamed Monte Carlo study.

    python studies/bench/memory.py [--runs 1000000] [--horizon 1.0] [--chunk 65536] [--out results/bench_memory]

Runs ``pfjax study studies/robustness_default.toml`` in a child process with ``n_runs`` set so the
study holds about ``--runs`` runs in all (3 paths x 3 controllers), a short horizon (the cost per
run does not change what is held in memory: the metrics mode keeps O(batch) state whatever the
horizon), no margin sweep, falsifier, float64 check or report; samples the child's resident memory
every 0.2 s from ``/proc`` and takes its peak from ``getrusage``. Writes ``memory.json`` (runs,
wall time, peak RSS, the RSS trace, the size of ``runs.parquet``) beside the study's output (``--out``/study).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

from pfjax.cli.common import Parser
from pfjax.errors import InputError, command_main
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash


def rss_mib(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def main(argv=None) -> int:
    ap = Parser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1_000_000, help="runs in all (default 10^6)")
    ap.add_argument("--horizon", type=float, default=1.0, help="simulated seconds per run (default 1)")
    ap.add_argument("--chunk", type=int, default=65536, help="runs simulated per chunk")
    ap.add_argument("--out", default="results/bench_memory")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("memory.py", lambda: run(args))


def run(args) -> int:
    if args.runs < 9 or args.horizon <= 0 or args.chunk < 1:
        raise InputError("--runs/--horizon/--chunk: --runs >= 9, --horizon > 0 and --chunk >= 1 required")
    cfg = {"runs": args.runs, "horizon": args.horizon, "chunk": args.chunk}
    with OutputDir(
        args.out, command="bench-memory", config_sha256=config_hash(cfg), overwrite=args.overwrite
    ) as output:
        code = measure(args, output.staging)
        if code == 0:
            print(f"wrote {output.commit()}", file=sys.stderr)
        return code


def measure(args, out: Path) -> int:
    """Run the study in a child process into ``out/study`` and write ``out/memory.json``."""
    n_runs = args.runs // 9
    study_out = out / "study"
    h = args.horizon
    sets = [
        f"n_runs={n_runs}",
        f"chunk_size={args.chunk}",
        f"sim.horizon={h}",
        f"sim.steady_window={h / 2}",
        f"success.from_s={h / 2}",
        "margin.enabled=false",
        "falsifier.enabled=false",
        "f64_check_runs=0",
    ]
    cmd = [
        sys.executable,
        "-m",
        "pfjax.cli",
        "study",
        "studies/robustness_default.toml",
        "--no-report",
        "--fresh",
        "--out",
        str(study_out),
        "--json",
    ] + [a for s in sets for a in ("--set", s)]
    t0 = time.time()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    trace = []
    while proc.poll() is None:
        trace.append((round(time.time() - t0, 2), rss_mib(proc.pid)))
        time.sleep(0.2)
    stdout = proc.stdout.read()
    wall = time.time() - t0
    if proc.returncode != 0:
        print(f"memory.py: the study failed (exit {proc.returncode})", file=sys.stderr)
        return 1
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    json.loads(stdout)  # the CLI's one JSON object (checked); the full summary is on disk
    summary = json.loads((study_out / "summary.json").read_text())
    result = {
        "runs": summary["n_runs_total"],
        "horizon_s": h,
        "chunk_size": args.chunk,
        "wall_s": wall,
        "runs_per_s": summary["n_runs_total"] / wall,
        "peak_rss_mib": peak,
        "runs_parquet_mib": (study_out / "runs.parquet").stat().st_size / 2**20,
        "config_sha256": summary["config_sha256"],
        "pfjax_version": summary["pfjax_version"],
        "cpus": os.cpu_count(),
        "command": cmd,
        "rss_trace_mib": trace,
    }
    (out / "memory.json").write_text(json.dumps(result) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k not in ("rss_trace_mib", "command")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
