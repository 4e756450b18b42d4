#!/usr/bin/env python
"""Kinematic vs dynamic: does the robustness verdict of the kinematic slip studies survive a vehicle
whose slip comes from tyre forces (CommonRoad's single-track model, :mod:`pfjax.sim.dynamic`)?

    python studies/kinematic_vs_dynamic.py [--config studies/kinematic_vs_dynamic.toml] [--set key=value ...]
                                           [--out DIR] [--quick] [--overwrite]

The arms (dynamic, high friction, kinematic slip ranges, LMI designs, passenger-car scale) are
described in :mod:`pfjax.dynamic_study.arms`; the config keys in
:class:`pfjax.dynamic_study.config.KinematicVsDynamic`. Writes to ``results/kinematic_vs_dynamic/``
(or ``--out``): ``runs.parquet`` (one row per arm, path, controller and run), ``summary.json``,
``report.md`` and ``report.html``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pfjax.cli.study import NAMED_OUT, default_out, script_parser, start_script

start_script(x64=False)

from pfjax.dynamic_study import config as study_config  # noqa: E402
from pfjax.dynamic_study.report import report  # noqa: E402
from pfjax.dynamic_study.runs import run  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.report.document import to_markdown  # noqa: E402


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=Path(__file__).resolve().with_suffix(".toml"),
        out_default=NAMED_OUT,
        quick="a small sample and short runs (for tests)",
    )
    args = ap.parse_args(argv)

    def go() -> int:
        config = study_config.load(args.config, args.set, quick=args.quick)
        out = default_out(args.out, config.name)
        print(to_markdown(report(run(config, out, overwrite=args.overwrite))))
        return 0

    return command_main("kinematic_vs_dynamic", go)


if __name__ == "__main__":
    from pfjax.interrupts import finished

    sys.exit(finished(main()))  # a Ctrl-C after the study ended changes nothing
