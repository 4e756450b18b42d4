"""``pfjax study``: load and validate a study, run it, write runs, margin sweep, summary and report.

Outputs under ``results/<name>/`` (or ``--out``), assembled in a temporary directory and moved
into place only when complete: ``runs.parquet`` (one row per run), ``margin.parquet`` (the
slip-margin sweep), ``summary.json`` (strict JSON) and, unless disabled, ``report.html`` with
``figures/*.png|svg``.
"""

from __future__ import annotations

import time
from pathlib import Path

import jax
import pandas as pd

from pfjax.montecarlo.config import StudySpec, load_study
from pfjax.montecarlo.runner import margin_sweep, run_study
from pfjax.montecarlo.summary import summarize

ROOT = Path(__file__).resolve().parents[2]
#: The phases of ``timings_s`` in summary.json (main-thread wall clock, s).
PHASES = ("runs", "margin", "worst_case", "float64_check", "summary", "report")


class SideJobs:
    """The parts of a study that do not depend on its runs: the worst-case search (one task per
    controller) and the float64 re-simulation (one task per path).

    With ``overlap=True`` they run in one background thread while the main thread simulates the
    runs and the margin sweep. The XLA compiler and the simulations release the GIL, so the
    background compiles run on the core that the main thread's single-threaded work (compiling,
    tracing, sampling, writing Parquet) leaves idle. Every task computes exactly what it computes
    alone (its own PRNG streams, its own precision context, which JAX keeps per thread), so the
    results do not depend on ``overlap`` (tests/test_montecarlo.py). With ``overlap=False`` each
    task runs in the main thread when its result is first asked for.

    The tasks run on one device (the last local one), never on several: programs that span devices
    synchronise them (all-gathers), and two threads launching such programs can interleave them
    differently on each device and deadlock (seen: XLA's CPU rendezvous aborted the process).
    Only the main thread launches multi-device programs.
    """

    def __init__(self, spec: StudySpec, controllers: dict, *, overlap: bool = True, report: bool = True):
        from concurrent.futures import ThreadPoolExecutor

        from pfjax.montecarlo.checks import float64_runs
        from pfjax.montecarlo.runner import precision
        from pfjax.montecarlo.worst_case import worst_case

        self.seconds = {"worst_case": 0.0, "float64_check": 0.0}
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="pfjax-study") if overlap else None

        device = jax.local_devices()[-1]

        def task(phase, fn, *args, pinned=True):
            def timed():
                t = time.perf_counter()
                with precision(spec):
                    if pinned:
                        with jax.default_device(device):
                            value = fn(*args, devices=[device])
                    else:
                        value = fn(*args)
                self.seconds[phase] = self.seconds.get(phase, 0.0) + time.perf_counter() - t
                return value
            return self._pool.submit(timed) if self._pool is not None else _Deferred(timed)

        # first, as the report needs it soonest: compile the slip map's linearised prediction (1-2 s),
        # with JAX's default device as the report has it, so that the report's call finds it compiled
        self.report_warmup = None
        if report:
            from pfjax.report.study_report import warm_predictions

            self.report_warmup = task("report_warmup", warm_predictions, spec, {k: v[2] for k, v in controllers.items()},
                                      pinned=False)
        self.worst = {name: task("worst_case", worst_case, spec, controllers, i)
                      for i, name in enumerate(controllers)} if spec.falsifier.enabled else {}
        checked = spec.dtype != "float64" and spec.f64_check_runs > 0
        self.float64 = [task("float64_check", float64_runs, spec, controllers, spec.f64_check_runs, p)
                        for p in range(len(spec.paths))] if checked else None

    def worst_cases(self) -> tuple[dict, dict]:
        """``(summary blocks, trajectories)`` per controller, as :func:`pfjax.montecarlo.worst_case.worst_cases`."""
        blocks, trajs = {}, {}
        for name, f in self.worst.items():
            blocks[name], trajs[name] = f.result()
        return blocks, trajs

    def float64_runs(self) -> list | None:
        return None if self.float64 is None else [f.result() for f in self.float64]

    def close(self) -> None:
        """Cancel the tasks not yet started (the running one finishes: at most one task's time)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


class _Deferred:
    """A task computed in the calling thread when its result is first asked for."""

    def __init__(self, fn):
        self._fn, self._done, self._value = fn, False, None

    def result(self):
        if not self._done:
            self._value, self._done = self._fn(), True
        return self._value


def run(spec: StudySpec, out: Path | None = None, *, progress: bool | None = None, report: bool = True,
        fresh: bool = False, warn=None, overlap: bool = True) -> dict:
    """Run a validated study; returns the summary.

    Resumes an interrupted run of the same study into ``out`` (its finished chunks are reused);
    ``fresh=True`` discards them and starts over. ``warn(message)`` receives each feasibility
    warning (:func:`pfjax.montecarlo.checks.study_warnings`) before the simulation starts; the
    warnings are also recorded in ``summary.json``. ``overlap``: run the worst-case search and the
    float64 check alongside the runs (:class:`SideJobs`; the same results either way).
    """
    from pfjax.cli import dumps
    from pfjax.montecarlo.checks import float64_check, sample_indices, study_warnings
    from pfjax.montecarlo.runner import controllers_of

    out = Path(out) if out is not None else Path("results") / spec.name
    t0 = time.time()
    result = {}
    warnings = study_warnings(spec)
    for w in warnings:
        (warn or (lambda m: None))(w)
    controllers = controllers_of(spec)
    side = SideJobs(spec, controllers, overlap=overlap, report=report)

    def finish(tmp: Path, runs_path: Path, controllers, store) -> dict:
        timings = {"runs": time.time() - t0}  # s per phase (wall clock), in summary.json
        lap = [time.time()]

        def mark(phase):
            now = time.time()
            timings[phase] = timings.get(phase, 0.0) + now - lap[0]
            lap[0] = now

        sweep = margin_sweep(spec, controllers, progress=progress, store=store) if spec.margin.enabled else None
        if sweep is not None:
            sweep.to_parquet(tmp / "margin.parquet", index=False)
            _stamp(tmp / "margin.parquet", spec)
        mark("margin")
        # Without a report the run table is never loaded whole: the summary reads one controller at
        # a time and the float64 check only its sampled runs (memory: one controller's rows at most).
        runs = read_runs(runs_path) if report else None
        summary = summarize(spec, runs if runs is not None else runs_path, sweep,
                            gains={k: v[2] for k, v in controllers.items()}, wall_s=time.time() - t0)
        summary["warnings"] = warnings
        summary["float64_check"] = None  # below: its float64 runs may still be running in the background
        summary["chunks"] = {"simulated": store.computed, "resumed": store.reused}
        mark("summary")
        if report:  # the figures first, those of the runs while the worst-case search may still run
            from pfjax.report.study_report import FIGURES, ordered_figures, report_figures, write_report

            figures = report_figures(tmp, spec, summary, runs, names=[n for n in FIGURES if n != "worst_cases"])
            mark("report")
        worst, worst_traj = side.worst_cases()
        for name, block in worst.items():
            summary["controllers"][name]["worst_case"] = block
        mark("worst_case")
        if report:
            figures = ordered_figures(report_figures(tmp, spec, summary, runs, worst_traj, names=["worst_cases"]), figures)
            mark("report")
        check_rows = runs if runs is not None or spec.dtype == "float64" or spec.f64_check_runs <= 0 else \
            read_runs(runs_path, filters=[("run", "in", sample_indices(spec, spec.f64_check_runs).tolist())])
        summary["float64_check"] = float64_check(spec, controllers, check_rows, spec.f64_check_runs, sims=side.float64_runs())
        mark("float64_check")
        if report:
            write_report(tmp, spec, summary, runs, sweep, worst_traj, figures=figures)
            mark("report")
            summary["wall_s"] = time.time() - t0
        timings = {k: timings[k] for k in PHASES if k in timings}
        # and the side jobs' own compute time (in the background thread when overlapped with the runs)
        summary["timings_s"] = {**timings, "side_jobs": {**side.seconds, "overlapped": overlap}}
        (tmp / "summary.json").write_text(dumps(summary) + "\n")
        result["summary"] = summary
        return {}

    try:
        run_study(spec, out, progress=progress, extra=finish, fresh=fresh, controllers=controllers)
    finally:
        side.close()
    return result["summary"]


def read_runs(path: Path, **kw) -> pd.DataFrame:
    """``runs.parquet`` as a DataFrame (pandas >= 3 keeps the string columns Arrow-backed, a few
    bytes per run); ``kw`` go to :func:`pandas.read_parquet` (``columns``, ``filters``)."""
    return pd.read_parquet(path, **kw)


def _stamp(path: Path, spec: StudySpec) -> None:
    """Rewrite a small Parquet file with the study's config, hash, seed and version in its metadata."""
    import pyarrow.parquet as pq

    from pfjax.montecarlo.chunks import file_metadata

    t = pq.read_table(path)
    pq.write_table(t.replace_schema_metadata({**(t.schema.metadata or {}), **file_metadata(spec)}), path)


def main_from_args(config: str, overrides: list[str], out: str | None, report: bool) -> dict:
    spec, _ = load_study(config, overrides)
    return run(spec, None if out is None else Path(out), report=report)
