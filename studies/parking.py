#!/usr/bin/env python
"""Parking by switching travel direction and gain (docs/reproductions/parking.md): every case of its §4,
the a_f calibration, the garage X_s tries, the GA and grid searches, the start-pose map and a
robustness Monte Carlo.

    python studies/parking.py [--config studies/parking.toml] [--set key=value ...] [--out DIR] [--quick] [--overwrite]

Writes to ``results/parking/`` (or ``--out``): ``summary.json`` (config, SHA-256, seed, version),
``cases.parquet``, ``assumptions.parquet`` (cases A-D under every combination of the open assumptions),
``grid.parquet``, ``start_map.parquet``, ``montecarlo.parquet``, ``figures/*.png|svg``, ``report.md``
and ``report.html``. The config schema is :class:`pfjax.parking.study_config.ParkingStudy`. Outputs are
assembled in a temporary directory and moved into place when complete; a bad key or value stops with
one line, exit 2, nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pfjax
from pfjax.cli.study import NAMED_OUT, default_out, script_parser, start_script

start_script()

from pfjax.errors import command_main  # noqa: E402
from pfjax.parking.study_config import load  # noqa: E402


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=Path(__file__).resolve().with_suffix(".toml"),
        out_default=NAMED_OUT,
        quick="small sizes (tests)",
    )
    args = ap.parse_args(argv)
    return command_main("parking", lambda: run(args))


def run(args) -> int:
    config = load(args.config, args.set, quick=args.quick)
    out = default_out(args.out, config.name)
    out, summary = pfjax.parking.run_study(config, out, quick=args.quick, overwrite=args.overwrite, flag="--out")
    print(f"wrote {out} in {summary['wall_s']:.1f} s")
    return 0


if __name__ == "__main__":
    from pfjax.interrupts import finished

    sys.exit(finished(main()))  # a Ctrl-C after the study ended changes nothing
