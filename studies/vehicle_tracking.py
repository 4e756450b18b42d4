#!/usr/bin/env python
"""Vehicle tracking with a focus point: Lemma 8.1 by batched simulation and by geometry,
and a robustness Monte Carlo of pfjax's input-output linearising controller.

    python studies/vehicle_tracking.py [--config studies/vehicle_tracking.toml] [--set key=value ...] [--out DIR] [--quick]
                                       [--overwrite]

Writes ``results/vehicle_tracking/`` (or ``--out``): ``summary.json``, ``lemma_runs.parquet``,
``lemma_table.parquet`` / ``.csv`` (the four outcomes per mode and region), ``geometry.parquet``,
``mc_runs.parquet``, ``figures/*.png|svg``, ``report.md`` and ``report.html``. The config keys are
:class:`pfjax.tracking.study_config.TrackingStudy` (docs/studies.md). Outputs are assembled in a
temporary directory and moved into place when complete; a bad key or value, or sizes whose tables
would not fit in memory, stop with one line naming the key, exit code 2, nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pfjax.cli.study import NAMED_OUT, default_out, script_parser, start_script

start_script()

from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.outputs import OutputDir, check_name  # noqa: E402
from pfjax.provenance import config_hash  # noqa: E402
from pfjax.tracking import study, study_config  # noqa: E402


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=Path(__file__).resolve().with_suffix(".toml"),
        out_default=NAMED_OUT,
        quick="small grid and sample (for tests)",
    )
    args = ap.parse_args(argv)
    return command_main("vehicle_tracking", lambda: run(args))


def run(args) -> int:
    config = study_config.load(args.config, args.set, quick=args.quick)
    check_name("name", config.name)
    out = default_out(args.out, config.name)
    cfg = config.model_dump(mode="json")
    with OutputDir(
        out,
        command="vehicle-tracking",
        config_sha256=config_hash(cfg),
        overwrite=args.overwrite,
        extra={"seed": config.seed},
    ) as output:
        summary = study.run(config, output, quick=args.quick)
        written = output.commit()
    mc = {
        k: {kk: v[kk] for kk in ("n", "success_rate", "success_ci95", "status_counts")}
        for k, v in summary["monte_carlo"].items()
    }
    headline = {"lemma_table": summary["lemma_grid"]["table"], "geometry": summary["geometry"], "monte_carlo": mc}
    print(dumps({"out": str(written), "wall_s": summary["wall_s"], **headline}))
    return 0


if __name__ == "__main__":
    from pfjax.interrupts import finished

    sys.exit(finished(main()))  # a Ctrl-C after the study ended changes nothing
