"""Report of the tuning study (:mod:`pfjax.tuning.study`): the cost-against-budget figure and
:func:`report`, a :class:`pfjax.report.document.Document` (``report.md`` and ``report.html``) built
from the summary alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from pfjax.report.document import Code, Document, Figure, Heading, Paragraph, Table
from pfjax.report.study_format import fmt_gains
from pfjax.tuning.study_config import problem_list

#: Every problem's cost (an IAE, mean or CVaR over the problem's runs: :data:`pfjax.tuning.study.COLUMNS`).
COST_UNIT = "m·s"


def figures(hist: pd.DataFrame, problem: str, out: Path) -> list[str]:
    """Best cost so far against rollouts and wall time on ``problem``: median over seeds, band min-max."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pfjax.report.figures import save

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    colors = {"ga": "tab:blue", "gradient": "tab:red", "gradient-plain": "tab:gray", "ga+gradient": "tab:green"}
    h = hist[hist.problem == problem]
    for method, color in colors.items():
        g = h[h.method == method]
        if g.empty:
            continue
        by_it = g.groupby("iteration")
        x = by_it.rollouts.median()
        med, lo, hi = by_it.best_cost.median(), by_it.best_cost.min(), by_it.best_cost.max()
        axes[0].plot(x, med, color=color, label=f"{method} (median over seeds)")
        axes[0].fill_between(x, lo, hi, color=color, alpha=0.2, lw=0)
        axes[1].plot(by_it.wall_s.median(), med, color=color, label=method)
    for ax, xl in zip(axes, ("simulated rollouts", "wall time [s] (compilation excluded)")):
        ax.set_xscale("log")
        ax.set_xlabel(xl)
        ax.set_ylabel(f"best cost so far [{COST_UNIT}]")
        ax.grid(alpha=0.3)
        ax.legend()
    axes[0].set_title(f"{problem}: cost vs rollouts (band: min-max over seeds)")
    axes[1].set_title("cost vs wall time (median over seeds)")
    save(fig, out / "figures", "cost_vs_budget", tight=False)
    return ["figures/cost_vs_budget.png", "figures/cost_vs_budget.svg"]


def _method_tables(s: dict, main: str) -> list:
    """Every method on every problem (median, spread, wins, budget), then the ingredients (ablation
    variants) on each problem of ``compare.ablate_problems``."""
    t = s["targets"]
    per = []
    for name, row in t["by_problem"].items():
        for m in ("ga", "gradient", "gradient-plain"):
            g = row[m]
            per.append(
                [
                    name,
                    m,
                    f"{g['median']:.5f}",
                    f"{g['min']:.5f}",
                    f"{g['max']:.5f}",
                    f"{g['wins']}/{g['n']}",
                    f"{g['rollouts']} ({100 * g['rollout_fraction']:.1f} %)",
                    f"{g['forward_passes']} ({100 * g['forward_pass_fraction']:.1f} %)",
                    f"{g['wall_s_median']:.2f}",
                    "" if m == "ga" else "met" if g["met"] else "not met",
                ]
            )
    header = ["problem", "method", "median", "min", "max", "seeds ≤ GA median", "rollouts (% GA)"]
    header += ["forward passes (% GA)", "wall s (median)", "target"]
    blocks: list = [Table(header, per)]
    cfg = s["config"]["compare"]
    for name in problem_list(cfg["ablate_problems"]) if cfg["ablate"] else [main]:
        abl = []
        for m in sorted({r["method"] for r in s["tuning_runs"] if r["problem"] == name}):
            rs = [r for r in s["tuning_runs"] if r["problem"] == name and r["method"] == m]
            c = np.asarray([r["cost"] for r in rs])
            wins = int(np.sum(c <= t["by_problem"][name]["ga_median"]))
            abl.append(
                [m, f"{np.median(c):.5f}", f"{c.max():.5f}", f"{wins}/{len(c)}"]
                + [str(rs[0]["n_rollouts"]), str(rs[0]["n_forward_passes"])]
            )
        header = ["method", "median", "max", "seeds ≤ GA median", "rollouts", "forward passes"]
        blocks += [Heading(f"Ingredients on {name}", level=3), Table(header, abl)]
    return blocks


def _num(x, d: int = 4) -> str:
    return "n/a" if x is None else (f"{x:.{d}f}" if isinstance(x, float) else str(x))


def _heldout_cell(r: dict, c: str) -> str:
    if c == "success_rate":
        return f"{100 * r[c]:.1f} %"
    if c == "success_ci95":
        return f"[{100 * r[c][0]:.1f}, {100 * r[c][1]:.1f}]"
    if c == "slip_margin_deg":
        return "none (fails at 0°)" if r.get("margin_fails_at_smallest") else _num(r[c], 1)
    if c == "gains":
        return fmt_gains(r[c])
    return _num(r[c], 4) if isinstance(r[c], float) else str(r[c])


def _part1(s: dict) -> list:
    main = problem_list(s["config"]["compare"]["problems"])[0]
    cli, seeds = s["targets"]["cli"], s["config"]["seeds"]
    blocks = [
        Heading(f"1. GA vs gradient tuners over {seeds} seeds"),
        Paragraph(
            f"Costs in {COST_UNIT}. A seed wins when the tuner's cost is at most the GA's median cost over "
            f"the same seeds; the target is {s['targets']['wins_needed']} of {seeds} seeds with at most a "
            "tenth of the GA's rollouts."
        ),
        *_method_tables(s, main),
        Figure("cost_vs_budget", f"{main}: best cost so far against rollouts and wall time (band: min-max over seeds)"),
    ]
    if cli["gradient_costs"]:
        blocks.append(Paragraph(_cli_verdict(cli), style="verdict"))
    checks = "; ".join(
        f"{m}: {c['verdict']} (cost {c['cost']:.5f}, best probe {100 * c['probe_decrease']:.3f} % lower)"
        for m, c in s["checks"].items()
    )
    blocks.append(Paragraph(f"Local check of the best answer of each method on the first problem: {checks}."))
    return blocks


def _cli_verdict(cli: dict) -> str:
    """Part 1b's verdict, naming the settings it ran: the command line's defaults, or the study's
    settings that differ from them (``cli["changed"]``)."""
    problem = f"dt {cli['dt']} s, horizon {cli['horizon']:g} s"
    if cli["changed"]:
        changed = ", ".join(f"{k} = {v}" for k, v in cli["changed"].items())
        how = f"on the command line's problem ({problem}) with the study's settings where they differ from "
        how += f"its defaults ({changed})"
    else:
        how = f"at the command line's defaults ({problem})"
    return (
        f"`pfjax tune --method gradient` {how}, seeds 0-{len(cli['gradient_costs']) - 1}: costs "
        f"{np.round(cli['gradient_costs'], 5).tolist()} against the GA's best {cli['ga_best']:.5f} at the same "
        f"settings over the same seeds (relative: {np.round(cli['gradient_over_ga_best'], 4).tolist()}); "
        f"**within 0.5 %: {'met' if cli['met'] else 'not met'}**."
    )


def _heldout_text(h: dict) -> str:
    """What the held-out set is: runs per path, the paths, the study, its margin sweeps."""
    others = [a for a in h["margin_axes"] if a != h["margin_axis"]]
    also = f" (`margin.parquet` also holds the {', '.join(others)} sweep{'s' if len(others) > 1 else ''})"
    return (
        f"{h['n_per_path']} runs per path ({', '.join(h['paths'])}), `{h['study']}` (seed {h['seed']}), slip "
        f"margin from the {h['margin_axis']} sweep with {h['margin_runs']} runs per amplitude"
        f"{also if others else ''}."
    )


#: The held-out table's column headers (units).
HEADERS = {"iae_mean": f"iae_mean [{COST_UNIT}]"}


def _parts23(s: dict) -> list:
    t, t3, h = s["targets"], s["table3"], s["heldout"]
    cols = ["controller", "gains", "success_rate", "success_ci95", "iae_mean", "steady_abs_d_p95_mm", "slip_margin_deg"]
    steady = t["integral_steady_abs_d_m"]
    return [
        Heading("2. Are the Table 3 gains a local optimum of this cost?"),
        Paragraph(
            f"Table 3 (adopted reading) cost {t3['cost']:.5f}, gradient {np.round(t3['gradient'], 5).tolist()}, "
            f"check: {t3['check_verdict']}; {t3['descent_steps']} projected adam steps of {t3['descent_lr']:g} box "
            f"widths from there reach "
            f"{t3['descent_cost']:.5f} ({t3['relative_decrease']:.1%} lower) at {fmt_gains(t3['descent_gains'])}."
        ),
        Heading("3. Held-out Monte Carlo set"),
        Paragraph(_heldout_text(h)),
        Table([HEADERS.get(c, c) for c in cols], [[_heldout_cell(r, c) for c in cols] for r in h["table"]]),
        Paragraph(
            "**Target (robust designs beat the source's K and PI in held-out success and slip margin): "
            f"{t['robust_vs_source']}**",
            style="verdict",
        ),
        Paragraph(
            f"Integral design, steady |d| under constant slip on the line (3 slips, 30 s): max {1e3 * steady:.2e} mm "
            f"(target < 0.1 mm: {'met' if steady < 1e-4 else 'not met'})."
        ),
        Heading("4. LMI designs"),
        Code(json.dumps(s["designs"], indent=1)),
    ]


def report(summary: dict, tables: dict | None = None) -> Document:
    """The study's report from its summary (``tables`` are not needed: every number is in the summary)."""
    s = summary
    subtitle = (
        f"pfjax {s['pfjax_version']}, config sha256 `{s['config_sha256'][:16]}…`, {s['machine']}, "
        f"total {s['wall_s']:.0f} s."
    )
    return Document("Tuning study: GA vs gradient tuners, robust designs", subtitle, [*_part1(s), *_parts23(s)])


__all__ = ["figures", "report"]
