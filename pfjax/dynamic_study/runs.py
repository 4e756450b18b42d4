"""Running the kinematic-vs-dynamic study: the designs, every arm through :func:`pfjax.run_study`,
the throughput comparison, the summary, and the outputs (``runs.parquet``, ``summary.json``,
``report.md``, ``report.html``) through :class:`pfjax.outputs.OutputDir`."""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

import pfjax
from pfjax.dynamic_study.arms import arms
from pfjax.dynamic_study.config import KinematicVsDynamic
from pfjax.dynamic_study.designs import designs
from pfjax.dynamic_study.report import report
from pfjax.dynamic_study.summary import summarise
from pfjax.dynamic_study.throughput import throughput
from pfjax.jsonio import dumps
from pfjax.outputs import OutputDir
from pfjax.provenance import config_hash, machine
from pfjax.report import document


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
    """Run the study and write its outputs to ``out``; returns the summary."""
    digest = config_hash(config.model_dump(mode="json"))
    with OutputDir(out, command="kinematic-vs-dynamic", config_sha256=digest, overwrite=overwrite) as output:
        t0 = time.time()
        designed, design_record = designs(config) if config.designs.enabled else ([], {})
        t_designs = time.time() - t0
        runs, wall = run_arms(config, designed, log)
        t = time.time()
        bench = throughput(config) if config.bench else {}
        t_bench = time.time() - t
        summary = summarise(config, runs)
        summary.update(
            study=config.name,
            config=config.model_dump(mode="json"),
            config_sha256=digest,
            pfjax_version=pfjax.__version__,
            machine=machine(),
            load_average=list(os.getloadavg()),
            designs=design_record,
            throughput=bench,
            wall_s={"arms": wall, "designs": t_designs, "throughput": t_bench, "total": time.time() - t0},
        )
        runs.to_parquet(output.staging / "runs.parquet", index=False)
        (output.staging / "summary.json").write_text(dumps(summary) + "\n")
        document.write(report(summary), output.staging)
        output.commit()
    return summary


__all__ = ["run", "run_arms"]
