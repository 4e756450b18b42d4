"""Tracking study outputs: Parquet with the config stamp, figures (PNG + SVG) and ``report.html``.

Matplotlib is imported inside the functions (the library never selects a backend); the page is one
self-contained HTML file (Jinja2, figures embedded as base64 PNG).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pandas as pd
from jinja2 import Environment, StrictUndefined

from pfjax.report.figures import save
from pfjax.tracking.lemma import four_way, outcomes

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
        ax.axvline(x, color="#e76f51", lw=1, ls="--")
    ax.set_xlabel("p γ (deg)")
    ax.set_ylabel("φ − p γ at z~ = 0 (deg)")
    ax.set_title("Geometry: z~ = 0 forces φ = pγ only while |pγ| < 90°")
    fig.tight_layout()
    names.append(save(fig, fig_dir, "lemma_geometry"))
    plt.close(fig)

    # 3. Monte Carlo: final error by leader
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    for ax, mode in zip(axes, ("forward", "backward")):
        d = mc[(mc["mode"] == mode) & (mc.status == "ok")]
        for lname, g in d.groupby("leader"):
            x = np.sort(np.maximum(g.window_max_z.to_numpy(), 1e-9))
            ax.step(x, np.arange(1, len(x) + 1) / len(x), where="post", label=lname)
        ax.axvline(cfg["sim"]["band"], color="k", lw=1, ls="--")
        ax.set_xscale("log")
        ax.set_xlabel("max |z~| over the final window (m)")
        ax.set_title(f"{mode}: ECDF per leader motion")
    axes[0].set_ylabel("fraction of runs")
    axes[1].legend(frameon=False, fontsize=8)
    fig.tight_layout()
    names.append(save(fig, fig_dir, "mc_final_error"))
    plt.close(fig)
    return names


TEMPLATE = """<!doctype html><html><head><meta charset="utf-8"><title>{{ s.study }}</title>
<style>body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f2f2f2}td:first-child,th:first-child{text-align:left}img{max-width:100%}code{background:#f5f5f5}</style>
</head><body>
<h1>Vehicle tracking with a focus point — Lemma 8.1 and robustness</h1>
<p>pfjax {{ s.pfjax_version }}, config SHA-256 <code>{{ s.config_sha256[:16] }}…</code>, seed {{ s.seed }},
{{ s.machine }}, {{ '%.0f' % s.wall_s }} s{% if s.quick %} (<b>quick</b> sizes){% endif %}.</p>
<h2>Definitions</h2><ul>{% for k, v in s.definitions.items() %}<li><b>{{ k }}</b>: {{ v }}</li>{% endfor %}</ul>
<h2>Lemma 8.1 by batched simulation ({{ s.lemma_grid.n_runs }} runs)</h2>
<p>Grid: p ∈ {{ s.config.lemma.p }}, |l| ∈ {{ s.config.lemma.l_abs }} m (l = f|l|), γ_max ∈ {{ s.config.lemma.gamma_max_deg }}°,
six leader motions, offsets {{ s.config.lemma.offsets }} m, forward and backward. The lemma claims only the
"equivalence" columns z_only = phi_only = 0 inside the bound.</p>
<table><tr>{% for c in cols %}<th>{{ c }}</th>{% endfor %}</tr>
{% for r in rows %}<tr>{% for c in cols %}<td>{{ r[c] }}</td>{% endfor %}</tr>{% endfor %}</table>
<img src="data:image/png;base64,{{ figs['lemma_outcomes'] }}">
<h3>Outside the bound, by γ_max and p (runs where exactly one limit holds)</h3>
<table><tr>{% for c in out_cols %}<th>{{ c }}</th>{% endfor %}</tr>
{% for r in out_rows %}<tr>{% for c in out_cols %}<td>{{ r[c] }}</td>{% endfor %}</tr>{% endfor %}</table>
<h2>Lemma 8.1 as geometry</h2>
<p>{{ s.geometry.n_states_z_err_0 }} random states with z~ = 0: max |φ − pγ| where |pγ| &lt; π/2 is
{{ '%.1e' % s.geometry.max_abs_phi_minus_pgamma_when_abs_pgamma_lt_pi_2 }} rad;
{{ s.geometry.n_counterexamples_abs_pgamma_gt_pi_2 }} states with |pγ| &gt; π/2 have |φ − pγ| in
{{ s.geometry.counterexample_abs_phi_minus_pgamma_range }} rad (= π: the same connection line, the other half), all
outside the bound: {{ s.geometry.counterexamples_only_outside_bound }}. The converse needs the distance:
a leader on the focus direction at the wrong distance has φ = pγ and |z~| ≥ {{ '%.3f' % s.geometry.wrong_distance_min_z_err }} m.</p>
<img src="data:image/png;base64,{{ figs['lemma_geometry'] }}">
<h2>Robustness Monte Carlo</h2>
<table><tr><th>mode</th><th>runs</th><th>success [95 % CI]</th><th>statuses</th><th>final |z~| p50 / p95 (m)</th><th>IAE p50 / p95 (m·s)</th><th>max |γ| p95 (deg)</th></tr>
{% for mode, m in s.monte_carlo.items() %}<tr><td>{{ mode }}</td><td>{{ m.n }}</td>
<td>{{ '%.2f' % (100*m.success_rate) }} % [{{ '%.2f' % (100*m.success_ci95[0]) }}, {{ '%.2f' % (100*m.success_ci95[1]) }}]</td>
<td>{{ m.status_counts }}</td>
<td>{{ '%.2e' % m.quantiles.final_error_norm.q50 }} / {{ '%.2e' % m.quantiles.final_error_norm.q95 }}</td>
<td>{{ '%.3f' % m.quantiles.iae.q50 }} / {{ '%.3f' % m.quantiles.iae.q95 }}</td>
<td>{{ '%.1f' % m.quantiles.max_abs_gamma_deg.q95 }}</td></tr>{% endfor %}</table>
<h3>Success by leader motion</h3><table><tr><th>mode</th><th>leader</th><th>runs</th><th>success [95 % CI]</th></tr>
{% for mode, m in s.monte_carlo.items() %}{% for ld, b in m.by_leader.items() %}<tr><td>{{ mode }}</td><td>{{ ld }}</td><td>{{ b.n }}</td>
<td>{{ '%.2f' % (100*b.success_rate) }} % [{{ '%.2f' % (100*b.success_ci95[0]) }}, {{ '%.2f' % (100*b.success_ci95[1]) }}]</td></tr>{% endfor %}{% endfor %}</table>
<img src="data:image/png;base64,{{ figs['mc_final_error'] }}">
</body></html>"""


def write_report(out_dir: Path, summary: dict, table: pd.DataFrame, lemma_df: pd.DataFrame) -> Path:
    figs = {
        n: base64.b64encode((out_dir / "figures" / f"{n}.png").read_bytes()).decode()
        for n in ("lemma_outcomes", "lemma_geometry", "mc_final_error")
    }
    outside = lemma_df[~lemma_df.inside_bound & (lemma_df.status == "ok")]
    out_tab = four_way(outside, ["mode", "gamma_max_deg", "p"])[
        ["mode", "gamma_max_deg", "p", "n", "z_only", "phi_only"]
    ]
    out_tab = out_tab.rename(columns={"n": "n_ok"})[(out_tab.z_only + out_tab.phi_only) > 0]
    s = json.loads(json.dumps(summary, default=lambda o: None))
    html = (
        Environment(undefined=StrictUndefined, autoescape=True)
        .from_string(TEMPLATE)
        .render(
            s=_ns(s),
            cols=list(table.columns),
            rows=table.to_dict(orient="records"),
            figs=figs,
            out_cols=list(out_tab.columns),
            out_rows=out_tab.to_dict(orient="records"),
        )
    )
    path = out_dir / "report.html"
    path.write_text(html)
    return path


class _ns(dict):
    """dict with attribute access for the template (``s.geometry.x``)."""

    def __init__(self, d):
        super().__init__({k: _ns(v) if isinstance(v, dict) else v for k, v in d.items()})

    def __getattr__(self, k):
        try:
            return self[k]
        except KeyError:
            raise AttributeError(k) from None


__all__ = ["write_figures", "write_report"]
