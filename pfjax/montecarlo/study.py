"""``pfjax study``: load and validate a study, run it, write runs, margin sweep, summary and report.

Outputs under ``results/<name>/`` (or ``--out``), assembled in a temporary directory and moved
into place only when complete: ``runs.parquet`` (one row per run), ``margin.parquet`` (the
slip-margin sweep), ``summary.json`` (strict JSON) and, unless disabled, ``report.html`` with
``figures/*.png|svg``.
"""

from __future__ import annotations

import time
from pathlib import Path

import pandas as pd

from pfjax.montecarlo.config import StudySpec, load_study
from pfjax.montecarlo.runner import margin_sweep, run_study
from pfjax.montecarlo.summary import summarize

ROOT = Path(__file__).resolve().parents[2]


def run(spec: StudySpec, out: Path | None = None, *, progress: bool | None = None, report: bool = True) -> dict:
    """Run a validated study; returns the summary."""
    from pfjax.cli import dumps

    out = Path(out) if out is not None else Path("results") / spec.name
    t0 = time.time()
    result = {}

    def finish(tmp: Path, runs_path: Path, controllers) -> dict:
        sweep = margin_sweep(spec, controllers, progress=progress) if spec.margin.enabled else None
        if sweep is not None:
            sweep.to_parquet(tmp / "margin.parquet", index=False)
        worst, worst_traj = {}, {}
        if spec.falsifier.enabled:
            from pfjax.montecarlo.runner import precision
            from pfjax.montecarlo.worst_case import worst_cases

            with precision(spec):
                worst, worst_traj = worst_cases(spec, controllers)
        runs = pd.read_parquet(runs_path)
        summary = summarize(spec, runs, sweep, gains={k: v[2] for k, v in controllers.items()}, wall_s=time.time() - t0)
        for name, block in worst.items():
            summary["controllers"][name]["worst_case"] = block
        if report:
            from pfjax.report.study_report import write_report

            write_report(tmp, spec, summary, runs, sweep, worst_traj)
            summary["wall_s"] = time.time() - t0
        (tmp / "summary.json").write_text(dumps(summary) + "\n")
        result["summary"] = summary
        return {}

    run_study(spec, out, progress=progress, extra=finish)
    return result["summary"]


def main_from_args(config: str, overrides: list[str], out: str | None, report: bool) -> dict:
    spec, _ = load_study(config, overrides)
    return run(spec, None if out is None else Path(out), report=report)
