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
from pfjax.outputs import OutputDir, check_name
from pfjax.parking.calibrate import calibrate_front
from pfjax.parking.maps import GARAGE, PARALLEL, to_obstacle_map
from pfjax.parking.report import write_report
from pfjax.parking.simulate import simulated_first_switch
from pfjax.parking.study_config import ParkingStudy, load
from pfjax.parking.study_parts import part_assumptions, part_montecarlo, part_search, part_start_map
from pfjax.parking.study_runs import part_cases, part_outcomes
from pfjax.provenance import config_hash, parquet_metadata
from pfjax.provenance import stamp as provenance_stamp
from pfjax.reproduce.parking import verdicts as parking_verdicts
from pfjax.tables import write_parquet

#: the Parquet tables of a study folder
TABLES = ("cases", "assumptions", "grid", "start_map", "montecarlo")


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

    cal = calibrate_front()
    cal["simulated_first_switch"] = simulated_first_switch(cal["a_f"])
    tick("calibration")
    case_rows, _ = part_cases(cfg, fig_dir, pmap, gmap)
    tick("cases")
    outcomes = part_outcomes(cfg, pmap, gmap)
    sens, sweep = part_assumptions(cfg, pmap)
    tick("assumptions")
    ga, ga_runs, grid, grid_df = part_search(cfg, fig_dir, gmap, k_ga)
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
        "search": {"ga": ga, "ga_runs": ga_runs, "grid": grid},
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
        write_parquet(tables[name], out / f"{name}.parquet", meta)
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
        {"runs": results["search"]["ga_runs"]},
    )
    summary["verdicts"] = [v._asdict() for v in rows]
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
    folder = Path(out) if out is not None else Path("results") / config.name
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
