"""A Monte Carlo study's ``report.md`` and ``report.html``: the page a person reads to see which
controller is more robust and by how much.

:func:`write_report` draws the figures (:mod:`pfjax.report.study_figures`, written to
``figures/<name>.png`` and ``.svg``) unless given, builds the report
(:func:`pfjax.report.study_document.study_document`) from the study's summary (see
:mod:`pfjax.montecarlo.summary`) and run table, and writes it with the one report writer
(:func:`pfjax.report.document.write`): Markdown with the figures linked, and one self-contained
HTML page with the figures embedded as base64 PNG. The verdict's paired comparison is explained in
:mod:`pfjax.report.study_verdict`.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.sampling import column_names
from pfjax.report import document
from pfjax.report.figure_set import draw_figures
from pfjax.report.study_document import study_document
from pfjax.report.study_figures import controller_colors

__all__ = ["write_report"]


def write_report(
    out_dir: Path,
    spec: StudySpec,
    summary: dict,
    runs: pd.DataFrame,
    worst_trajectories: dict | None = None,
    figures: dict | None = None,
) -> list[Path]:
    """Write ``out_dir/report.md``, ``out_dir/report.html`` (self-contained) and, unless given,
    ``out_dir/figures/<name>.png|svg``; returns the report files written.

    Args:
        out_dir: the study's output (or staging) directory (created if missing).
        spec: the validated study.
        summary: the study summary (:func:`pfjax.montecarlo.summary.summarize`).
        runs: one row per run (``runs.parquet``).
        worst_trajectories: the falsifier's worst runs per controller (:mod:`pfjax.montecarlo.worst_case`),
            or None when the study did no worst-case search.
        figures: :func:`pfjax.report.figure_set.report_figures` of the same study if already rendered.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cfg = summary.get("config") or spec.model_dump(mode="json")
    colors = controller_colors(cfg["controllers"])
    params = [c for c in column_names(spec) if c in runs.columns and runs[c].nunique(dropna=True) > 1]
    if figures is None:
        figures = draw_figures(out_dir, spec, summary, runs, colors, worst_trajectories)
    doc = study_document({**summary, "config": cfg}, runs, figures, params, colors)
    return document.write(doc, out_dir)
