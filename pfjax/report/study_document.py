"""The Monte Carlo study report as a :class:`pfjax.report.document.Document`: which controller is
more robust and by how much, built from the study's summary and run table (every number formatted
from them, none recomputed) and written by :func:`pfjax.report.document.write` to ``report.md`` and
``report.html``.

Sections: verdict, set-up, headline per controller, per path, run status and worst sampled runs,
distributions, slip margins, robustness map, worst cases found and rare failures (when searched),
failure drivers, sample size, numerical precision, reproducibility.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pandas as pd

from pfjax.report import document as D
from pfjax.report import study_tables as T
from pfjax.report.study_format import cell, fmt_margin, fmt_num
from pfjax.report.study_setup import setup
from pfjax.report.study_verdict import verdict
from pfjax.tables import COLUMNS

__all__ = ["study_document"]

_DRIVERS_NOTE = (
    "Spearman rank correlation of each varied parameter with failure (ρ fail) and with IAE over the runs with status ok (ρ IAE); effect size: "
    "how many standard deviations the failed runs' mean sits above the successful runs'. abs_x is |x| (slip hurts "
    "in both directions). Dashes: undefined (no failure, or the parameter does not vary)."
)
_STATUS_NOTE = (
    "Every run is counted: a run succeeds only if it reaches the end of the horizon (status ok) inside the band. "
    "Failed runs are listed below and count as +∞ in the figures' distributions; the tables' IAE and steady |d| "
    "statistics are over the runs with status ok (a failed run's metrics stop at its failure)."
)
_HEADLINE_NOTE = (
    "Success counts every run. IAE and steady |d| are over the runs with status ok (a failed run's metrics stop at "
    "its failure; see Run status below)."
)
_REPRO_NOTE = (
    "Same config (hash) and seed give a bit-identical runs.parquet and margin.parquet, whatever the chunk size "
    "(batches are padded to a multiple of 32 runs so XLA's vector code treats every run alike); runs.parquet and "
    "margin.parquet carry the config, its hash, the seed and the pfjax version in their Parquet metadata. An "
    "interrupted study resumes from its finished chunks when the same command is run again. Rebuild this page "
    "with `pfjax report CONFIG --out DIR`."
)


def _figure(figures: Mapping, name: str) -> list[D.Block]:
    f = figures.get(name)
    return [D.Figure(name, f["caption"])] if f else []


def _left(*values) -> list[D.Cell]:
    return [cell(v, cls="left") for v in values]


def _verdict_blocks(summary: dict, runs: pd.DataFrame, figures: Mapping) -> list[D.Block]:
    best, lines, rows = verdict(summary, runs)
    out: list[D.Block] = [D.Heading("Verdict", anchor="verdict"), D.Paragraph("\n\n".join(lines), style="verdict")]
    if rows:
        head = ["controller", f"success rate − {best}’s", "95 % CI (paired)"]
        head += [f"runs only {best} / only this one succeeded", "McNemar p", f"mean IAE ÷ {best}’s"]
        cap = f"Each controller against the most robust one, {best}, on the same scenarios (pp: percentage points)"
        out.append(D.Table(head, rows, cap))
    return out + _figure(figures, "headline")


def _setup_blocks(cfg: dict, summary: dict, colors: dict) -> list[D.Block]:
    s = setup(cfg, summary)
    paths = [_left(p["name"], p["kind"], p["detail"]) for p in s["paths"]]
    ctrls = [
        [cell(c["name"], cls="left", swatch=colors[c["name"]]), *_left(c["how"], c["gains"])] for c in s["controllers"]
    ]
    quantities = [_left(f"**{u['name']}**" if u["varies"] else u["name"], u["dist"]) for u in s["uncertain"]]
    runs_line = (
        f"{s['n_runs']} per controller and path ({summary['n_runs_total']} in all); seed {s['seed']}; "
        f"{s['dtype']}; chunks of {s['chunk_size']}"
    )
    study = [
        _left("runs", runs_line),
        _left("simulation", s["sim"]),
        _left("success criterion", s["success"]),
        _left("slip-margin sweep", s["margin"]),
    ]
    out: list[D.Block] = [
        D.Heading("Set-up", anchor="setup"),
        D.Table(["path", "kind", "geometry"], paths, "Paths"),
        D.Table(["controller", "design", "gains"], ctrls, "Controllers"),
        D.Table(["quantity", "distribution"], quantities, "Uncertain quantities (per run)"),
        D.Paragraph(
            "Bold: sampled per run; every controller sees the same sampled scenarios (common random numbers).",
            style="note",
        ),
        D.Table(["study", ""], study),
    ]
    warnings = summary.get("warnings") or []
    if warnings:
        out += [D.Paragraph("**Warnings** (the study ran; these runs are likely to fail):", style="warning")]
        out += [D.Bullets(warnings)]
    return out


def _headline_blocks(summary: dict, colors: dict, axes: list[str]) -> list[D.Block]:
    ctrl = summary["controllers"]
    head = ["controller", "successes / runs", "success rate", "95 % CI (Clopper-Pearson)", "IAE mean [m·s]"]
    head += ["IAE p95 [m·s]", "steady |d| p95 [mm]"] + [f"slip margin, {x} [lo, hi]" for x in axes]
    per_path = ["controller", "path", "successes / runs", "success rate", "95 % CI", "IAE mean [m·s]"]
    per_path += ["IAE p95 [m·s]", "steady |d| p95 [mm]", "status counts"]
    return [
        D.Heading("Headline per controller", anchor="headline"),
        D.Table(head, T.headline_rows(summary, colors, axes)),
        D.Paragraph(_HEADLINE_NOTE, style="note"),
        D.Heading("What the sample supports (95 % confidence)", level=3),
        D.Bullets([f"**{n}**: {c['statement']['text']}" for n, c in ctrl.items()], [colors[n] for n in ctrl]),
        D.Heading("Per path", anchor="paths"),
        D.Table(per_path, T.per_path_rows(summary, colors)),
    ]


def _status_blocks(runs: pd.DataFrame, colors: dict, params: Sequence[str]) -> list[D.Block]:
    head, rows = T.status_table(runs, colors)
    worst_head = ["path", "run", "status", "fail time [s]", "late max |d| [mm]", "IAE [m·s]", "success", *params]
    out: list[D.Block] = [
        D.Heading("Run status", anchor="status"),
        D.Paragraph(_STATUS_NOTE, style="note"),
        D.Table(head, rows),
        D.Heading("Worst sampled runs", level=3),
        D.Paragraph(
            "Per controller: failures first (earliest first), then the largest max |d| in the success window.",
            style="note",
        ),
    ]
    return out + [D.Table(worst_head, r, n) for n, r in T.worst_runs(runs, list(params)).items()]


def _margin_blocks(summary: dict, colors: dict, figures: Mapping) -> list[D.Block]:
    out: list[D.Block] = [D.Heading("Slip margins", anchor="margins")]
    if "margin_curves" not in figures:
        return out + [D.Paragraph("No slip-margin sweep in this study (`margin.enabled = false`).")]
    rows = [
        [cell(n, swatch=colors[n]), cell(x), cell(fmt_margin(m)), cell(fmt_num(m["resolution"]))]
        for n, c in summary["controllers"].items()
        for x, m in c.get("slip_margin", {}).items()
    ]
    level = round((1 - summary["config"]["margin"]["eps"]) * 100, 2)
    cap = (
        f"Margin at success ≥ {level} %: point estimate, and with the Clopper-Pearson lower / upper bounds; "
        "≥: every amplitude tested passed"
    )
    head = ["controller", "axis", "margin [lo, hi]", "grid resolution [deg]"]
    return out + _figure(figures, "margin_curves") + [D.Table(head, rows, cap)]


def _search_blocks(summary: dict, colors: dict, figures: Mapping) -> list[D.Block]:
    out: list[D.Block] = []
    wc = T.worst_case_rows(summary, colors)
    if wc:
        head = ["controller", "path", "objective", "falsifier (status)", "random search (status)", "ratio"]
        head += ["rollouts each", "worst scenario"]
        shown = _figure(figures, "worst_cases") or [
            D.Paragraph(
                "No figure of the worst runs: it is drawn from the search's trajectories when the study "
                "runs with its report, and `pfjax report` cannot redraw it (re-run the study to have it).",
                style="note",
            )
        ]
        out += [D.Heading("Worst cases found", anchor="worst"), D.Table(head, wc), *shown]
    rare = T.rare_event_rows(summary, colors)
    if rare:
        head = ["controller", "P(fail) [95 % interval]", "rel. error", "rollouts (method)"]
        head += [
            "plain failure rate of the runs [95 %]",
            "failure modes (mean failure inputs): path, weight, inputs far from their medians (σ of u)",
        ]
        rare_cfg = summary["config"]["rare_event"]
        from pfjax.rare.study import failure_threshold

        threshold = failure_threshold(rare_cfg, summary["config"]["success"]["band"])
        note = (
            "P(fail) from pfjax.rare over the study's uncertain inputs (importance sampling, subset simulation or "
            f"plain Monte Carlo): a run fails if its status is not ok or its {rare_cfg['metric']} passes "
            f"{threshold:g} ({COLUMNS.get(rare_cfg['metric'], ('', ''))[0]}). The plain rate is the share of the "
            "study's own runs that fail by the same event, with its Clopper-Pearson interval (not the "
            "success band's failures of the headline)."
        )
        out += [D.Heading("Rare failures", anchor="rare"), D.Table(head, rare), D.Paragraph(note, style="note")]
    return out


def _driver_blocks(summary: dict, figures: Mapping) -> list[D.Block]:
    out: list[D.Block] = [D.Heading("Failure drivers", anchor="drivers"), *_figure(figures, "success_by_param")]
    out.append(D.Paragraph(_DRIVERS_NOTE, style="note"))
    for n, rows in T.drivers(summary).items():
        if rows:
            out.append(D.Table(["parameter", "ρ fail", "p", "ρ IAE", "p", "effect size"], rows, n))
        else:
            out.append(D.Paragraph(f"**{n}**: no varied parameter to rank."))
    return out


def _sample_blocks(summary: dict) -> list[D.Block]:
    ss = summary.get("sample_size", {})
    n_runs, n_ctrl = summary["config"]["n_runs"], len(summary["controllers"])
    note = (
        f"{ss.get('note', '')}. This study has {n_runs} runs per controller and path, "
        f"{summary['n_runs_total'] // n_ctrl} per controller."
    )
    rows = [[k, v["hoeffding"], v["zero_failure"]] for k, v in ss.items() if k != "note"]
    head = ["tolerance ε", "Hoeffding: ln(2/δ)/(2ε²)", "zero failures: ln(1/δ)/ln(1/(1−ε))"]
    return [D.Heading("Sample size", anchor="sample"), D.Paragraph(note, style="note"), D.Table(head, rows)]


def _precision_blocks(summary: dict, colors: dict) -> list[D.Block]:
    chk = summary.get("float64_check") or {}
    rows = T.precision_rows(summary, colors)
    out: list[D.Block] = [D.Heading("Numerical precision", anchor="precision")]
    if not rows:
        return out + [D.Paragraph(f"No float32-vs-float64 check: {chk.get('reason', 'not run')}.", style="note")]
    note = (
        f"{chk['n_per_controller']} runs per controller (spread over the paths) re-simulated in float64 from the same "
        "sampled scenarios and gains and compared with the study's float32 rows."
    )
    if chk.get("noise_realisation_differs"):
        note += (
            " Measurement noise is drawn at the run's precision, so the float64 runs see a different noise realisation."
        )
    head = ["controller", "runs", "max |ΔIAE| [m·s]", "max relative ΔIAE", "max |Δ late max |d|| [m]"]
    head += ["same status", "same success", "status changes"]
    return out + [D.Paragraph(note, style="note"), D.Table(head, rows)]


def _repro_blocks(summary: dict) -> list[D.Block]:
    n_sweep, chunks = summary.get("n_margin_runs", 0), summary.get("chunks") or {}
    runs = f"{summary['n_runs_total']} study runs" + (f", {n_sweep} slip-margin runs" if n_sweep else "")
    rows = [
        _left("pfjax version", summary["pfjax_version"]),
        _left("config SHA-256", f"`{summary['config_sha256']}`"),
        _left("seed", summary["seed"]),
        _left("dtype", summary["dtype"]),
        _left("machine", summary["machine"]),
        _left(
            "wall time",
            f"{fmt_num(summary.get('wall_s'), 4)} s (runs, sweep, summary, side jobs and figures; writing this report out not included)",
        ),
        _left("runs", runs),
    ]
    if chunks:
        resumed = f", {chunks['resumed']} resumed from an interrupted run" if chunks.get("resumed") else ""
        rows.append(_left("chunks", f"{chunks['simulated']} simulated{resumed}"))
    return [
        D.Heading("Reproducibility", anchor="repro"),
        D.Table(["", ""], rows),
        D.Paragraph(_REPRO_NOTE, style="note"),
    ]


def study_document(
    summary: dict, runs: pd.DataFrame, figures: Mapping, params: Sequence[str], colors: dict
) -> D.Document:
    """The Monte Carlo study's report.

    Args:
        summary: the study summary (:func:`pfjax.montecarlo.summary.summarize`), with its ``config``.
        runs: one row per run (``runs.parquet``).
        figures: ``{name: {"name", "caption", ...}}`` of the figures written to ``figures/``
            (:func:`pfjax.report.figure_set.report_figures`); figures not there are left out.
        params: the sampled run-table columns shown beside the worst runs.
        colors: one colour per controller (:func:`pfjax.report.study_figures.controller_colors`).
    """
    cfg, ctrl = summary["config"], summary["controllers"]
    axes = [x for x in ("rear", "front", "joint") if any(x in c.get("slip_margin", {}) for c in ctrl.values())]
    n_sweep = summary.get("n_margin_runs", 0)
    subtitle = (
        f"{summary['n_runs_total']} simulated runs ({cfg['n_runs']} per controller and path, "
        f"{len(summary['paths'])} path(s), {len(ctrl)} controller(s))"
        + (f" + {n_sweep} slip-margin runs" if n_sweep else "")
        + f". pfjax {summary['pfjax_version']}, config `{summary['config_sha256'][:12]}`, seed {summary['seed']}."
    )
    no_map = "The slip angles are not varied in this study, so there is no map over (β_r, β_f)."
    blocks = [
        *_verdict_blocks(summary, runs, figures),
        *_setup_blocks(cfg, summary, colors),
        *_headline_blocks(summary, colors, axes),
        *_status_blocks(runs, colors, params),
        D.Heading("Distributions", anchor="distributions"),
        *_figure(figures, "dist_iae"),
        *_figure(figures, "dist_late_max_abs_d"),
        *_margin_blocks(summary, colors, figures),
        D.Heading("Robustness map (from simulation)", anchor="map"),
        *(_figure(figures, "slip_map") or [D.Paragraph(no_map)]),
        *_search_blocks(summary, colors, figures),
        *_driver_blocks(summary, figures),
        *_sample_blocks(summary),
        *_precision_blocks(summary, colors),
        *_repro_blocks(summary),
    ]
    return D.Document(f"Robustness study “{summary['study']}”", subtitle, blocks)
