"""Running the kinematic-vs-dynamic study: the designs, every arm through :func:`pfjax.run_study`,
the throughput comparison, the summary, and the outputs (``runs.parquet``, ``summary.json``,
``report.md``, ``report.html``) through :class:`pfjax.outputs.OutputDir`. ``runs.parquet`` carries
each column's unit and the provenance record (:func:`pfjax.tables.write_parquet`); ``summary.json``
the same record (:func:`pfjax.provenance.stamp`) and its units (``units``,
:data:`pfjax.dynamic_study.summary.UNITS`). The declared slip (``beta_r_deg``, ``beta_f_deg``) is NaN
in the dynamic arms (the sampler declares none on st and std), as the friction ``mu`` is in the
kinematic ones."""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

import pfjax
from pfjax.dynamic_study.arms import arms, check
from pfjax.dynamic_study.config import KinematicVsDynamic
from pfjax.dynamic_study.designs import designs
from pfjax.dynamic_study.report import report
from pfjax.dynamic_study.summary import UNITS, summarise
from pfjax.dynamic_study.throughput import throughput
from pfjax.jsonio import dumps
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash, parquet_metadata, stamp
from pfjax.report import document
from pfjax.tables import write_parquet

#: Units of the columns :data:`pfjax.tables.COLUMNS` does not describe.
COLUMNS = {"arm": ("", "the study arm (pfjax.dynamic_study.arms)")}


def run_arms(config: KinematicVsDynamic, designed: list[dict], log=None) -> tuple[pd.DataFrame, dict]:
    """Every arm's runs (one table, column ``arm``) and each arm's wall time (s); a line per arm to
    ``log`` (default: standard error)."""
    log = sys.stderr if log is None else log
    frames, wall = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, spec in arms(config, designed).items():
            t = time.time()
            res = pfjax.run_study(spec, Path(tmp) / name, report=False, progress=False)
            wall[name] = time.time() - t
            frames.append(res.runs.assign(arm=name))
            print(f"{name}: {len(res.runs)} runs, {wall[name]:.1f} s", file=log)
    return pd.concat(frames, ignore_index=True), wall


def run(config: KinematicVsDynamic, out: str | Path, overwrite: bool = False, log=None) -> dict:
    """Run the study and write its outputs to ``out``; returns the summary. Every arm's study config is
    checked first (:func:`pfjax.dynamic_study.arms.check`: :class:`pfjax.config.ConfigError` naming
    the key, before anything is written or run)."""
    check(config)
    digest = config_hash(config.model_dump(mode="json"))
    marker = {"seed": config.study["seed"]}
    with OutputDir(
        out, command="kinematic-vs-dynamic", config_sha256=digest, overwrite=overwrite, extra=marker
    ) as output:
        t0 = time.time()
        designed, design_record = designs(config) if config.designs.enabled else ([], {})
        t_designs = time.time() - t0
        runs, wall = run_arms(config, designed, log)
        t = time.time()
        bench = throughput(config) if config.bench else {}
        t_bench = time.time() - t
        summary = summarise(config, runs)
        cfg, seed = config.model_dump(mode="json"), config.study["seed"]
        summary.update(
            study=config.name,
            config=cfg,
            **stamp(cfg, seed),
            units=UNITS,
            load_average=list(os.getloadavg()),
            designs=design_record,
            throughput=bench,
            wall_s={"arms": wall, "designs": t_designs, "throughput": t_bench, "total": time.time() - t0},
        )
        meta = parquet_metadata(cfg, seed, config_sha256=digest)
        write_parquet(runs, output.staging / "runs.parquet", meta, units=COLUMNS)
        (output.staging / "summary.json").write_text(dumps(summary) + "\n")
        document.write(report(summary), output.staging)
        output.commit()
    return summary


__all__ = ["COLUMNS", "run", "run_arms"]
