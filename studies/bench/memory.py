"""Peak memory of a large streamed Monte Carlo study.

    python studies/bench/memory.py [--runs 1000000] [--horizon 1.0] [--chunk 65536] [--out results/bench_memory]

Runs ``pfjax study studies/robustness_default.toml`` in a child process with ``n_runs`` set so the
study holds about ``--runs`` runs in all (3 paths x 3 controllers), a short horizon (the cost per
run does not change what is held in memory: the metrics mode keeps O(batch) state whatever the
horizon), no margin sweep, falsifier, float64 check or report; samples the child's resident memory
every 0.2 s from ``/proc`` and takes its peak from ``getrusage``. Writes ``memory.json`` (runs,
wall time, peak RSS, the RSS trace, the size of ``runs.parquet``, their units, the machine as
``pfjax bench`` records it and the config hash of the flags) beside the study's output
(``--out``/study). Each flag is checked before anything runs (one line naming it, exit 2); Ctrl-C
stops the study, waits for it and leaves nothing behind (a new run starts afresh).
"""

from __future__ import annotations

import codecs
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

from pfjax.cli.common import Parser
from pfjax.cli.study import first_paragraph
from pfjax.errors import InputError, command_main
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash

#: the study measured: the default robustness study beside the study scripts (whatever the current directory)
STUDY = Path(__file__).resolve().parents[1] / "robustness_default.toml"


def rss_mib(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def main(argv=None) -> int:
    ap = Parser(description=first_paragraph(__doc__))
    ap.add_argument("--runs", type=int, default=1_000_000, help="runs in all (default 10^6)")
    ap.add_argument("--horizon", type=float, default=1.0, help="simulated seconds per run (default 1)")
    ap.add_argument("--chunk", type=int, default=65536, help="runs simulated per chunk")
    ap.add_argument(
        "--out",
        metavar="DIR",
        default="results/bench_memory",
        help="output directory (default: results/bench_memory, under the current directory; the study's "
        "output in DIR/study)",
    )
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)
    return command_main("memory.py", lambda: run(args))


#: The study's config keys each flag sets: a refusal of one of them names the flag.
FLAGS = {
    "n_runs": "--runs",
    "chunk_size": "--chunk",
    "sim.horizon": "--horizon",
    "sim.steady_window": "--horizon",
    "success.from_s": "--horizon",
}
#: ``memory.json``'s units (:func:`pfjax.cli.records.units`); ``rss_trace_mib``: ``[time, RSS]`` pairs.
UNITS = {
    "horizon_s": "s",
    "wall_s": "s",
    "runs_per_s": "1/s",
    "peak_rss_mib": "MiB",
    "runs_parquet_mib": "MiB",
    "rss_trace_mib": "[s, MiB]",
}
#: What an interrupted ``pfjax study`` offers, which this script cannot do (it starts afresh).
RESUME = "re-run the same command to resume"


def overrides(args) -> list[str]:
    """The study's ``--set`` overrides for the flags, each flag checked first (``--horizon``: a whole
    number of the study's steps): one line naming the flag, before anything runs."""
    from pfjax import errors, resources
    from pfjax.montecarlo.config import load_study

    runs = errors.integer("--runs", args.runs, low=9)
    errors.integer("--chunk", args.chunk, low=1)
    h = errors.number("--horizon", args.horizon, positive=True, unit=" s")
    dt = load_study(STUDY)[0].sim.dt
    if h < dt:
        raise InputError(f"--horizon: must be at least the study's step dt = {dt:g} s, got {h:g} s", "--horizon")
    try:
        resources.check_steps(h, dt)
    except InputError as e:
        raise InputError(f"--horizon: {str(e).removeprefix('dt: ')}", "--horizon") from None
    resources.whole_steps(h, dt, "--horizon")
    sets = [
        f"n_runs={runs // 9}",
        f"chunk_size={args.chunk}",
        f"sim.horizon={h}",
        f"sim.steady_window={h / 2}",
        f"success.from_s={h / 2}",
        "margin.enabled=false",
        "falsifier.enabled=false",
        "f64_check_runs=0",
    ]
    try:
        load_study(STUDY, sets)  # the study's own checks, here rather than in the child
    except InputError as e:
        if e.key == "n_runs":
            body = str(e).removeprefix("n_runs: ")
            raise InputError(f"--runs: {runs} runs give n_runs = {runs // 9} per path and controller, {body}") from None
        raise errors.renamed(e, e.key, FLAGS[e.key]) if e.key in FLAGS else e from None
    return sets


def run(args) -> int:
    sets = overrides(args)
    cfg = {"runs": args.runs, "horizon": args.horizon, "chunk": args.chunk}
    with OutputDir(
        args.out, command="bench-memory", config_sha256=config_hash(cfg), overwrite=args.overwrite
    ) as output:
        code = measure(args, sets, output.staging, config_hash(cfg))
        if code == 0:
            print(f"wrote {output.commit()}", file=sys.stderr)
        return code


def study_command(sets: list[str], study_out: Path) -> list[str]:
    """The child's command: ``pfjax study`` of :data:`STUDY` with ``sets`` into ``study_out``."""
    cmd = [sys.executable, "-m", "pfjax.cli", "study", str(STUDY), "--no-report", "--fresh"]
    return cmd + ["--out", str(study_out), "--json"] + [a for s in sets for a in ("--set", s)]


class _Stderr:
    """The child's standard error, passed on as it comes (read without blocking), but for the line
    that offers to resume."""

    def __init__(self, pipe):
        self.pipe = pipe
        os.set_blocking(pipe.fileno(), False)
        self.decoder = codecs.getincrementaldecoder("utf-8")("replace")

    def forward(self, final: bool = False) -> None:
        chunks = []
        while True:
            try:
                chunk = os.read(self.pipe.fileno(), 65536)
            except BlockingIOError:
                break
            if not chunk:
                break
            chunks.append(chunk)
        text = self.decoder.decode(b"".join(chunks), final)
        kept = "".join(line for line in text.splitlines(keepends=True) if RESUME not in line)
        if kept:
            sys.stderr.write(kept)
            sys.stderr.flush()


def _stop(proc, err: _Stderr) -> None:
    """Ctrl-C: stop the study with one SIGINT (as at a terminal) and wait until it has cleaned up
    (a second Ctrl-C kills it)."""
    try:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        while proc.poll() is None:
            err.forward()
            time.sleep(0.05)
    except KeyboardInterrupt:
        proc.kill()
        proc.wait()
    err.forward(final=True)


def measure(args, sets: list[str], out: Path, config_sha256: str) -> int:
    """Run the study in a child process into ``out/study`` and write ``out/memory.json``."""
    from pfjax.bench.report import MACHINE_UNITS
    from pfjax.bench.run import machine
    from pfjax.cli.records import units
    from pfjax.jsonio import dumps

    study_out = out / "study"
    cmd = study_command(sets, study_out)
    t0 = time.time()
    # a process group of its own: a Ctrl-C at the terminal reaches this script alone, which stops the
    # study and waits for it before its output directory is removed (_stop)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, process_group=0)
    err = _Stderr(proc.stderr)
    trace = []
    try:
        while proc.poll() is None:
            trace.append((round(time.time() - t0, 2), rss_mib(proc.pid)))
            err.forward()
            time.sleep(0.2)
    except KeyboardInterrupt:
        _stop(proc, err)
        raise
    err.forward(final=True)
    stdout = proc.stdout.read().decode()
    wall = time.time() - t0
    if proc.returncode != 0:
        print(f"memory.py: the study failed (exit {proc.returncode})", file=sys.stderr)
        return 1
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0
    json.loads(stdout)  # the CLI's one JSON object (checked); the full summary is on disk
    summary = json.loads((study_out / "summary.json").read_text())
    result = {
        "runs": summary["n_runs_total"],
        "horizon_s": args.horizon,
        "chunk_size": args.chunk,
        "wall_s": wall,
        "runs_per_s": summary["n_runs_total"] / wall,
        "peak_rss_mib": peak,
        "runs_parquet_mib": (study_out / "runs.parquet").stat().st_size / 2**20,
        "config_sha256": config_sha256,  # of --runs, --horizon and --chunk (the output's marker)
        "study_config_sha256": summary["config_sha256"],
        "pfjax_version": summary["pfjax_version"],
        "machine": machine(),  # CPU, cores, JAX and its devices, as pfjax bench records them
        "cpus": os.cpu_count(),
        "command": cmd,
        "rss_trace_mib": trace,
    }
    result["units"] = units(result, {**UNITS, **MACHINE_UNITS})
    (out / "memory.json").write_text(dumps(result) + "\n")
    print(dumps({k: v for k, v in result.items() if k not in ("rss_trace_mib", "command", "machine")}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
