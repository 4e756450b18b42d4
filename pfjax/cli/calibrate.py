"""``pfjax calibrate``: measure this CPU's best block size and vector width, and keep them."""

from __future__ import annotations

import sys
import time


def register(sub) -> None:
    p = sub.add_parser(
        "calibrate",
        help="measure this CPU's best CPU block size, vector width and sine-cosine sharing and keep them for later runs",
        description="Simulate the benchmark problem (pfjax bench's) with pfjax's simulator program for every "
        "candidate vector width (XLA's default; 512 bits with AVX-512) and block size (2,500-20,000 bytes per "
        "batched array) in float32 and float64, and keep the fastest in the calibration directory "
        "($PFJAX_CALIBRATION_DIR, else $XDG_CACHE_HOME/pfjax/calibration (default ~/.cache/pfjax/calibration), "
        "whatever PFJAX_CACHE_DIR says), where every later pfjax process on a CPU of the same identity reads it. PFJAX_CALIBRATION=off ignores it. "
        "The directory is made and a file written and removed in it, and the calibration file is checked, before "
        "measuring: a file there that is not a pfjax calibration is never replaced. Each candidate simulates 20,000 runs "
        "of 5 s (1,000 steps), best of 3 rounds, after a compiling call: 8 candidates per precision with AVX-512 "
        "(2 widths x 4 blocks), 4 without; then, at the chosen width and block of each precision, the sine-cosine "
        "pair shared between the simulator's kernels as one complex number and as two reals (PFJAX_SINCOS_SHARING "
        "overrides the choice). A candidate whose per-run IAE differs from the first's by more than the "
        "benchmark's tolerance (float32 1e-4 m s, float64 1e-10 m s: rounding) is never chosen; when none agrees, "
        "nothing is kept (one line on stderr, exit 1).",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="1,024 runs of 0.5 s, one round, blocks of 2,500 and 5,000 bytes: a rough choice",
    )
    p.add_argument("--dry-run", action="store_true", help="measure and print, but keep nothing")
    p.add_argument("--json", action="store_true", help="print one JSON object (the calibration)")
    p.set_defaults(func=_cmd, failure=_failure)


def _cmd(args) -> dict:
    from pfjax.bench.calibrate import calibrate
    from pfjax.numerics import calibration

    if not args.dry_run:
        calibration.writable_directory()  # before measuring: where the result goes, and its file
    t0 = time.perf_counter()
    say = lambda m: print(f"[calibrate {time.perf_counter() - t0:6.1f} s] {m}", file=sys.stderr, flush=True)
    if args.quick:
        result = calibrate(batch=1024, horizon=0.5, rounds=1, blocks=(2_500, 5_000), progress=say)
    else:
        result = calibrate(progress=say)
    failed = result.get("failed")
    out = None if args.dry_run or failed else str(calibration.save(result))
    shown = {k: v for k, v in result.items() if k != "machine"}  # the machine record stays in the file
    if isinstance(shown.get("units"), dict):  # and so do its units
        shown["units"] = {k: u for k, u in shown["units"].items() if not k.startswith("machine.")}
    return dict(shown, file=out)  # failed: printed (data), nothing kept, then _failure's line and exit 1


def _failure(out: dict) -> str | None:
    """The stderr line of a calibration in which no candidate agrees with the default settings
    (nothing was kept; exit 1); None otherwise."""
    return f"{out['failed']}; nothing was kept" if out.get("failed") else None
