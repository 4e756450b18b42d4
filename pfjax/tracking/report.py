"""Tracking study outputs: Parquet with the config stamp, figures (PNG + SVG) and the report
(:func:`report`, a :class:`pfjax.report.document.Document` written as ``report.md`` and ``report.html``).

Matplotlib is imported inside the functions (the library never selects a backend).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pfjax.report.document import Bullets, Document, Figure, Heading, Paragraph, Table
from pfjax.report.figures import save
from pfjax.reproduce.verdict import verdict_block
from pfjax.tracking.lemma import outcomes

OUTCOMES = ("both", "z_only", "phi_only", "neither", "failed")
LABELS = {
    "both": "z~→0 and φ−pγ→0",
    "z_only": "z~→0 only",
    "phi_only": "φ−pγ→0 only",
    "neither": "neither",
    "failed": "failed (status)",
}


def write_figures(fig_dir: Path, cfg: dict, lemma_df: pd.DataFrame, geo: pd.DataFrame, mc: pd.DataFrame) -> list[str]:
    import matplotlib.pyplot as plt

    fig_dir.mkdir(parents=True, exist_ok=True)
    names = []

    # 1. the four outcomes per mode and region
    tab = lemma_df.assign(**outcomes(lemma_df))
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    colors = ["#2a9d8f", "#e76f51", "#f4a261", "#8d99ae", "#264653"]
    for ax, mode in zip(axes, ("forward", "backward")):
        d = tab[tab["mode"] == mode]
        regions = sorted(d.region.unique())
        bottoms = np.zeros(len(regions))
        for o, c in zip(OUTCOMES, colors):
            vals = []
            for r in regions:
                x = d[d.region == r]
                vals.append(x[o].mean() if len(x) else 0.0)
            ax.bar(regions, vals, bottom=bottoms, color=c, label=LABELS[o])
            bottoms += np.array(vals)
        ax.set_title(f"{mode} tracking")
        ax.set_ylabel("fraction of grid runs")
    axes[1].legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    fig.suptitle("Lemma 8.1 by simulation: outcomes inside and outside |p| < π/(2γ_max)")
    fig.tight_layout()
    names.append(save(fig, fig_dir, "lemma_outcomes"))
    plt.close(fig)

    # 2. geometry: phi - p gamma on states with z~ = 0
    on = geo[geo.kind == "on_focus"]
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.scatter(np.degrees(on.p_gamma), np.degrees(on.phi_minus_pgamma), s=3, alpha=0.4, color="#264653")
    for x in (-90, 90):
        ax.axvline(x, color="#e76f51", lw=1, ls="--", label="|p γ| = 90°" if x > 0 else None)
    ax.legend(frameon=False, fontsize=8)
    ax.set_xlabel("p γ (deg)")
    ax.set_ylabel("φ − p γ at z~ = 0 (deg)")
    ax.set_title("Geometry: z~ = 0 forces φ = pγ only while |pγ| < 90°")
    fig.tight_layout()
    names.append(save(fig, fig_dir, "lemma_geometry"))
    plt.close(fig)

    # 3. Monte Carlo: final error by leader
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    for ax, mode in zip(axes, ("forward", "backward")):
        d = mc[mc["mode"] == mode]
        for lname, g in d.groupby("leader"):
            ax.step(*final_error_ecdf(g), where="post", label=lname)
        ax.axvline(cfg["sim"]["band"], color="k", lw=1, ls="--", label=f"success band ({cfg['sim']['band']:g} m)")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())  # the decades only: minor labels overlap on a short range
        ax.set_xlabel("max |z~| over the final window (m)")
        ax.set_title(f"{mode}: ECDF per leader motion")
    axes[0].set_ylabel("fraction of all runs (failed: never)")
    axes[1].legend(frameon=False, fontsize=8)
    fig.tight_layout()
    names.append(save(fig, fig_dir, "mc_final_error"))
    plt.close(fig)
    return names


def final_error_ecdf(runs: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    """The empirical distribution of ``window_max_z`` (m, floored at 1e-9 m for the log axis) over
    all of ``runs``: a run whose status is not ok never reaches any error, so the curve ends at the
    share of runs that finished."""
    x = np.sort(np.maximum(runs[runs.status == "ok"].window_max_z.to_numpy(), 1e-9))
    return x, np.arange(1, len(x) + 1) / len(runs)


def _pct(b: dict) -> str:
    lo, hi = b["success_ci95"]
    return f"{100 * b['success_rate']:.2f} % [{100 * lo:.2f}, {100 * hi:.2f}]"


def _frame_table(df: pd.DataFrame, caption: str = "") -> Table:
    return Table(list(df.columns), [list(r) for r in df.itertuples(index=False)], caption)


def _lemma_blocks(s: dict, tables: dict) -> list:
    lem, g = s["config"]["lemma"], s["geometry"]
    return [
        Heading(f"Lemma 8.1 by batched simulation ({s['lemma_grid']['n_runs']} runs)"),
        Paragraph(
            f"Grid: p ∈ {lem['p']}, |l| ∈ {lem['l_abs']} m (l = f|l|), γ_max ∈ {lem['gamma_max_deg']}°, "
            f"six leader motions, offsets {lem['offsets']} m, forward and backward. The lemma claims only the "
            "equivalence columns z_only = phi_only = 0 inside the bound."
        ),
        _frame_table(tables["lemma_table"]),
        Figure("lemma_outcomes", "Outcomes per mode inside and outside |p| < π/(2γ_max)."),
        Heading("Outside the bound, by γ_max and p (runs where exactly one limit holds)", 3),
        _frame_table(tables["outside"])
        if len(tables["outside"])
        else Paragraph("None: no finished run outside the bound has exactly one limit."),
        Heading("Lemma 8.1 as geometry"),
        Paragraph(
            f"{g['n_states_z_err_0']} random states with z~ = 0: max |φ − pγ| where |pγ| < π/2 is "
            f"{g['max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2']:.1e} rad; "
            f"{g['n_counterexamples_abs_pgamma_gt_pi_2']} states with |pγ| > π/2 have |φ − pγ| in "
            f"{g['counterexample_abs_phi_minus_pgamma_range']} rad (= π: the same connection line, the other half); "
            "such states exist only outside the bound, since the sampled |γ| ≤ γ_max. The converse needs the distance: "
            f"a leader on the focus direction at the wrong distance has φ = pγ and "
            f"|z~| ≥ {g['wrong_distance_min_z_err']:.3f} m."
        ),
        Figure("lemma_geometry", "φ − pγ on random states with z~ = 0."),
    ]


def _mc_blocks(s: dict) -> list:
    header = ["mode", "runs", "success [95 % CI]", "statuses", "final |z~| p50 / p95, runs ok (m)"]
    header += ["IAE p50 / p95, runs ok (m·s)", "max |γ| p95, runs ok (deg)"]
    rows, lead = [], []
    for mode, m in s["monte_carlo"].items():
        q = m["quantiles"]
        rows.append(
            [
                mode,
                m["n"],
                _pct(m),
                str(m["status_counts"]),
                f"{q['final_error_norm']['q50']:.2e} / {q['final_error_norm']['q95']:.2e}",
                f"{q['iae']['q50']:.3f} / {q['iae']['q95']:.3f}",
                f"{q['max_abs_gamma_deg']['q95']:.1f}",
            ]
        )
        lead += [[mode, ld, b["n"], _pct(b)] for ld, b in m["by_leader"].items()]
    return [
        Heading("Robustness Monte Carlo"),
        Table(header, rows),
        Heading("Success by leader motion", 3),
        Table(["mode", "leader", "runs", "success [95 % CI]"], lead),
        Figure("mc_final_error", "Max |z~| over the final window, ECDF per leader motion."),
    ]


def report(summary: dict, tables: dict[str, pd.DataFrame]) -> Document:
    """The study report from its summary and the tables ``lemma_table`` and ``outside`` (the
    runs outside the bound where exactly one limit holds); no number is computed here."""
    s = summary
    subtitle = (
        f"pfjax {s['pfjax_version']}, config SHA-256 {s['config_sha256'][:16]}…, seed {s['seed']}, "
        f"{s['machine']}, {s['wall_s']:.0f} s" + (" (quick sizes)" if s["quick"] else "")
    )
    blocks: list = [Heading("Definitions"), Bullets([f"**{k}**: {v}" for k, v in s["definitions"].items()])]
    blocks += [Heading("Verdicts on the source's claim"), verdict_block(s["verdicts"])]
    blocks += _lemma_blocks(s, tables) + _mc_blocks(s)
    return Document("Vehicle tracking with a focus point — Lemma 8.1 and robustness", subtitle, blocks)


__all__ = ["report", "write_figures"]
