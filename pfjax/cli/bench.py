"""``pfjax bench``: the performance benchmark (pfjax vs NumPy, Numba and SciPy on one batch)."""

from __future__ import annotations

import sys
import time

from pfjax.cli.common import UsageError, as_flags


def register(sub) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmark the simulator against a minimal JAX implementation and NumPy, Numba and SciPy references",
        description="Simulate one random batch of the slip model (sine path, 3 Newton steps, RK4 5 ms, 20 s, "
        "metrics on) with pfjax in float32 and float64 at several batch sizes, with a minimal JAX implementation "
        "of the same problem written for speed (the limit: IAE only, the same elementary functions, devices and "
        "blocks), and with independent NumPy, Numba (prange) and SciPy solve_ivp references; check they agree on "
        "the per-run IAE; report million rollout-steps/s, compile time, pfjax's fraction of the minimal "
        "implementation's throughput, ratios, gradient cost, peak memory and the CPU (vendor, family, model, flags). "
        "Writes bench.json, bench.parquet, report.md and figures/throughput.png|svg.",
    )
    p.add_argument("--quick", action="store_true", help="small batches and a 2 s horizon (well under a minute)")
    p.add_argument(
        "--sizes",
        default=None,
        help="comma-separated batch sizes of pfjax and the minimal JAX implementation (default 1000,10000,100000; "
        "--quick: 256,1024); the NumPy and Numba references run at most 10,000 (--quick: 256 and 1,024) of the "
        "largest; the gradient's batch (2,000; --quick: 256) and the vehicle-model comparison (2,000 runs; "
        "--quick: 64) do not follow --sizes",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random batch")
    p.add_argument("--out", default="results/bench", help="output directory (default results/bench)")
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a pfjax output of another config or command in --out (never anything else)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (the summary)")
    p.set_defaults(func=_cmd, human=_human)


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
    from pfjax.cli.records import units

    cfg = config(args.quick, args.sizes, args.seed)

    from pfjax.bench import report, run

    with report.output_dir(args.out, cfg, overwrite=args.overwrite) as output:  # refused before any work
        t0 = time.perf_counter()
        say = lambda m: print(f"[bench {time.perf_counter() - t0:6.1f} s] {m}", file=sys.stderr, flush=True)
        result = run.run(cfg, progress=say)
        result["units"] = units(result, report.result_units(result))  # bench.json's
        out = report.write(result, output)
    # the summary with the provenance of the outputs (config_sha256, seed, pfjax_version) and its units
    printed = dict(result["summary"], out=str(out), machine=result["machine"], **report.provenance(result))
    return dict(printed, units=units(printed, {**report.summary_units(result["summary"]), **report.MACHINE_UNITS}))


def _human(out: dict) -> None:
    """Without ``--json``: the report (``report.md``: tables of throughput, agreement, gradient cost,
    vehicle models and goals) and where the outputs are."""
    from pathlib import Path

    print((Path(out["out"]) / "report.md").read_text(encoding="utf-8").rstrip())
    print(f"\nWritten to {out['out']}: bench.json, bench.parquet, report.md, figures/throughput.png|svg")
