"""``pfjax study``: load and validate a study, run it, write runs, margin sweep, summary and report.

Outputs under ``results/<name>/`` (or ``--out``), assembled in a temporary directory and moved
into place only when complete: ``runs.parquet`` (one row per run), ``margin.parquet`` (the
slip-margin sweep), ``summary.json`` (strict JSON) and, unless disabled, ``report.md`` and ``report.html`` with
``figures/*.png|svg``.
"""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.runner import margin_sweep, run_study
from pfjax.montecarlo.side_jobs import SideJobs
from pfjax.montecarlo.summary import missing_key, summarize
from pfjax.report import figure_worker

ROOT = Path(__file__).resolve().parents[2]
#: Report figures drawn by the figure worker (:mod:`pfjax.report.figure_worker`) when there is
#: one: those that need only the runs, asked for as soon as the runs are written, the worst-case
#: figure (3-4 s), asked for by whichever thread finishes the last worst-case search
#: (:class:`WorstFigure`), and those that need only the summary (2.9 s of drawing on the default
#: study). The main thread draws the slip map (its prediction is a JAX program) and meanwhile
#: computes the side jobs the background thread has not started.
RUN_FIGURES = ["dist_iae", "dist_late_max_abs_d"]
WORKER_SUMMARY_FIGURES = ["headline", "margin_curves", "success_by_param"]
#: The phases of ``timings_s`` in summary.json (main-thread wall clock, s).
PHASES = ("runs", "margin", "worst_case", "rare_event", "float64_check", "summary", "report")


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
    from pfjax.montecarlo.runner import controllers_of, study_output
    from pfjax.outputs import OutputDir

    check_resources(spec, report=report)  # before anything is written or allocated
    if spec.rare_event.enabled:
        from pfjax.rare.study import check_budget

        check_budget(spec)  # the rare-event estimates' budget, before the runs
    output = out if isinstance(out, OutputDir) else study_output(spec, out, overwrite=overwrite)
    if controllers is None and not distributed:  # a design that fails stops here, before --out is made
        controllers = controllers_of(spec)
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
    from pfjax.montecarlo.checks import study_warnings
    from pfjax.montecarlo.runner import controllers_of

    t0 = time.time()
    result: dict = {}
    warnings = study_warnings(spec)
    for w in warnings:
        (warn or (lambda m: None))(w)
    controllers = controllers_of(spec) if controllers is None else controllers
    side = SideJobs(spec, controllers, overlap=overlap, report=report, worker=worker)
    job = dict(spec=spec, side=side, worker=worker, report=report, progress=progress, t0=t0)
    job.update(warnings=warnings, overlap=overlap, result=result)

    try:
        run_study(
            spec,
            output,
            progress=progress,
            extra=functools.partial(_finish, job=job),
            fresh=fresh,
            controllers=controllers,
        )
    finally:
        side.close()
    return result["summary"]


def _finish(tmp: Path, runs_path: Path, controllers, store, *, job: dict) -> dict:
    """After the runs: the margin sweep, the summary, the side jobs' results, the figures and the
    report, and ``summary.json``, in ``tmp`` (``job``: the study's settings and side jobs, and
    ``job["result"]`` receives the summary)."""
    from pfjax.jsonio import dumps
    from pfjax.montecarlo.checks import float64_check

    spec, side, worker, report, progress = job["spec"], job["side"], job["worker"], job["report"], job["progress"]
    t0, warnings, overlap = job["t0"], job["warnings"], job["overlap"]
    timings = {"runs": time.time() - t0}  # s per phase (wall clock), in summary.json
    lap = [time.time()]
    early = _start_figures(job, tmp, runs_path)

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
        _add_rare_events(spec, controllers, summary, progress, runs_path)
        mark("rare_event")
    if report:
        worst_figure = side.worst_figure.result() if side.worst_figure is not None else None
        if worst_figure is None:
            worst_figure = report_figures(tmp, spec, summary, runs, worst_traj, names=["worst_cases"])
        figures = ordered_figures(worst_figure, figures, *(part.result() for part in parts))
        mark("report")
    summary["float64_check"] = float64_check(
        spec, controllers, _check_rows(spec, runs, runs_path), spec.f64_check_runs, sims=side.float64_runs()
    )
    mark("float64_check")
    # the study's wall time: everything but writing the report out, so that the report (and
    # `pfjax report`, re-rendering it) shows the same number as summary.json
    summary["wall_s"] = time.time() - t0
    if report:
        write_report(tmp, spec, summary, runs, worst_traj, figures=figures)
        mark("report")
    timings = {k: timings[k] for k in PHASES if k in timings}
    # and the side jobs' own compute time (in the background thread when overlapped with the runs)
    summary["timings_s"] = {**timings, "side_jobs": {**side.seconds, "overlapped": overlap}}
    (tmp / "summary.json").write_text(dumps(summary) + "\n")
    job["result"]["summary"] = summary
    return {}


def _start_figures(job: dict, tmp: Path, runs_path: Path):
    """Ask the figure worker for the figures of the runs alone (drawn during the margin sweep), and
    for the worst-case figure now if the search is done, else when it is; the run figures' answer."""
    spec, side, worker = job["spec"], job["side"], job["worker"]
    early = (
        worker.submit(tmp, spec, {"paths": [p.label for p in spec.paths]}, runs_path, RUN_FIGURES)
        if worker is not None
        else None
    )
    if side.worst_figure is not None:
        side.worst_figure.start(tmp, runs_path)
    return early


def _add_rare_events(spec: StudySpec, controllers, summary: dict, progress, runs_path: Path) -> None:
    """Each controller's rare-event failure estimate (:mod:`pfjax.rare`) into its summary block,
    beside the share of the study's own runs that fail by the same event (``plain_fail``, with its
    Clopper-Pearson ``plain_fail_ci95``): a run that failed, or whose ``rare_event.metric`` passes
    the threshold (``rare_event.threshold``, else ``success.band``): the limit state's own test,
    :func:`pfjax.rare.study.margins`. The run table is read one controller at a time."""
    from pfjax.metrics.robustness import clopper_pearson
    from pfjax.rare.study import estimate_study, failure_threshold, margins

    rare = spec.rare_event
    threshold = failure_threshold(rare.model_dump(), spec.success.band)
    for name, est in estimate_study(spec, controllers, progress=progress).items():
        runs = read_runs(runs_path, columns=["status_code", rare.metric], filters=[("controller", "==", name)])
        k, n = int(np.sum(margins(runs["status_code"], runs[rare.metric], threshold) <= 0)), len(runs)
        summary["controllers"][name].update(
            p_fail=est["p_fail"],
            p_fail_ci95=est["ci95"],
            rel_error=est["rel_error"],
            n_rollouts=est["n_rollouts"],
            method=est["method"],
            plain_fail=k / n if n else None,
            plain_fail_ci95=list(clopper_pearson(k, n)) if n else None,
            rare_event=est,
        )


def _check_rows(spec: StudySpec, runs: pd.DataFrame | None, runs_path: Path) -> pd.DataFrame | None:
    """The rows the float64 check compares: the whole run table if loaded, else only its sampled runs."""
    from pfjax.montecarlo.checks import sample_indices

    if runs is not None or spec.dtype == "float64" or spec.f64_check_runs <= 0:
        return runs
    return read_runs(runs_path, filters=[("run", "in", sample_indices(spec, spec.f64_check_runs).tolist())])


def read_runs(path: Path, **kw) -> pd.DataFrame:
    """``runs.parquet`` as a DataFrame (pandas >= 3 keeps the string columns Arrow-backed, a few
    bytes per run); ``kw`` go to :func:`pandas.read_parquet` (``columns``, ``filters``)."""
    return pd.read_parquet(path, **kw)


def read_finished(out, flag: str = "--out") -> tuple[dict, pd.DataFrame]:
    """A finished study's ``(summary, runs)`` from its output directory;
    :class:`~pfjax.errors.InputError` naming ``flag`` (one line) if a file is missing or corrupt."""
    import json

    from pfjax.errors import InputError, one_line

    out = Path(out)

    def load(name, reader):
        f = out / name
        if not f.is_file():
            raise InputError(f"{flag}: {f} is missing; re-run the study (pfjax study CONFIG --out {out})", flag)
        try:
            return reader(f)
        except (OSError, ValueError, UnicodeDecodeError) as e:  # pyarrow's errors are ValueErrors too
            raise InputError(f"{flag}: {f} cannot be read ({one_line(e)}); re-run the study", flag) from None

    summary = load("summary.json", lambda f: json.loads(f.read_text(encoding="utf-8")))
    key = missing_key(summary)
    if key is not None:
        what = f" (no {key})" if key else ""
        raise InputError(f"{flag}: {out / 'summary.json'} is not a study summary{what}; re-run the study", flag)
    return summary, load("runs.parquet", read_runs)


def _unchanged_inputs(out: Path, flag: str = "--out", reader: str = "a report is built from") -> None:
    """:class:`~pfjax.errors.InputError` naming ``flag`` if a file the report is built from
    (``summary.json``, ``runs.parquet``, ``margin.parquet``) is missing or changed after the study wrote it
    (:func:`pfjax.outputs.as_written`: its size or contents differ from the output marker's; a copy
    with new times is unchanged): a report follows from the study's own
    files, and ``--overwrite`` would otherwise record the edited file as pfjax's. ``reader``: who
    reads them, in the message (``pfjax.load_study reads``)."""
    from pfjax.errors import InputError
    from pfjax.outputs import as_written, read_marker

    listed = (read_marker(out) or {}).get("files", {})
    for name in ("summary.json", "runs.parquet", "margin.parquet"):
        f = out / name
        if name in listed and not f.exists():
            raise InputError(
                f"{flag}: {f} is missing (the study wrote it); {reader} the study's own files: re-run the study",
                flag,
            )
        if f.is_file() and not as_written(listed, name, f.stat(), f):
            how = "changed after the study wrote it" if name in listed else "was not written by the study"
            raise InputError(f"{flag}: {f} {how}; {reader} the study's own files: re-run the study", flag)


def study_marker(out, flag: str = "--out", run_first: str = "run the study first") -> dict:
    """The output marker of the finished study in ``out``; :class:`~pfjax.errors.InputError` naming
    ``flag`` where ``out`` holds none (no marker of ``pfjax study``: nothing there, or another
    command's output), its advice ``run_first``."""
    from pfjax.errors import InputError
    from pfjax.outputs import MARKER, read_marker

    out = Path(out)
    marker = read_marker(out) if out.is_dir() else None
    if marker is None or marker.get("command") != "study":
        what = f"no {MARKER} of pfjax study" if marker is None else f"the output of pfjax {marker.get('command')}"
        raise InputError(f"{flag}: no finished study in {out} ({what}); {run_first}", flag)
    return marker


def read_study(
    out, flag: str = "--out", reader: str = "a report is built from"
) -> tuple[dict, pd.DataFrame, pd.DataFrame | None]:
    """A finished study's ``(summary, runs, margin)`` from its output directory, as the study wrote
    them (``margin`` None without a slip-margin sweep); :class:`~pfjax.errors.InputError` naming
    ``flag`` (one line) where ``out`` holds no output of ``pfjax study`` (its marker), or a file is
    missing, changed since the study wrote it (:func:`_unchanged_inputs`) or unreadable. What
    ``pfjax report`` and :func:`pfjax.load_study` read."""
    from pfjax.errors import InputError, one_line

    out = Path(out)
    study_marker(out, flag)
    _unchanged_inputs(out, flag, reader)
    summary, runs = read_finished(out, flag)
    margin = None
    if (out / "margin.parquet").is_file():
        try:
            margin = pd.read_parquet(out / "margin.parquet")
        except (OSError, ValueError) as e:  # pyarrow's errors are ValueErrors too
            raise InputError(
                f"{flag}: {out / 'margin.parquet'} cannot be read ({one_line(e)}); re-run the study", flag
            ) from None
    return summary, runs, margin


def rewrite_report(out, spec: StudySpec, *, overwrite: bool = False) -> Path:
    """Render the report of the finished study in ``out`` again (``pfjax report``), without
    simulating: the figures that need only the summary and runs are redrawn, the worst-case figure
    (which needs the search's trajectories) is kept. The output is replaced whole, as a study's
    (:class:`~pfjax.outputs.OutputDir`); returns its directory."""
    from pfjax.montecarlo.runner import study_output, study_target
    from pfjax.outputs import read_marker
    from pfjax.report.figure_set import FIGURES, figure_entries, ordered_figures, report_figures
    from pfjax.report.study_report import write_report

    target = study_target(spec, out)
    marker = None if target.is_symlink() else read_marker(target)
    if marker is not None and marker.get("command") == "study":  # before the output's rules advise --overwrite
        _unchanged_inputs(target)
    output = study_output(spec, out, overwrite=overwrite)
    with output:
        summary, runs, _ = read_study(output.target)  # again, under the output's lock
        redraw = [n for n in FIGURES if n != "worst_cases"]
        output.start_from_existing(
            lambda rel: (
                rel not in ("report.html", "report.md")
                and not (rel.startswith("figures/") and Path(rel).stem in redraw)
            )
        )
        tmp = output.staging
        figures = report_figures(tmp, spec, summary, runs, names=redraw)
        if (tmp / "figures" / "worst_cases.png").is_file():
            figures = ordered_figures(figure_entries(tmp, spec, ["worst_cases"]), figures)
        write_report(tmp, spec, summary, runs, figures=figures)
        return output.commit()
