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

import pfjax  # before JAX: one CPU device per core (pfjax.default_host_devices)
import pfjax.cache
from pfjax.cli.common import Parser

pfjax.cache.enable()

from pfjax.dynamic_study import config as study_config  # noqa: E402
from pfjax.dynamic_study.report import report  # noqa: E402
from pfjax.dynamic_study.runs import run  # noqa: E402
from pfjax.errors import command_main  # noqa: E402
from pfjax.report.document import to_markdown  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = Parser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", help="a TOML file of the study's keys (studies/kinematic_vs_dynamic.toml)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--out")
    ap.add_argument("--quick", action="store_true", help="a small sample and short runs (for tests)")
    ap.add_argument("--overwrite", action="store_true", help="replace a pfjax output of another config in --out")
    args = ap.parse_args(argv)

    def go() -> int:
        config = study_config.load(args.config, args.set, quick=args.quick)
        out = Path(args.out) if args.out else ROOT / "results" / config.name
        print(to_markdown(report(run(config, out, overwrite=args.overwrite))))
        return 0

    return command_main("kinematic_vs_dynamic", go)


if __name__ == "__main__":
    sys.exit(main())
