"""``pfjax study``: load and validate a study, run it, write runs, margin sweep, summary and report.

Outputs under ``results/<name>/`` (or ``--out``), assembled in a temporary directory and moved
into place only when complete: ``runs.parquet`` (one row per run), ``margin.parquet`` (the
slip-margin sweep), ``summary.json`` (strict JSON) and, unless disabled, ``report.html`` with
``figures/*.png|svg``.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import jax
import pandas as pd

from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.runner import margin_sweep, run_study
from pfjax.montecarlo.summary import summarize
from pfjax.report import figure_worker

ROOT = Path(__file__).resolve().parents[2]
#: Report figures drawn by the figure worker (:mod:`pfjax.report.figure_worker`) when there is
#: one: those that need only the runs, asked for as soon as the runs are written, the worst-case
#: figure (3-4 s), asked for by whichever thread finishes the last worst-case search
#: (:class:`_WorstFigure`), and those that need only the summary (2.9 s of drawing on the default
#: study). The main thread draws the slip map (its prediction is a JAX program) and meanwhile
#: computes the side jobs the background thread has not started.
RUN_FIGURES = ["dist_iae", "dist_late_max_abs_d"]
WORKER_SUMMARY_FIGURES = ["headline", "margin_curves", "success_by_param"]
#: The phases of ``timings_s`` in summary.json (main-thread wall clock, s).
PHASES = ("runs", "margin", "worst_case", "rare_event", "float64_check", "summary", "report")


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

    When the main thread asks for a result, it first takes over every task the background thread
    has not started (the latest first; the background thread works from the front): it cancels the
    task there and computes it itself, the same function on the same device, so the same result.
    Whichever thread is free works, and the study does not wait for a queue that one thread would
    work through alone.
    """

    def __init__(
        self,
        spec: StudySpec,
        controllers: dict,
        *,
        overlap: bool = True,
        report: bool = True,
        worker: figure_worker.FigureWorker | None = None,
    ):
        from concurrent.futures import ThreadPoolExecutor

        from pfjax.montecarlo.checks import float64_runs
        from pfjax.montecarlo.runner import precision
        from pfjax.montecarlo.worst_case import worst_case

        self.seconds = {"worst_case": 0.0, "float64_check": 0.0}
        self._queued: list = []  # tasks the main thread may take over, in submission order
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

            if self._pool is None:
                return _Deferred(timed)
            job = _Stealable(self._pool.submit(timed), timed)
            self._queued.append(job)
            return job

        # first, as the report needs it soonest: compile the slip map's linearised prediction (1-2 s),
        # with JAX's default device as the report has it, so that the report's call finds it compiled
        self.report_warmup = None
        if report:
            from pfjax.report.figure_set import warm_predictions

            self.report_warmup = task(
                "report_warmup", warm_predictions, spec, {k: v[2] for k, v in controllers.items()}, pinned=False
            )
        self.worst_figure = _WorstFigure(worker, spec, list(controllers)) if report and spec.falsifier.enabled else None
        found = (lambda name, value: value) if self.worst_figure is None else self.worst_figure.found
        self.worst = (
            {
                name: task(
                    "worst_case", lambda *a, name=name, **k: found(name, worst_case(*a, **k)), spec, controllers, i
                )
                for i, name in enumerate(controllers)
            }
            if spec.falsifier.enabled
            else {}
        )
        checked = spec.dtype != "float64" and spec.f64_check_runs > 0
        self.float64 = (
            [
                task("float64_check", float64_runs, spec, controllers, spec.f64_check_runs, p)
                for p in range(len(spec.paths))
            ]
            if checked
            else None
        )

    def take_over(self) -> None:
        """Compute here every task the background thread has not started, the latest first."""
        for job in reversed(self._queued):
            job.take_over()

    def worst_cases(self) -> tuple[dict, dict]:
        """``(summary blocks, trajectories)`` per controller, as :func:`pfjax.montecarlo.worst_case.worst_cases`."""
        self.take_over()
        blocks, trajs = {}, {}
        for name, f in self.worst.items():
            blocks[name], trajs[name] = f.result()
        return blocks, trajs

    def float64_runs(self) -> list | None:
        self.take_over()
        return None if self.float64 is None else [f.result() for f in self.float64]

    def close(self) -> None:
        """Cancel the tasks not yet started (the running one finishes: at most one task's time)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


class _WorstFigure:
    """The worst-case figure, asked of the figure worker as soon as every controller's worst-case
    search has finished and the study's output directory exists, by whichever thread gets there
    last (a search's thread, or the main thread when it names the directory). Without a worker
    :meth:`result` returns None and the study draws the figure itself."""

    def __init__(self, worker, spec: StudySpec, names: list[str]):
        self._worker, self._spec, self._names = worker, spec, names
        self._lock = threading.Lock()
        self._found: dict = {}
        self._out: tuple[Path, Path] | None = None
        self._request = None

    def found(self, name: str, value):
        """Record one controller's ``(summary block, trajectory)``; returns ``value``."""
        with self._lock:
            self._found[name] = value
        self._maybe_submit()
        return value

    def start(self, out_dir: Path, runs_path: Path) -> None:
        """The directory the figure goes to (``out_dir/figures``) and the run table's file."""
        with self._lock:
            self._out = (out_dir, runs_path)
        self._maybe_submit()

    def _maybe_submit(self) -> None:
        with self._lock:
            if (
                self._worker is None
                or self._out is None
                or self._request is not None
                or len(self._found) < len(self._names)
            ):
                return
            # the figure reads only the summary's worst-case blocks, in the controllers' order
            summary = {"controllers": {n: {"worst_case": self._found[n][0]} for n in self._names}}
            trajs = {n: self._found[n][1] for n in self._names}
            self._request = self._worker.submit(
                *self._out[:1], self._spec, summary, self._out[1], ["worst_cases"], trajs
            )

    def result(self) -> dict | None:
        """The figure's entry (as :func:`~pfjax.report.figure_set.report_figures`), or None if it
        was not asked of a worker."""
        self._maybe_submit()
        return None if self._request is None else self._request.result()


class _Stealable:
    """A task submitted to the background thread that the calling thread can take over."""

    def __init__(self, future, fn):
        self._future, self._fn = future, fn

    def take_over(self) -> None:
        """Compute the task here, now, if the background thread has not started it."""
        if not isinstance(self._future, _Deferred) and self._future.cancel():
            self._future = _Deferred(self._fn)
            self._future.result()

    def result(self):
        self.take_over()
        return self._future.result()


class _Deferred:
    """A task computed in the calling thread when its result is first asked for."""

    def __init__(self, fn):
        self._fn, self._done, self._value = fn, False, None

    def result(self):
        if not self._done:
            self._value, self._done = self._fn(), True
        return self._value


def run(
    spec: StudySpec,
    out=None,
    *,
    progress: bool | None = None,
    report: bool = True,
    fresh: bool = False,
    warn=None,
    overlap: bool = True,
    worker: figure_worker.FigureWorker | None = None,
    controllers: dict | None = None,
    overwrite: bool = False,
    distributed: bool = False,
) -> dict:
    """Run a validated study; returns the summary.

    ``out``: the output directory (default ``results/<name>``), or an
    :class:`~pfjax.outputs.OutputDir` the caller opened. It is checked and locked before anything
    is computed, and replaced only as :mod:`pfjax.outputs` allows (``overwrite``: replace a pfjax
    output of another config or command). Resumes an interrupted run of the same study into
    ``out`` (its finished chunks are reused); ``fresh=True`` discards them and starts over.
    ``warn(message)`` receives each feasibility warning
    (:func:`pfjax.montecarlo.checks.study_warnings`) before the simulation starts; the warnings are
    also recorded in ``summary.json``. ``overlap``: run the worst-case search and the float64 check
    alongside the runs (:class:`SideJobs`; the same results either way). ``worker``: a
    :class:`~pfjax.report.figure_worker.FigureWorker` the caller started (the CLI starts it before
    it imports JAX, so that both imports overlap); ``run`` closes it. By default ``run`` starts one
    when it writes a report with ``overlap`` and ``PFJAX_FIGURE_WORKER`` is not ``0``.
    ``controllers``: :func:`pfjax.montecarlo.runner.controllers_of` ``(spec)`` if the caller has
    them. ``distributed``: this is process 0 of a multi-process study
    (:func:`pfjax.montecarlo.processes.lead` tells the others what to simulate).
    """
    from pfjax.montecarlo.checks import check_resources
    from pfjax.montecarlo.runner import study_output
    from pfjax.outputs import OutputDir

    check_resources(spec, report=report)  # before anything is written or allocated
    output = out if isinstance(out, OutputDir) else study_output(spec, out, overwrite=overwrite)
    opened_here = not output.is_open
    if worker is not None and not (report and overlap):
        worker.close()
        worker = None
    try:
        if distributed:
            from pfjax.montecarlo.processes import lead

            controllers = lead(spec, output, fresh=fresh)  # opens (locks) the output, or tells the others why not
            fresh = False
        output.open()
        if worker is None and report and overlap and figure_worker.enabled():
            worker = figure_worker.FigureWorker()  # imports matplotlib now, draws once the runs are written
        return _run(
            spec,
            output,
            progress=progress,
            report=report,
            fresh=fresh,
            warn=warn,
            overlap=overlap,
            worker=worker,
            controllers=controllers,
        )
    finally:
        if worker is not None:
            worker.close()
        if opened_here:
            output.close()


def _run(spec: StudySpec, output, *, progress, report, fresh, warn, overlap, worker, controllers) -> dict:
    from pfjax.jsonio import dumps
    from pfjax.montecarlo.checks import float64_check, sample_indices, study_warnings
    from pfjax.montecarlo.runner import controllers_of

    t0 = time.time()
    result = {}
    warnings = study_warnings(spec)
    for w in warnings:
        (warn or (lambda m: None))(w)
    controllers = controllers_of(spec) if controllers is None else controllers
    side = SideJobs(spec, controllers, overlap=overlap, report=report, worker=worker)

    def finish(tmp: Path, runs_path: Path, controllers, store) -> dict:
        timings = {"runs": time.time() - t0}  # s per phase (wall clock), in summary.json
        lap = [time.time()]
        # the figures of the runs alone, drawn by the worker process during the margin sweep
        early = (
            worker.submit(tmp, spec, {"paths": [p.label for p in spec.paths]}, runs_path, RUN_FIGURES)
            if worker is not None
            else None
        )
        if side.worst_figure is not None:
            side.worst_figure.start(tmp, runs_path)  # asked of the worker now if the search is done, else when it is

        def mark(phase):
            now = time.time()
            timings[phase] = timings.get(phase, 0.0) + now - lap[0]
            lap[0] = now

        sweep = (
            margin_sweep(spec, controllers, progress=progress, store=store, dest=tmp / "margin.parquet")
            if spec.margin.enabled
            else None
        )
        mark("margin")
        # Without a report the run table is never loaded whole: the summary reads one controller at
        # a time and the float64 check only its sampled runs (memory: one controller's rows at most).
        runs = read_runs(runs_path) if report else None
        summary = summarize(
            spec,
            runs if runs is not None else runs_path,
            sweep,
            gains={k: v[2] for k, v in controllers.items()},
            wall_s=time.time() - t0,
        )
        summary["warnings"] = warnings
        summary["float64_check"] = None  # below: its float64 runs may still be running in the background
        summary["chunks"] = {"simulated": store.computed, "resumed": store.reused}
        mark("summary")
        parts = []
        if report:
            from pfjax.report.figure_set import FIGURES, ordered_figures, report_figures
            from pfjax.report.study_report import write_report

            here = [n for n in FIGURES if n != "worst_cases"]
            if worker is not None:
                # the worker draws the run figures (asked above) and the summary's; meanwhile this
                # thread computes the side jobs not started yet (SideJobs), then draws the others
                parts = [early, worker.submit(tmp, spec, summary, runs_path, WORKER_SUMMARY_FIGURES)]
                here = [n for n in here if n not in RUN_FIGURES + WORKER_SUMMARY_FIGURES]
                side.take_over()
            # the figures before the wait for the worst-case search, which may still run
            figures = report_figures(tmp, spec, summary, runs, names=here)
            mark("report")
        worst, worst_traj = side.worst_cases()
        for name, block in worst.items():
            summary["controllers"][name]["worst_case"] = block
        mark("worst_case")
        if spec.rare_event.enabled:
            from pfjax.rare.study import estimate_study

            for name, est in estimate_study(spec, controllers, progress=progress).items():
                summary["controllers"][name].update(
                    p_fail=est["p_fail"],
                    p_fail_ci95=est["ci95"],
                    rel_error=est["rel_error"],
                    n_rollouts=est["n_rollouts"],
                    method=est["method"],
                    rare_event=est,
                )
            mark("rare_event")
        if report:
            worst_figure = side.worst_figure.result() if side.worst_figure is not None else None
            if worst_figure is None:
                worst_figure = report_figures(tmp, spec, summary, runs, worst_traj, names=["worst_cases"])
            figures = ordered_figures(worst_figure, figures, *(part.result() for part in parts))
            mark("report")
        check_rows = (
            runs
            if runs is not None or spec.dtype == "float64" or spec.f64_check_runs <= 0
            else read_runs(runs_path, filters=[("run", "in", sample_indices(spec, spec.f64_check_runs).tolist())])
        )
        summary["float64_check"] = float64_check(
            spec, controllers, check_rows, spec.f64_check_runs, sims=side.float64_runs()
        )
        mark("float64_check")
        if report:
            write_report(tmp, spec, summary, runs, worst_traj, figures=figures)
            mark("report")
            summary["wall_s"] = time.time() - t0
        timings = {k: timings[k] for k in PHASES if k in timings}
        # and the side jobs' own compute time (in the background thread when overlapped with the runs)
        summary["timings_s"] = {**timings, "side_jobs": {**side.seconds, "overlapped": overlap}}
        (tmp / "summary.json").write_text(dumps(summary) + "\n")
        result["summary"] = summary
        return {}

    try:
        run_study(spec, output, progress=progress, extra=finish, fresh=fresh, controllers=controllers)
    finally:
        side.close()
    return result["summary"]


def read_runs(path: Path, **kw) -> pd.DataFrame:
    """``runs.parquet`` as a DataFrame (pandas >= 3 keeps the string columns Arrow-backed, a few
    bytes per run); ``kw`` go to :func:`pandas.read_parquet` (``columns``, ``filters``)."""
    return pd.read_parquet(path, **kw)


def read_finished(out) -> tuple[dict, pd.DataFrame]:
    """A finished study's ``(summary, runs)`` from its output directory;
    :class:`~pfjax.errors.InputError` naming ``--out`` (one line) if a file is missing or corrupt."""
    import json

    from pfjax.errors import InputError, one_line

    out = Path(out)

    def load(name, reader):
        f = out / name
        if not f.is_file():
            raise InputError(f"--out: {f} is missing; re-run the study (pfjax study CONFIG --out {out})")
        try:
            return reader(f)
        except (OSError, ValueError, UnicodeDecodeError) as e:  # pyarrow's errors are ValueErrors too
            raise InputError(f"--out: {f} cannot be read ({one_line(e)}); re-run the study") from None

    summary = load("summary.json", lambda f: json.loads(f.read_text(encoding="utf-8")))
    if not isinstance(summary, dict) or not isinstance(summary.get("controllers"), dict):
        raise InputError(f"--out: {out / 'summary.json'} is not a study summary; re-run the study")
    return summary, load("runs.parquet", read_runs)


def rewrite_report(out, spec: StudySpec, *, overwrite: bool = False) -> Path:
    """Render the report of the finished study in ``out`` again (``pfjax report``), without
    simulating: the figures that need only the summary and runs are redrawn, the worst-case figure
    (which needs the search's trajectories) is kept. The output is replaced whole, as a study's
    (:class:`~pfjax.outputs.OutputDir`); returns its directory."""
    from pfjax.montecarlo.runner import study_output
    from pfjax.report.figure_set import FIGURES, figure_entries, ordered_figures, report_figures
    from pfjax.report.study_report import write_report

    output = study_output(spec, out, overwrite=overwrite)
    with output:
        summary, runs = read_finished(output.target)
        redraw = [n for n in FIGURES if n != "worst_cases"]
        output.start_from_existing(
            lambda rel: rel != "report.html" and not (rel.startswith("figures/") and Path(rel).stem in redraw)
        )
        tmp = output.staging
        figures = report_figures(tmp, spec, summary, runs, names=redraw)
        if (tmp / "figures" / "worst_cases.png").is_file():
            figures = ordered_figures(figure_entries(tmp, spec, ["worst_cases"]), figures)
        write_report(tmp, spec, summary, runs, figures=figures)
        return output.commit()
