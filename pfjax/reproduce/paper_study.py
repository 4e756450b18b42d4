"""The paper reproduction (``studies/paper_reproduction.py``): every part in order, the figures,
the tables and ``summary.json``, and the report (:mod:`pfjax.reproduce.paper_report`).

:func:`run` takes a validated :class:`~pfjax.reproduce.paper_config.PaperStudy`, an open
:class:`pfjax.outputs.OutputDir` and a progress bar (an ``update(n)`` method; :data:`N_STEPS` steps).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax import controllers as C
from pfjax.background import Background, last_device
from pfjax.controllers.linear import PI_GAIN_NAMES
from pfjax.jsonio import dumps
from pfjax.provenance import STAMP_UNITS, parquet_metadata
from pfjax.provenance import stamp as provenance_stamp
from pfjax.report import document, figures
from pfjax.reproduce import path_following
from pfjax.reproduce.paper_analysis import part_ga_readings, part_long_pi, part_stability, sine_error_analysis
from pfjax.reproduce.paper_config import PaperStudy, check
from pfjax.reproduce.paper_report import report
from pfjax.reproduce.paper_runs import part_paper_runs, part_pi_readings, part_synthesis, source_test
from pfjax.sim.scenario import PAPER_TESTS
from pfjax.tables import COLUMNS, H2_CHANNELS, HINF_CHANNELS, write_parquet


def _gain(controller: str, name: str, text: str) -> tuple[str, str]:
    """A gain column's ``(unit, description)``, its unit the controller's (:func:`pfjax.controllers.gain_units`)."""
    return C.gain_units(C.entry(controller))[name], text


#: Units of the study's own Parquet columns (beside :data:`pfjax.tables.COLUMNS`): column -> (unit,
#: description). Angles in rad unless named ``_deg``; the trackers' gains carry the controller's name.
UNITS: dict[str, tuple[str, str]] = {
    # runs.parquet: the gains of each row's controller (NaN for another controller's)
    "gain_k_d": _gain("state_feedback", "k_d", "state feedback: gain on d (delta = k_d d + k_theta theta_e)"),
    "gain_k_theta": _gain("state_feedback", "k_theta", "state feedback: gain on theta_e"),
    "gain_kp_d": _gain("pi", "kp_d", "PI: proportional gain on d"),
    "gain_ki_d": _gain("pi", "ki_d", "PI: integral gain on d"),
    "gain_kp_theta": _gain("pi", "kp_theta", "PI: proportional gain on theta_e"),
    "gain_ki_theta": _gain("pi", "ki_theta", "PI: integral gain on theta_e"),
    "gain_stanley_k": _gain("stanley", "k", "Stanley: cross-track gain"),
    "gain_stanley_k_soft": _gain("stanley", "k_soft", "Stanley: softening speed"),
    "gain_pure_pursuit_ld_gain": _gain("pure_pursuit", "ld_gain", "pure pursuit: look-ahead time"),
    "gain_pure_pursuit_ld_min": _gain("pure_pursuit", "ld_min", "pure pursuit: minimum look-ahead distance"),
    "gain_rear_wheel_k_theta": _gain("rear_wheel", "k_theta", "rear-wheel feedback: gain on theta_e"),
    "gain_rear_wheel_k_d": _gain("rear_wheel", "k_d", "rear-wheel feedback: gain on d"),
    "final_d": ("m", "lateral error at the end of the run, left positive"),
    "final_theta_e": ("rad", "heading error at the end of the run"),
    "final_delta": ("rad", "applied steering at the end of the run"),
    "max_abs_delta_cmd": ("rad", "largest commanded steering |delta_cmd| (before saturation)"),
    "max_abs_delta": ("rad", "largest applied steering |delta| (after saturation)"),
    "delta_max": ("rad", "steering limit"),
    # stability.parquet: one row per (beta_r, beta_f) of the grid, with the source's K
    "source_max_re": ("1/s", "largest real part of the source's linearisation at [0, -beta_r]"),
    "eq_exists": ("", "the true equilibrium exists (|delta*| <= delta_max: the boundary included)"),
    "eq_d": ("m", "true equilibrium: lateral error d*"),
    "eq_theta_e": ("rad", "true equilibrium: heading error theta_e*"),
    "eq_delta": ("rad", "true equilibrium: steering delta*"),
    "eq_max_re": ("1/s", "largest real part of the eigenvalues at the true equilibrium"),
    "eq_hurwitz": (
        "",
        "the true equilibrium is locally stable: |delta*| < delta_max and both eigenvalues' real parts < 0",
    ),
    "sim_status": ("", "run status name of the simulated line test"),
    "sim_final_d": ("m", "lateral error at the end of the simulated line test"),
    "sim_converged": ("", "the simulation ends at the predicted equilibrium (within stability.tol_d, tol_theta_deg)"),
}

#: The PI's gains (:func:`pfjax.controllers.pi_params`), as the ``gain_*`` columns give them.
_PI_GAINS = ", ".join(f"{n} {C.gain_units(C.entry('pi'))[n]}" for n in PI_GAIN_NAMES)
#: ``summary.json``'s own units, by field name (a field has one meaning wherever it occurs; "1":
#: dimensionless); :func:`summary_units` adds the run table's and the stability table's.
SUMMARY_UNITS: dict[str, str] = {
    **STAMP_UNITS,
    "seed": "1 (recorded; the study is deterministic)",
    "wall_s": "s",
    # synthesis
    "K": "rad/m, rad/rad (K_d, K_theta: delta = K_d d + K_theta theta_e)",
    "alpha": "1 (weight of gamma_inf^2)",
    "beta": "1 (weight of gamma_2^2)",
    **dict.fromkeys(("gamma_inf", "gamma_inf_certified"), f"H-infinity bound {HINF_CHANNELS}"),
    "hinf_norm": f"H-infinity norm {HINF_CHANNELS}",
    **dict.fromkeys(("gamma_2", "gamma_2_certified"), f"H2 bound {H2_CHANNELS}"),
    "h2_norm": f"H2 norm {H2_CHANNELS}",
    "objective": "1 (alpha gamma_inf^2 + beta gamma_2^2)",
    "closed_loop_poles": "1/s ([real, imaginary] per pole)",
    "rel_diff": "1 (|pfjax's - source's| / |source's|)",
    "success": "1 (1: no failure and within the success band, 0: not)",
    # the PI readings' filters
    **dict.fromkeys(("passing", "consistent"), "readings (of the 24 of Table 3)"),
    **dict.fromkeys(("sensitivity_cases", "sensitivity_unique"), "threshold cases (one threshold halved or doubled)"),
    "thresholds": "sat 1 (fraction of a run), delta_deg deg, ss_factor 1",
    # the stability grid
    "grid_deg": "deg, deg, points (first and last value of each axis, points per axis)",
    **dict.fromkeys(
        (
            "source_hurwitz_fraction",
            "equilibrium_exists_fraction",
            "sim_converged_fraction",
            "sim_agrees_with_analysis_fraction",
        ),
        "1 (fraction of the grid)",
    ),
    "hurwitz_where_exists_fraction": "1 (fraction of the grid points where the equilibrium exists)",
    "hurwitz_fraction": "1 (fraction of the eigenvalue scan)",
    "d_star": "m",
    "theta_e_star": "rad",
    "delta_star": "rad",
    "eig": "1/s ([real, imaginary] per eigenvalue)",
    "grid_max_deg": "deg",
    "n": "points per axis (of the eigenvalue scan)",
    **dict.fromkeys(("max_re_slow", "max_re_fast", "source_max_re_slow", "source_max_re_fast"), "1/s"),
    **dict.fromkeys(("max_re_slow_at", "max_re_fast_at"), "deg (beta_r, beta_f)"),
    # the sine test's error against the curvature
    "peak_x": "m (x of each |d| peak after the transient)",
    **dict.fromkeys(("median_peak_to_kappa_max_m", "median_peak_to_dkappa_max_m"), "m (along x)"),
    # the PI's long line run
    **dict.fromkeys(("horizon_s", "settle_time_s"), "s"),
    **dict.fromkeys(("steady_abs_d_mm", "final_d_mm"), "mm"),
    # Table 2's GA readings
    "crossover_fraction": "1",
    **dict.fromkeys(
        ("costs", "median_cost"),
        "the tuning cost's unit, mean over the scenario set: m s for IAE (the default), m^2 s for ISE, m s^2 for ITAE (ga.cost)",
    ),
    **dict.fromkeys(("best_gains", "seed_gains"), _PI_GAINS),
    "n_rollouts": "rollouts (simulated runs)",
}


def summary_units() -> dict[str, str]:
    """``summary.json``'s ``units``: the run table's columns (:data:`pfjax.tables.COLUMNS` and
    :data:`UNITS`, those with a unit), then :data:`SUMMARY_UNITS`."""
    columns = {**COLUMNS, **UNITS}
    return {**{k: u for k, (u, _) in columns.items() if u}, **SUMMARY_UNITS}


def n_steps(config: PaperStudy) -> int:
    """The progress bar's total: the source tests per controller, the PI readings, the stability
    grid, the long PI run, the GA readings and the figures."""
    return 3 * (6 if config.trackers else 3) + 3 + 3


#: The stretch of each source test's path its figure draws, x in m (towards increasing x).
DRAWN = {"line": (-1.0, 16.0), "parabola": (-2.6, 4.0), "sine": (-3.0, 16.0)}


def _tracking_figures(figdir: Path, cfg: dict, trajs: dict) -> None:
    for test in PAPER_TESTS:
        st = source_test(test, cfg["model"]["direction"])
        lo, hi = DRAWN[test]
        if st.u0 is not None:  # decreasing_x: the same stretch reflected about the start's closest point
            lo, hi = 2 * st.u0 - hi, 2 * st.u0 - lo
        px, py = st.path.point(jnp.linspace(lo, hi, 2000))
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
    write_parquet(runs, tmp / "runs.parquet", meta, units=UNITS)
    runs.to_csv(tmp / "runs.csv", index=False)
    pi_df.assign(config_sha256=stamp["config_sha256"])[["config_sha256", *pi_df.columns]].to_csv(
        tmp / "pi_readings.csv", index=False
    )
    write_parquet(stab_df, tmp / "stability.parquet", meta, units=UNITS)


def run(config: PaperStudy, output, pbar) -> dict:
    """Run the study into ``output.staging``: ``summary.json``, ``runs.parquet``/``.csv``,
    ``pi_readings.csv``, ``stability.parquet``, ``figures/``, ``report.md`` and ``report.html``.
    Returns the summary (its ``verdicts`` as dicts). ``config`` is checked first as
    :func:`pfjax.reproduce.paper_config.load` checks a file (:func:`~pfjax.reproduce.paper_config.check`).
    The study runs in float64 whether or not the caller enabled it (as its script does): the
    eigenvalue scan and the reference comparisons need it (in float32 the slower eigenvalue's
    maximum at the square's edge rounds to 0)."""
    check(config)
    with jax.enable_x64(True):
        return _run(config, output, pbar)


def _run(config: PaperStudy, output, pbar) -> dict:
    t0 = time.time()
    cfg = config.model_dump(mode="json")
    tmp = output.staging
    # Table 2's GA readings depend on nothing else here and run on one device, one generation at a
    # time: a background thread computes them on the last device while this thread simulates the
    # rest on all of them (or computes them itself, if it gets there first).
    thread = Background("pfjax-paper")
    device = last_device()

    def ga_readings():
        with jax.enable_x64(True), jax.default_device(device):
            return part_ga_readings(cfg)

    try:
        ga_job = thread.submit(ga_readings)
        syn = part_synthesis(cfg)
        rows, trajs = part_paper_runs(cfg, syn["ours"]["K"], pbar)
        pi_df, line_traces = part_pi_readings(cfg, rows, pbar)
        stab_df, stab = part_stability(cfg, pbar)
        sine = sine_error_analysis(trajs, direction=cfg["model"]["direction"])
        long_pi = part_long_pi(cfg)
        pbar.update(1)
        ga = ga_job.result()
        pbar.update(1)
    finally:
        thread.close()
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
        "units": summary_units(),
    }
    (tmp / "summary.json").write_text(dumps(summary) + "\n")
    document.write(report(summary, {"pi_readings": pi_df}), tmp)
    return summary


__all__ = ["SUMMARY_UNITS", "UNITS", "n_steps", "run", "summary_units", "write_figures"]
