"""A study report's figures: which, in what order, with what caption, rendered to files.

:func:`report_figures` draws the figures of :data:`FIGURES` (builders in
:mod:`pfjax.report.study_figures` and :mod:`pfjax.report.worst_case_figures`) into
``out_dir/figures/<name>.png|svg`` and returns them ready for the page (caption and base64 PNG).
The module needs matplotlib, pandas and NumPy, and JAX only for the slip map's linearised
prediction, so the figure worker (:mod:`pfjax.report.figure_worker`) starts without JAX.
"""

from __future__ import annotations

import base64
import math
from pathlib import Path

import numpy as np
import pandas as pd

from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.dists import nominal
from pfjax.report.figures import save
from pfjax.report.study_figures import (
    controller_colors,
    distribution_figure,
    freeze_layout,
    headline_figure,
    margin_figure,
    slip_map_figure,
    success_by_param_figure,
)
from pfjax.report.worst_case_figures import worst_case_figure

#: The report's figures, in the report's order.
FIGURES = (
    "worst_cases",
    "headline",
    "margin_curves",
    "dist_iae",
    "dist_late_max_abs_d",
    "slip_map",
    "success_by_param",
)
#: The figures drawn from the run table (the others need only the summary and the worst cases).
NEEDS_RUNS = {"dist_iae", "dist_late_max_abs_d", "slip_map"}


def _png_base64(path: Path) -> str:
    return base64.b64encode(path.read_bytes()).decode("ascii")


def captions(spec: StudySpec) -> dict[str, str]:
    """The caption under each figure of :data:`FIGURES` in ``report.html``."""
    band_mm = 1000 * spec.success.band
    return {
        "worst_cases": "Worst cases found by gradient ascent through the simulator (pfjax.falsification) over bounded, "
        "band-limited slip profiles and initial errors: the worst run's path, slip and lateral error, and the worst "
        "objective found against the rollouts spent, compared with random search of the same budget.",
        "headline": "Which controller is more robust: success rate with its 95 % interval, slip margin per axis, IAE spread.",
        "margin_curves": "Success rate against the slip amplitude, with 95 % Clopper-Pearson bands; the dashed line is "
        "1 − ε and each triangle a controller's margin (the largest amplitude at which it, and every smaller one, "
        "stays above).",
        "dist_iae": "IAE per path: histogram (fraction of runs per bin) and empirical CDF (further left and higher is "
        "better). Failed runs count as +∞: the ECDF stops short of 1 by the failed fraction.",
        "dist_late_max_abs_d": f"Largest |d| in the success window; runs left of the dashed line ({band_mm:g} mm) meet "
        "the accuracy criterion.",
        "slip_map": "From simulation: success rate of the study's runs binned over their sampled slip angles (all paths "
        "pooled). Dashed, where shown: beyond it no straight-line equilibrium exists (|steering| would exceed the "
        "nominal δ_max). Solid (state-feedback controllers): the linearised prediction on a straight line — the true "
        "equilibrium exists, is Hurwitz and has |d*| within the success band (pfjax.analysis.stability_map, nominal "
        "v, L, δ_max).",
        "success_by_param": "Where failures come from: success rate per bin of each sampled parameter (a flat curve: "
        "the parameter does not matter; a drop: failures concentrate there).",
    }


def figure_entries(out_dir: Path, spec: StudySpec, names) -> dict[str, dict]:
    """``{name: {"name", "caption", "b64"}}`` for figures already written to ``out_dir/figures``
    (the PNG base64-encoded for the page)."""
    text = captions(spec)
    return {
        n: {"name": n, "caption": text[n], "b64": _png_base64(Path(out_dir) / "figures" / f"{n}.png")} for n in names
    }


def draw_figures(
    out_dir: Path,
    spec: StudySpec,
    summary: dict,
    runs: pd.DataFrame,
    colors: dict,
    worst_trajectories: dict | None = None,
    names=None,
) -> dict[str, dict]:
    fig_dir = out_dir / "figures"
    paths = list(summary.get("paths") or ([] if runs is None else runs["path"].unique()))
    band_mm = 1000 * spec.success.band
    from_s = spec.success.from_s
    build = {
        "worst_cases": lambda: worst_case_figure(worst_trajectories, summary, colors) if worst_trajectories else None,
        "headline": lambda: headline_figure(summary, colors),
        "margin_curves": lambda: margin_figure(summary, colors),
        "dist_iae": lambda: distribution_figure(runs, "iae", colors, paths, unit="m·s", label="IAE ∫|d| dt"),
        "dist_late_max_abs_d": lambda: distribution_figure(
            runs,
            "late_max_abs_d",
            colors,
            paths,
            scale=1000.0,
            unit="mm",
            label=f"max |d| from t = {from_s:g} s",
            band=band_mm,
        ),
        "slip_map": lambda: slip_map_figure(
            runs,
            list(summary["controllers"]),
            delta_max_deg=nominal(spec.vehicle.delta_max_deg),
            convention=spec.vehicle.convention,
            note="" if spec.slip.kind == "constant" else " (constant part)",
            predicted=linearised_predictions(spec, summary),
        ),
        "success_by_param": lambda: success_by_param_figure(summary, colors),
    }
    done = []
    for name in FIGURES:
        if names is not None and name not in names:
            continue
        fig = build[name]()
        if fig is None:
            continue
        save(freeze_layout(fig), fig_dir, name)
        done.append(name)
    return figure_entries(out_dir, spec, done)


def warm_predictions(spec: StudySpec, gains: dict) -> None:
    """Compile the slip map's linearised predictions (:func:`linearised_predictions`) for the grid
    its figure evaluates (:data:`~pfjax.report.study_figures.PREDICTION_GRID` points per axis), so
    that the report finds them compiled: a study calls this alongside its runs. ``gains``: per
    controller, the summary's flat gains."""
    from pfjax.report.study_figures import PREDICTION_GRID

    grid = np.zeros(PREDICTION_GRID)
    for pred in linearised_predictions(spec, {"controllers": {n: {"gains": g} for n, g in gains.items()}}).values():
        pred(grid, grid)


def linearised_predictions(spec: StudySpec, summary: dict) -> dict:
    """For state-feedback controllers (registry ``state_feedback`` and its designs): success predicted on a straight line from
    the true equilibrium (exists, Hurwitz, |d*| <= success band), as functions of the slip grid in deg."""
    import jax.numpy as jnp

    from pfjax.analysis import stability_map
    from pfjax.controllers.designs import resolve
    from pfjax.models.slip import CONVENTIONS, SlipParams

    v = spec.vehicle
    params = SlipParams(
        nominal(v.speed), nominal(v.L), math.radians(nominal(v.delta_max_deg)), CONVENTIONS[v.convention]
    )
    out = {}
    types = {c.name: c.type for c in spec.controllers}
    for name, c in summary["controllers"].items():
        g = c.get("gains") or {}
        if name in types and resolve(types[name])[0].name == "state_feedback":
            K = jnp.asarray([g["k_d"], g["k_theta"]])

            def pred(xs, ys, K=K):
                eq, _ = stability_map(K, jnp.radians(jnp.asarray(xs)), jnp.radians(jnp.asarray(ys)), params)
                return np.asarray(eq.hurwitz) & (np.abs(np.asarray(eq.d)) <= spec.success.band)

            out[name] = pred
    return out


def report_figures(
    out_dir: Path,
    spec: StudySpec,
    summary: dict,
    runs: pd.DataFrame,
    worst_trajectories: dict | None = None,
    names=None,
) -> dict[str, dict]:
    """Render the report's figures into ``out_dir/figures`` (the slow part of :func:`write_report`;
    it needs the summary's statistics but not its float64 check). Pass the result to
    :func:`write_report` as ``figures``. ``names``: render only these (of :data:`FIGURES`; default
    all), so a study can draw the others before its worst-case search has finished; merge the parts
    with :func:`ordered_figures`. ``runs`` may be None when ``names`` has none of :data:`NEEDS_RUNS`."""
    cfg = summary.get("config") or spec.model_dump(mode="json")
    return draw_figures(
        Path(out_dir), spec, summary, runs, controller_colors(cfg["controllers"]), worst_trajectories, names
    )


def ordered_figures(*parts: dict) -> dict[str, dict]:
    """Merge :func:`report_figures` results into the report's order (:data:`FIGURES`)."""
    merged = {k: v for part in parts for k, v in part.items()}
    return {k: merged[k] for k in FIGURES if k in merged}
