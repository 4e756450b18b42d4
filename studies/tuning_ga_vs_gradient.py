"""Tuning study: GA vs gradient tuners over seeds and problems, ablation, Table 3 check, robust designs.

    python studies/tuning_ga_vs_gradient.py [--config studies/tuning_ga_vs_gradient.toml] [--set key=value ...]
                                            [--out results/tuning] [--quick] [--overwrite]

The config schema is :class:`pfjax.tuning.study_config.TuningStudy` (its keys: docs/studies.md); the
study is :func:`pfjax.tuning.study.run` (parts in :mod:`pfjax.tuning.study_parts`, report in
:mod:`pfjax.tuning.study_report`). Writes ``summary.json``, ``tuning_runs.parquet``,
``heldout.parquet``, ``margin.parquet``, ``figures/*.png|svg``, ``report.md`` and ``report.html``,
assembled beside the output directory and moved into place at the end
(:class:`pfjax.outputs.OutputDir`). A bad key or value: one line naming it, exit 2, nothing written.
"""

from __future__ import annotations

import sys
from pathlib import Path

from pfjax.cli.study import default_out, script_parser, start_script

start_script()

from pfjax.errors import command_main  # noqa: E402
from pfjax.jsonio import dumps  # noqa: E402
from pfjax.outputs import OutputDir  # noqa: E402
from pfjax.tuning import study, study_config  # noqa: E402


def main(argv=None) -> int:
    ap = script_parser(
        __doc__,
        config=Path(__file__).resolve().with_suffix(".toml"),
        out_default="results/tuning, or results/tuning_quick with --quick",
        quick="tiny sizes (seconds of simulation; used by the tests)",
    )
    args = ap.parse_args(argv)
    return command_main("tuning_ga_vs_gradient", lambda: main_checked(args))


def main_checked(args) -> int:
    config = study_config.load(args.config, args.set, quick=args.quick)
    out = default_out(args.out, "tuning_quick" if args.quick else "tuning")
    with OutputDir(
        out,
        command="tuning-study",
        config_sha256=study.study_hash(config.model_dump(mode="json")),
        overwrite=args.overwrite,
        extra={"seeds": config.seeds},
    ) as output:
        summary = study.run(config, output.staging, progress=sys.stderr.isatty())
        out = output.commit()
    print(dumps({"out": str(out), "wall_s": round(summary["wall_s"], 1), "targets": summary["targets"]}, indent=1))
    return 0


if __name__ == "__main__":
    from pfjax.interrupts import finished

    sys.exit(finished(main()))  # a Ctrl-C after the study ended changes nothing
