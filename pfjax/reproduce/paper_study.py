"""The paper reproduction (``studies/paper_reproduction.py``): every part in order, the figures,
the tables and ``summary.json``, and the report (:mod:`pfjax.reproduce.paper_report`).

:func:`run` takes a validated :class:`~pfjax.reproduce.paper_config.PaperStudy`, an open
:class:`pfjax.outputs.OutputDir` and a progress bar (an ``update(n)`` method; :data:`N_STEPS` steps).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax.jsonio import dumps
from pfjax.provenance import parquet_metadata
from pfjax.provenance import stamp as provenance_stamp
from pfjax.report import document, figures
from pfjax.reproduce import path_following
from pfjax.reproduce.paper_analysis import part_ga_readings, part_long_pi, part_stability, sine_error_analysis
from pfjax.reproduce.paper_config import PaperStudy
from pfjax.reproduce.paper_report import report
from pfjax.reproduce.paper_runs import fixed_path, part_paper_runs, part_pi_readings, part_synthesis
from pfjax.sim.scenario import PAPER_TESTS
from pfjax.tables import write_parquet


def n_steps(config: PaperStudy) -> int:
    """The progress bar's total: the source tests per controller, the PI readings, the stability
    grid, the long PI run, the GA readings and the figures."""
    return 3 * (6 if config.trackers else 3) + 3 + 3


def _tracking_figures(figdir: Path, cfg: dict, trajs: dict) -> None:
    for test in PAPER_TESTS:
        p = fixed_path(test)
        uu = jnp.linspace(-3.0 if test != "line" else -1.0, 16.0, 2000)
        if test == "parabola":
            uu = jnp.linspace(-2.6, 4.0, 2000)
        px, py = p.point(uu)
        shown = {k: v for k, v in trajs[test].items() if k in ("mixed", "paper-k", "pi")}
        figures.save(
            figures.tracking_figure(
                f"{test} test (equivalent of the source's Figs. 6-17 for this path)",
                np.stack([np.asarray(px), np.asarray(py)], 1),
                shown,
                math.radians(cfg["model"]["delta_max_deg"]),
            ),
            figdir,
            f"tracking_{test}",
        )


def write_figures(figdir: Path, cfg: dict, trajs: dict, stab_df, grid, pi_df, line_traces, sine: dict) -> None:
    """``figures/``: the three source tests, the stability maps, the PI readings and the sine error."""
    _tracking_figures(figdir, cfg, trajs)
    grid, shape = grid
    figures.save(
        figures.stability_figure(
            grid,
            stab_df.source_max_re.to_numpy().reshape(shape),
            stab_df.eq_max_re.to_numpy().reshape(shape),
            stab_df.eq_exists.to_numpy().reshape(shape),
            stab_df.sim_converged.to_numpy().reshape(shape),
            cfg["model"]["delta_max_deg"],
        ),
        figdir,
        "stability_maps",
    )
    ok = dict(zip(pi_df.reading, pi_df.consistent))
    figures.save(figures.pi_assignment_figure(list(pi_df.reading), line_traces, ok), figdir, "pi_readings")
    figures.save(
        figures.sine_error_figure(sine["x"], sine["abs_d"], sine["kappa_x"], sine["kappa"], sine["dkappa_ds"], "mixed"),
        figdir,
        "sine_error",
    )


def _write_tables(tmp: Path, cfg: dict, stamp: dict, rows: list[dict], pi_df, stab_df) -> None:
    runs = pd.DataFrame(rows)
    runs.insert(0, "config_sha256", stamp["config_sha256"])
    meta = parquet_metadata(cfg, cfg["seed"])
    write_parquet(runs, tmp / "runs.parquet", meta)
    runs.to_csv(tmp / "runs.csv", index=False)
    pi_df.to_csv(tmp / "pi_readings.csv", index=False)
    write_parquet(stab_df, tmp / "stability.parquet", meta)


def run(config: PaperStudy, output, pbar) -> dict:
    """Run the study into ``output.staging``: ``summary.json``, ``runs.parquet``/``.csv``,
    ``pi_readings.csv``, ``stability.parquet``, ``figures/``, ``report.md`` and ``report.html``.
    Returns the summary (its ``verdicts`` as dicts)."""
    t0 = time.time()
    cfg = config.model_dump(mode="json")
    tmp = output.staging
    syn = part_synthesis(cfg)
    rows, trajs = part_paper_runs(cfg, syn["ours"]["K"], pbar)
    pi_df, line_traces = part_pi_readings(cfg, rows, pbar)
    stab_df, stab = part_stability(cfg, pbar)
    sine = sine_error_analysis(trajs)
    long_pi = part_long_pi(cfg)
    pbar.update(1)
    ga = part_ga_readings(cfg)
    pbar.update(1)
    verdict_rows = path_following.verdicts(cfg, rows, stab, pi_df, sine, long_pi, ga)
    write_figures(tmp / "figures", cfg, trajs, stab_df, stab.pop("grid"), pi_df, line_traces, sine)
    pbar.update(1)
    stamp = {**provenance_stamp(cfg, cfg["seed"]), "wall_s": time.time() - t0}
    _write_tables(tmp, cfg, stamp, rows, pi_df, stab_df)
    summary = {
        "study": cfg["name"],
        **stamp,
        "config": cfg,
        "synthesis": syn,
        "runs": rows,
        "pi_consistent_readings": list(pi_df[pi_df.consistent].reading),
        "pi_filters": pi_df.attrs["filters"],
        "stability": stab,
        "sine_error": {k: v for k, v in sine.items() if not isinstance(v, np.ndarray)},
        "pi_long_horizon": long_pi,
        "ga_crossover_readings": ga,
        "verdicts": [v._asdict() for v in verdict_rows],
    }
    (tmp / "summary.json").write_text(dumps(summary) + "\n")
    document.write(report(summary, {"pi_readings": pi_df}), tmp)
    return summary


__all__ = ["n_steps", "run", "write_figures"]
