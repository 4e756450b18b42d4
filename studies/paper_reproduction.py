#!/usr/bin/env python
"""Reproduce Fakharian et al. (docs/reproductions/path-following.md) and check every claim it makes.

    python studies/paper_reproduction.py [--config studies/paper_reproduction.toml] [--set key=value ...] [--out DIR] [--quick]
                                         [--overwrite]

Writes to ``results/paper_reproduction/`` (or ``--out``): ``summary.json``, ``runs.parquet`` /
``runs.csv`` (one row per path x controller), ``pi_readings.csv`` (the 24 readings of Table 3),
``stability.parquet`` (the (beta_r, beta_f) grid), ``figures/*.png|svg``, ``report.md`` and
``report.html``. The config keys are :class:`pfjax.reproduce.paper_config.PaperStudy`
(docs/studies.md); a bad key or value stops with one line naming it, exit code 2, nothing written.
Every number in the report is computed by the study; the source's published values are read from
the config's ``[source]`` table and always labelled as the source's.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from pfjax.cli.study import NAMED_OUT, default_out, script_parser, start_script

start_script()

from tqdm import tqdm  # noqa: E402

from pfjax.errors import command_main  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.provenance import config_hash  # noqa: E402
from pfjax.reproduce import paper_config, paper_study  # noqa: E402


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=Path(__file__).resolve().with_suffix(".toml"),
        out_default=NAMED_OUT,
        quick="small sizes (tests, a first look)",
    )
    args = ap.parse_args(argv)
    return command_main("paper_reproduction", lambda: run(args))


def run(args) -> int:
    config = paper_config.load(args.config, args.set, quick=args.quick)
    check_name("name", config.name)
    out = default_out(args.out, config.name)
    t0 = time.time()
    # Assembled beside the target and moved into place at the end: nothing half-written, nothing
    # that pfjax did not write replaced (pfjax.outputs).
    with OutputDir(
        out,
        command="paper-reproduction",
        config_sha256=config_hash(config.model_dump(mode="json")),
        overwrite=args.overwrite,
        extra={"seed": config.seed},
    ) as output:
        with tqdm(total=paper_study.n_steps(config), desc="paper reproduction", disable=None) as pbar:
            summary = paper_study.run(config, output, pbar)
        output.commit()
    print(f"wrote {out} ({time.time() - t0:.0f} s)")
    for v in summary["verdicts"]:
        print(f"  [{v['verdict']:>14s}] {v['claim']} — {v['path']}, {v['subject']}: {v['criterion'][:60]}")
    return 0


if __name__ == "__main__":
    from pfjax.interrupts import finished

    sys.exit(finished(main()))  # a Ctrl-C after the study ended changes nothing
