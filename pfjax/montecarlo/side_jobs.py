"""The Monte Carlo study's side jobs, computed beside the runs: the worst-case searches, the
float64 re-simulation and the worst-case figure (asked of the figure worker by whichever thread
finishes the last search); a background thread starts them, and the main thread takes over those
not started yet once it has nothing else to do."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import jax

from pfjax.background import Background, last_device
from pfjax.montecarlo.config import StudySpec
from pfjax.report import figure_worker

__all__ = ["SideJobs", "WorstFigure"]


class SideJobs:
    """The parts of a study that do not depend on its runs: the worst-case search (one task per
    controller) and the float64 re-simulation (one task per path).

    With ``overlap=True`` they run in one background thread (:class:`pfjax.background.Background`,
    on the last local device; why one device: :mod:`pfjax.background`) while the main thread
    simulates the runs and the margin sweep. Every task computes exactly what it computes alone
    (its own PRNG streams, its own precision context, which JAX keeps per thread), so the results
    do not depend on ``overlap`` (tests/test_montecarlo.py). With ``overlap=False`` each task runs
    in the main thread when its result is first asked for.

    The tasks see the study's controllers as one, their union (:func:`pfjax.controllers.union.shared`):
    each searches and re-simulates its own controller, selected by its parameters, and the search's
    gradient step, the random search, the replay and the float64 simulation are each compiled once
    for the study instead of once per controller kind. The study's runs keep a program per kind (a
    batch of one kind runs that kind's code alone).

    When the main thread asks for a result, it first takes over every task the background thread
    has not started (the latest first; the background thread works from the front), the same
    function on the same device, so the same result: the study does not wait for a queue that one
    thread would work through alone.
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
        from pfjax.controllers.union import shared
        from pfjax.montecarlo.checks import float64_runs
        from pfjax.montecarlo.runner import precision
        from pfjax.montecarlo.worst_case import worst_case

        self.seconds = {"worst_case": 0.0, "float64_check": 0.0}
        self._thread = Background("pfjax-study", overlap=overlap)
        device = last_device()

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

            return self._thread.submit(timed)

        # first, as the report needs it soonest: compile the slip map's linearised prediction (1-2 s),
        # with JAX's default device as the report has it, so that the report's call finds it compiled
        self.report_warmup = None
        if report:
            from pfjax.report.figure_set import warm_predictions

            self.report_warmup = task(
                "report_warmup", warm_predictions, spec, {k: v[2] for k, v in controllers.items()}, pinned=False
            )
        # one controller for all (their union): one program per search and check, not one per kind
        searched = shared(controllers)
        self.worst_figure = WorstFigure(worker, spec, list(controllers)) if report and spec.falsifier.enabled else None
        found = (lambda name, value: value) if self.worst_figure is None else self.worst_figure.found
        self.worst = (
            {
                name: task("worst_case", lambda *a, name=name, **k: found(name, worst_case(*a, **k)), spec, searched, i)
                for i, name in enumerate(controllers)
            }
            if spec.falsifier.enabled
            else {}
        )
        checked = spec.dtype != "float64" and spec.f64_check_runs > 0
        self.float64 = (
            [
                task("float64_check", float64_runs, spec, searched, spec.f64_check_runs, p)
                for p in range(len(spec.paths))
            ]
            if checked
            else None
        )

    def take_over(self) -> None:
        """Compute here every task the background thread has not started, the latest first."""
        self._thread.take_over()

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
        self._thread.close()


class WorstFigure:
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
