"""``pfjax bench``: the performance benchmark (pfjax vs NumPy, Numba and SciPy on one batch).

Exit codes (:data:`EPILOG`): 0 when every reference agrees with pfjax on the per-run IAE;
:data:`EXIT_DISAGREE` (1) when one does not: the outputs are written (the measurement is data), the
fractions and ratios against it are null and one line on stderr names it; 2 for bad input (one
line naming the flag, nothing written); 130 when interrupted, 143 when terminated (SIGTERM):
nothing written, or, where the signal came during the final renames, the output complete (the
line says so).
"""

from __future__ import annotations

import sys
import time

from pfjax.cli.common import UsageError, as_flags
from pfjax.errors import EXIT_FAILED

#: The exit code of a benchmark in which a reference disagrees with pfjax on the per-run IAE.
EXIT_DISAGREE = EXIT_FAILED
EPILOG = (
    "Exit codes: 0, every reference agrees with pfjax on the per-run IAE; 1, a reference disagrees with pfjax "
    "(beyond its tolerance, or not finite): the outputs are written, pfjax's fractions of it and ratios over it "
    "are null (the report names it and the difference instead), the goals read against it are not measured, "
    "and one line on stderr names it; 2, bad input (one line naming the flag, nothing written); 130, "
    "interrupted (Ctrl-C; nothing written, or, during the final renames, the output complete and the line "
    "says so); 143, terminated (SIGTERM; the same)."
)


def register(sub) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmark the simulator against a minimal JAX implementation and NumPy, Numba and SciPy references",
        description="Simulate one random batch of the slip model (sine path, 3 Newton steps, RK4 5 ms, 20 s, "
        "metrics on) with pfjax in float32 and float64 at several batch sizes, with a minimal JAX implementation "
        "of the same problem written for speed (the limit: IAE only, the same elementary functions, devices and "
        "blocks, and the problem's own shortcuts), and with independent NumPy, Numba (prange) and SciPy solve_ivp references; check they agree on "
        "the per-run IAE; report million rollout-steps/s, compile time, pfjax's fraction of the minimal "
        "implementation's throughput, ratios, gradient cost, peak memory and the CPU (vendor, family, model, flags). "
        "Writes bench.json, bench.parquet, report.md and figures/throughput.png|svg.",
        epilog=EPILOG,
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="a check that the benchmark runs, measuring none of the goals: batches of 256 and 1,024 runs of 2 s "
        "(400 steps), one timed repeat, the references on at most 1,024 runs (NumPy 256, SciPy 1), the gradient "
        "at 256 runs and the kinematic and ST models at 64 runs",
    )
    p.add_argument(
        "--sizes",
        default=None,
        help="comma-separated batch sizes of pfjax and the minimal JAX implementation (default 1000,10000,100000; "
        "--quick: 256,1024); the NumPy and Numba references run at most 10,000 (--quick: 256 and 1,024) of the "
        "largest; the gradient's batch (2,000; --quick: 256) and the vehicle-model comparison (2,000 runs; "
        "--quick: 64) do not follow --sizes",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random batch (default 0)")
    p.add_argument("--out", default="results/bench", help="output directory (default results/bench)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a pfjax output of another config or command in --out (never anything else)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (the summary)")
    p.set_defaults(func=_cmd, human=_human, failure=_failure)


def _sizes(text: str):

    try:
        return tuple(int(s) for s in text.split(","))
    except ValueError:
        raise UsageError(f"--sizes: value {text!r}, expected comma-separated positive integers") from None


def config(quick: bool = False, sizes: str | None = None, seed: int = 0):
    """The :class:`~pfjax.bench.run.BenchConfig` of ``pfjax bench [--quick] [--sizes SIZES] [--seed
    SEED]``, checked: a :class:`~pfjax.cli.common.UsageError` naming the flag otherwise (also for
    ``studies/bench/compare.py``, which judges its flags as pfjax bench does)."""
    from dataclasses import replace

    from pfjax.bench.run import QUICK, BenchConfig

    with as_flags({"sizes": "--sizes", "seed": "--seed"}):
        cfg = QUICK if quick else BenchConfig()
        if sizes is not None:
            given = _sizes(sizes)
            cfg = replace(
                cfg,
                sizes=given,
                ref_size=min(cfg.ref_size, max(given, default=1)),
                ref_numpy=min(cfg.ref_numpy, max(given, default=1)),
            )
        return replace(cfg, seed=seed)


def _cmd(args) -> dict:
    """Run the benchmark and write its outputs; returns the summary as printed. Where a reference
    disagrees with pfjax, :func:`_failure` gives the stderr line and the exit code is
    :data:`EXIT_DISAGREE`."""
    from pfjax.cli.records import units

    cfg = config(args.quick, args.sizes, args.seed)

    from pfjax.bench import report, run

    with report.output_dir(args.out, cfg, overwrite=args.overwrite) as output:  # refused before any work
        t0 = time.perf_counter()
        say = lambda m: print(f"[bench {time.perf_counter() - t0:6.1f} s] {m}", file=sys.stderr, flush=True)
        result = run.run(cfg, progress=say)
        result.update(report.provenance(result))  # config_sha256, seed, pfjax_version
        result["units"] = units(result, report.result_units(result))  # bench.json's
        out = report.write(result, output)
    # the summary with the provenance of the outputs (config_sha256, seed, pfjax_version) and its units
    printed = dict(result["summary"], out=str(out), machine=result["machine"], **report.provenance(result))
    printed["units"] = units(printed, {**report.summary_units(result["summary"]), **report.MACHINE_UNITS})
    return printed


def _failure(out: dict) -> str | None:
    """The one stderr line of a benchmark whose reference disagrees with pfjax (the command then
    exits :data:`EXIT_DISAGREE`, its outputs written); None when every reference agrees."""
    from pfjax.bench import run

    if not run.disagreeing(out):
        return None
    return (
        f"references disagree with pfjax on the per-run IAE: {run.disagreement(out)}; their fractions and "
        f"ratios are not reported; the outputs are in {out['out']}"
    )


def _human(out: dict) -> None:
    """Without ``--json``: the report (``report.md``: tables of throughput, agreement, gradient cost,
    vehicle models and goals) and where the outputs are."""
    from pathlib import Path

    print((Path(out["out"]) / "report.md").read_text(encoding="utf-8").rstrip())
    print(f"\nWritten to {out['out']}: bench.json, bench.parquet, report.md, figures/throughput.png|svg")
