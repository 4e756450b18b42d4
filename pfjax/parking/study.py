"""The parking study (docs/reproductions/parking.md): the a_f calibration, every case of the source's
§4, the assumptions sweep, the garage tries, the GA and grid searches, the start-pose map and a
robustness Monte Carlo, written into one output folder (``summary.json``, five Parquet tables,
figures, ``report.md`` and ``report.html``)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import jax
import pandas as pd
from tqdm import tqdm

from pfjax import errors
from pfjax.errors import InputError
from pfjax.jsonio import dumps
from pfjax.numerics.random import seed_key
from pfjax.outputs import OutputDir, check_name, default_target
from pfjax.parking.calibrate import calibrate_front
from pfjax.parking.maps import GARAGE, PARALLEL, to_obstacle_map
from pfjax.parking.report import write_report
from pfjax.parking.simulate import simulated_first_switch
from pfjax.parking.study_config import ParkingStudy, load
from pfjax.parking.study_parts import part_assumptions, part_montecarlo, part_search, part_start_map
from pfjax.parking.study_runs import part_cases, part_outcomes, setup
from pfjax.provenance import STAMP_UNITS, config_hash, parquet_metadata
from pfjax.provenance import stamp as provenance_stamp
from pfjax.reproduce.parking import verdicts as parking_verdicts
from pfjax.tables import write_parquet

#: the Parquet tables of a study folder
TABLES = ("cases", "assumptions", "grid", "start_map", "montecarlo")

_STATUS = (
    "",
    "run status: converged, timeout, too_many_switches, heading_limit, nonfinite, stuck, start_overlap "
    "(pfjax.parking.runs.Status)",
)
_ERROR = ("m", "end error |x| + sqrt(y^2 + tan^2 theta) (the source's measure)")
#: Each parking table's columns: unit and description (units: "1" dimensionless, "" text, flag or code).
COLUMNS: dict[str, dict[str, tuple[str, str]]] = {
    "cases": {
        "case": ("", "source case A-D, or the garage try"),
        "map": ("", "map: parallel or garage"),
        "start": ("", "start pose (x m, y m, theta deg)"),
        "direction": ("", "first travel direction"),
        "schedule": ("1", "alpha at the start and after each switch, comma-separated"),
        "xs": ("m", "garage switching point X_s (NaN: no garage rule)"),
        "status": _STATUS,
        "converged": ("", "the run parked"),
        "time_s": ("s", "end time (parking time when converged)"),
        "switches": ("switches", "direction switches (a count)"),
        "final_x": ("m", "final x"),
        "final_y": ("m", "final y"),
        "final_theta_deg": ("deg", "final heading"),
        "error": _ERROR,
        "distance_m": ("m", "distance travelled"),
        "switch_times_s": ("s", "times of the logged switches, comma-separated"),
    },
    "assumptions": {
        "front": ("m", "a_f, the rectangle's reach ahead of the wheel axle"),
        "zone": ("", "part of the rectangle checked toward the travel direction: middle, axle, whole"),
        "scan_period": ("s", "scanner period"),
        "decision_delay": ("", "the scanner decides on the pose one period old"),
        "lag": ("", "yaw-rate PI loop on"),
        "pause": ("s", "time standing still at each reversal"),
        "case": ("", "source case A-D"),
        "status": _STATUS,
        "switches": ("switches", "direction switches (a count)"),
        "time_s": ("s", "end time (parking time when converged)"),
        "min_leg_m": ("m", "shortest travel between two reversals (NaN: no reversal)"),
    },
    "grid": {
        "xs": ("m", "switching point X_s"),
        "alpha1": ("1", "gain factor alpha from the 1st switch"),
        "alpha2": ("1", "gain factor alpha from the 2nd switch"),
        "status": _STATUS,
        "time_s": ("s", "end time t_e (parking time when converged)"),
        "switches": ("switches", "direction switches (a count)"),
        "error": _ERROR,
        "fitness": ("1/s", "J = 1/(t_e + search.weight x error); 0 for a failed run"),
    },
    "start_map": {
        "x0": ("m", "start x"),
        "theta0_deg": ("deg", "start heading"),
        "y0": ("m", "start y"),
        "xs": ("m", "best switching point X_s on the grid"),
        "alpha1": ("1", "best alpha from the 1st switch"),
        "alpha2": ("1", "best alpha from the 2nd switch"),
        "fitness": ("1/s", "the best run's J = 1/(t_e + search.weight x error)"),
        "time_s": ("s", "the best run's end time (parking time when converged)"),
        "status": _STATUS,
        "switches": ("switches", "the best run's direction switches (a count)"),
        "converged_fraction": ("1", "fraction of the start's grid runs that park"),
    },
    "montecarlo": {
        "schedule": ("", "the schedule: label with X_s, alpha1, alpha2"),
        "run": ("", "run index (the random stream of the run; the same runs for every schedule)"),
        "x0": ("m", "sampled start x"),
        "y0": ("m", "sampled start y"),
        "theta0_deg": ("deg", "sampled start heading"),
        "scan_period_s": ("s", "sampled scanner period"),
        "speed": ("m/s", "sampled travel speed |v1|"),
        "lag": ("", "sampled: yaw-rate PI loop on"),
        "status": _STATUS,
        "status_code": ("", "run status code (pfjax.parking.runs.Status)"),
        "converged": ("", "the run parked"),
        "time_s": ("s", "end time (parking time when converged)"),
        "switches": ("switches", "direction switches (a count)"),
        "error": _ERROR,
    },
}


#: ``summary.json``'s units by field name, beyond the tables' columns (:func:`summary_units`); a
#: field has one meaning wherever it occurs, a block's key names the unit of everything under it
#: (``time_s``: its quantiles over converged runs in ``montecarlo``); "1": dimensionless.
SUMMARY_UNITS: dict[str, str] = {
    **STAMP_UNITS,
    "wall_s": "s",
    "timings_s": "s (wall clock per part)",
    # calibration
    "a_f": "m",
    "tolerance_m": "m (one scanner period of travel)",
    "reach_per_obstacle": "m (the reach a_f at which the corner touches each obstacle)",
    "theta_deg_at_switch": "deg",
    "y_closed_form_at_switch_x": "m",
    "y_source": "m",
    "switch_x": "m",
    "t": "s",
    "x": "m",
    "y": "m",
    "theta_deg": "deg",
    # runs, searches, the Monte Carlo
    "switches": "direction switches (in montecarlo, their statistics over converged runs)",
    "n": "runs (in search.grid: levels per gene of the n x n x n grid)",
    "k": "runs (converged)",
    "n_finite": "runs (converged, the statistic's sample)",
    "status_counts": "runs",
    "by_zone": "runs (per case and status)",
    "success_rate": "1",
    "success_ci95": "1 (95 % Clopper-Pearson interval of the success rate)",
    "n_combinations": "combinations of the assumptions",
    "b_min_leg_m": "m",
    "n_simulations": "runs (simulated)",
    "seed_index": "1 (index of the GA run, folded into its key)",
    "bits": "1 (the chromosome's bits, 0 or 1)",
    "history_best_fitness": "1/s (the best fitness per generation)",
    "history_mean_fitness": "1/s (the population's mean fitness per generation)",
    "grid_fraction_better": "1 (fraction of the grid's runs with a higher fitness)",
    "fitness_ratio_to_grid_best": "1 (null where no grid point scores)",
}


def summary_units() -> dict[str, str]:
    """``summary.json``'s ``units``: the tables' columns that have a unit (:data:`COLUMNS`), then
    :data:`SUMMARY_UNITS`."""
    columns = {k: u for table in COLUMNS.values() for k, (u, _) in table.items() if u}
    return {**columns, **SUMMARY_UNITS}


def calibration(cfg: ParkingStudy) -> dict:
    """The a_f calibration (:func:`pfjax.parking.calibrate.calibrate_front`) and case A's first switch
    simulated as the study's runs go: with their reach (``front``: the calibrated a_f, or
    ``sim.front`` where set, ``front_source`` says which), controller and scanner period;
    ``tolerance_m``: one scanner period of travel, |v₁| × the scanner period."""
    control, front, pc, _ = setup(cfg)
    cal = calibrate_front()
    used = cal["a_f"] if front is None else front
    scan, speed = cfg.sim.scan_period, cfg.controller.speed
    cal.update(
        front=used,
        front_source="calibrated" if front is None else "sim.front",
        scan_period=scan,
        speed=speed,
        tolerance_m=speed * scan,
        simulated_first_switch=simulated_first_switch(used, control=control, scan_period=scan, cfg=pc),
    )
    return cal


def _parts(cfg: ParkingStudy, fig_dir: Path, progress: bool) -> tuple[dict, dict, dict]:
    """Run every part; returns ``(results, tables, timings_s)``."""
    pmap, gmap = to_obstacle_map(list(PARALLEL.values())), to_obstacle_map(list(GARAGE.values()))
    k_ga, k_mc = jax.random.split(seed_key(cfg.seed))
    steps = tqdm(total=6, desc="parking study", unit="part", disable=not progress)
    timings: dict = {}
    t0 = time.perf_counter()

    def tick(name):
        nonlocal t0
        timings[name] = time.perf_counter() - t0
        steps.update(1)
        t0 = time.perf_counter()

    cal = calibration(cfg)
    tick("calibration")
    case_rows, _ = part_cases(cfg, fig_dir, pmap, gmap)
    tick("cases")
    outcomes = part_outcomes(cfg, pmap, gmap)
    sens, sweep = part_assumptions(cfg, pmap)
    tick("assumptions")
    ga, ga_runs, grid, grid_df, sources = part_search(cfg, fig_dir, gmap, k_ga)
    tick("search")
    smap = part_start_map(cfg, fig_dir, gmap)
    tick("start_map")
    mc_df, mc = part_montecarlo(cfg, fig_dir, gmap, ga, grid, k_mc)
    tick("montecarlo")
    steps.close()
    results = {
        "calibration": cal,
        "cases": case_rows,
        "assumptions": sweep,
        "source_outcomes": outcomes,
        "search": {"ga": ga, "ga_runs": ga_runs, "grid": grid, "source_solutions": sources},
        "start_map": smap,
        "montecarlo": mc,
    }
    tables = {
        "cases": pd.DataFrame(case_rows),
        "assumptions": sens,
        "grid": grid_df.drop(columns=["converged_fraction"]),
        "start_map": pd.DataFrame(smap),
        "montecarlo": mc_df,
    }
    return results, tables, timings


def run_study(config: ParkingStudy, out: Path, quick: bool = False, progress: bool = True) -> dict:
    """Run the study into the (empty, staging) folder ``out``; returns the summary written there.

    Args:
        config: the validated study config.
        out: the folder to write ``summary.json``, the tables, ``figures/`` and the report into.
        quick: recorded in the summary (the ``--quick`` sizes are already in ``config``).
        progress: show progress bars.
    """
    t_start = time.perf_counter()
    cfg = config.model_dump(mode="json")
    fig_dir = out / "figures"
    fig_dir.mkdir(parents=True)
    results, tables, timings = _parts(config, fig_dir, progress)
    meta = parquet_metadata(cfg, cfg["seed"])
    for name in TABLES:
        write_parquet(tables[name], out / f"{name}.parquet", meta, units=COLUMNS[name])
    summary = {
        "study": cfg["name"],
        **provenance_stamp(cfg, cfg["seed"]),
        "quick": quick,
        "config": cfg,
        **results,
        "timings_s": timings,
        "wall_s": time.perf_counter() - t_start,
    }
    rows = parking_verdicts(
        results["source_outcomes"],
        results["calibration"],
        results["assumptions"],
        {
            "runs": results["search"]["ga_runs"],
            "source_solutions": results["search"]["source_solutions"],
            "grid_n": config.search.grid_n,
        },
        pause=config.experiment.pause,
        stuck_travel=config.sim.stuck_travel,
        stuck_switches=config.sim.stuck_switches,
    )
    summary["verdicts"] = [v._asdict() for v in rows]
    summary["units"] = summary_units()
    (out / "summary.json").write_text(dumps(summary) + "\n")
    write_report(out, summary, tables)
    return summary


def run(
    config: ParkingStudy | str | Path | None = None,
    out: str | Path | None = None,
    *,
    overrides: tuple[str, ...] | list[str] = (),
    quick: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    flag: str = "out",
) -> tuple[Path, dict]:
    """Run the parking study into ``out`` (default ``results/<name>``), assembled in a staging folder
    and moved into place when complete (:class:`pfjax.outputs.OutputDir`). Returns ``(folder, summary)``.

    Args:
        config: a validated :class:`ParkingStudy`, a TOML path (str or path-like), or None for the defaults.
        out: the output folder (str or path-like).
        overrides: a list or tuple of ``--set`` texts ``"key=value"`` (with a path or None only).
        quick: True: apply the ``--quick`` sizes (with a path or None; with a :class:`ParkingStudy`,
            only recorded in the summary).
        overwrite: replace a pfjax output of another config in ``out``.
        progress: show progress bars.
        flag: the name ``out`` goes by in the output directory's refusals (:class:`pfjax.outputs.OutputDir`;
            ``studies/parking.py`` passes its ``--out``).

    Raises:
        pfjax.errors.InputError: a bad argument, named as here (``config``, ``out``, ``overrides``,
            ``quick``, ``overwrite``, ``progress``), before anything is written; its subclass
            :class:`pfjax.config.ConfigError` for a bad key or value of the config (one line naming the key).
    """
    if config is not None and not isinstance(config, (ParkingStudy, str, os.PathLike)):
        raise InputError(f"config: expected a ParkingStudy, a TOML path or None, got {type(config).__name__}", "config")
    if out is not None and not isinstance(out, (str, os.PathLike)):
        raise InputError(f"out: expected a directory path or None, got {type(out).__name__}", "out")
    if not isinstance(overrides, (list, tuple)) or not all(isinstance(o, str) for o in overrides):
        raise InputError(f'overrides: expected a list of "key=value" strings, got {overrides!r:.80}', "overrides")
    for key, value in (("quick", quick), ("overwrite", overwrite), ("progress", progress)):
        errors.boolean(key, value)
    if isinstance(config, ParkingStudy):
        if overrides:
            raise InputError("overrides: only with a config path or None (a ParkingStudy is already validated)")
    else:
        try:
            config = load(config, overrides, quick=quick)
        except InputError as e:  # the config module's flag, by this function's argument
            raise errors.renamed(e, "--set", "overrides") from None
    check_name("name", config.name)
    folder = default_target(config.name, out)
    with OutputDir(
        folder,
        command="parking-study",
        config_sha256=config_hash(config.model_dump(mode="json")),
        overwrite=overwrite,
        extra={"seed": config.seed},
        flag=flag,
    ) as output:
        summary = run_study(config, output.staging, quick=quick, progress=progress)
        folder = output.commit()
    return folder, summary
