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


def run(spec: StudySpec, out: Path | None = None, *, progress: bool | None = None, report: bool = True,
        fresh: bool = False, warn=None) -> dict:
    """Run a validated study; returns the summary.

    Resumes an interrupted run of the same study into ``out`` (its finished chunks are reused);
    ``fresh=True`` discards them and starts over. ``warn(message)`` receives each feasibility
    warning (:func:`pfjax.montecarlo.checks.study_warnings`) before the simulation starts; the
    warnings are also recorded in ``summary.json``.
    """
    from pfjax.cli import dumps
    from pfjax.montecarlo.checks import float64_check, sample_indices, study_warnings
    from pfjax.montecarlo.runner import precision

    out = Path(out) if out is not None else Path("results") / spec.name
    t0 = time.time()
    result = {}
    warnings = study_warnings(spec)
    for w in warnings:
        (warn or (lambda m: None))(w)

    def finish(tmp: Path, runs_path: Path, controllers, store) -> dict:
        timings = {"runs": time.time() - t0}  # s per phase (wall clock), in summary.json
        lap = [time.time()]

        def mark(phase):
            now = time.time()
            timings[phase] = now - lap[0]
            lap[0] = now

        sweep = margin_sweep(spec, controllers, progress=progress, store=store) if spec.margin.enabled else None
        if sweep is not None:
            sweep.to_parquet(tmp / "margin.parquet", index=False)
            _stamp(tmp / "margin.parquet", spec)
        mark("margin")
        worst, worst_traj = {}, {}
        if spec.falsifier.enabled:
            from pfjax.montecarlo.worst_case import worst_cases

            with precision(spec):
                worst, worst_traj = worst_cases(spec, controllers)
        mark("worst_case")
        # Without a report the run table is never loaded whole: the summary reads one controller at
        # a time and the float64 check only its sampled runs (memory: one controller's rows at most).
        runs = read_runs(runs_path) if report else None
        check_rows = runs if runs is not None or spec.dtype == "float64" or spec.f64_check_runs <= 0 else \
            read_runs(runs_path, filters=[("run", "in", sample_indices(spec, spec.f64_check_runs).tolist())])
        check = float64_check(spec, controllers, check_rows, spec.f64_check_runs)
        mark("float64_check")
        summary = summarize(spec, runs if runs is not None else runs_path, sweep,
                            gains={k: v[2] for k, v in controllers.items()}, wall_s=time.time() - t0)
        summary["warnings"] = warnings
        summary["float64_check"] = check
        summary["chunks"] = {"simulated": store.computed, "resumed": store.reused}
        for name, block in worst.items():
            summary["controllers"][name]["worst_case"] = block
        mark("summary")
        if report:
            from pfjax.report.study_report import write_report

            write_report(tmp, spec, summary, runs, sweep, worst_traj)
            mark("report")
            summary["wall_s"] = time.time() - t0
        summary["timings_s"] = timings
        (tmp / "summary.json").write_text(dumps(summary) + "\n")
        result["summary"] = summary
        return {}

    run_study(spec, out, progress=progress, extra=finish, fresh=fresh)
    return result["summary"]


def read_runs(path: Path, **kw) -> pd.DataFrame:
    """``runs.parquet`` as a DataFrame (pandas >= 3 keeps the string columns Arrow-backed, a few
    bytes per run); ``kw`` go to :func:`pandas.read_parquet` (``columns``, ``filters``)."""
    return pd.read_parquet(path, **kw)


def _stamp(path: Path, spec: StudySpec) -> None:
    """Rewrite a small Parquet file with the study's config, hash, seed and version in its metadata."""
    import pyarrow.parquet as pq

    from pfjax.montecarlo.chunks import file_metadata

    t = pq.read_table(path)
    pq.write_table(t.replace_schema_metadata({**(t.schema.metadata or {}), **file_metadata(spec)}), path)


def main_from_args(config: str, overrides: list[str], out: str | None, report: bool) -> dict:
    spec, _ = load_study(config, overrides)
    return run(spec, None if out is None else Path(out), report=report)
