"""Draw a study's report figures in a second process while the study goes on.

Matplotlib holds the GIL while it builds and rasterises a figure, so figures drawn in a thread
of the study's process run one after another with the study's own Python work (measured: the
default study's seven figures take 8-10 s, and threads gave no speed-up). A
:class:`FigureWorker` is a child Python process (``python -m pfjax.report.figure_worker``)
that imports matplotlib and pandas while the study simulates (about 2 s of CPU, without JAX) and
then draws the figures it is asked for, alongside the study. A study
(:func:`pfjax.montecarlo.study.run`) asks for the figures that need only the runs
(``runs.parquet``) as soon as the runs are written, for the worst-case figure as soon as the
worst-case search has finished (from whichever thread finishes it), and for those that need only
the summary once it exists; it draws the slip map itself (its prediction is a JAX program).
Requests may come from several threads and their results be collected in any order.
The worker runs at the study's priority: a lower one (``nice 10``) starved it while the study's
two threads kept both cores busy, so it drew everything at the end (measured: report 8-10 s).

Protocol: the parent writes one line per request to the child's stdin, the path of a pickled
request ``(out_dir, spec, summary, runs_path, names, worst_trajectories)``; the child renders with
:func:`pfjax.report.figure_set.report_figures` into ``out_dir/figures`` and answers with one
JSON line per request, in order: ``{"ok": true, "names": [...]}`` or ``{"ok": false, "error": ...}``.
The figures themselves are the files; the parent reads the PNGs back for the report.

Failures: if the child cannot start, dies, or a request fails, :meth:`FigureRequest.result`
warns once (one line, naming the reason) and draws the figures in the study's process instead,
so a report never depends on the worker. Figures are the same either way (same code and data;
PNG files byte-identical, tests/test_study_report.py). ``PFJAX_FIGURE_WORKER=0`` turns the
worker off (figures in the study's process).
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import tempfile
import threading
import warnings
from pathlib import Path
from typing import IO

#: Environment variable: ``0`` draws every figure in the study's process.
ENV = "PFJAX_FIGURE_WORKER"
#: The request directories' name prefix in the system's temporary directory (then the owner's pid).
TMP_PREFIX = "pfjax-figures-"


def remove_stale_dirs() -> None:
    """Remove request directories whose owning process has ended (a study killed before it could
    remove its own): ``<tmp>/pfjax-figures-<pid>-*`` with no process ``pid``, and only those
    pfjax marked as its own (:func:`pfjax.outputs.is_temporary`)."""
    import shutil

    from pfjax.outputs import is_temporary

    for d in Path(tempfile.gettempdir()).glob(f"{TMP_PREFIX}*-*"):
        pid = d.name[len(TMP_PREFIX) :].split("-", 1)[0]
        if not pid.isdigit() or int(pid) == os.getpid() or not is_temporary(d):
            continue
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(d, ignore_errors=True)
        except OSError:  # alive, someone else's
            pass


def enabled(environ=None) -> bool:
    """Whether studies use a figure worker (``PFJAX_FIGURE_WORKER`` is not ``0``)."""
    return (os.environ if environ is None else environ).get(ENV, "1").strip() != "0"


def _pipe(stream: IO[str] | None) -> IO[str]:
    """A pipe of the child (opened with ``subprocess.PIPE``, so never None)."""
    if stream is None:
        raise RuntimeError("figure worker: pipe not open")
    return stream


class FigureRequest:
    """Figures asked of a :class:`FigureWorker`; :meth:`result` waits for them."""

    def __init__(self, worker: FigureWorker, args: tuple, sent: bool):
        self._worker, self._args, self._sent = worker, args, sent
        self._value: dict[str, dict] | None = None
        self._answer: dict | None = None  # the child's JSON answer, once read

    def result(self) -> dict[str, dict]:
        """``{name: {"name", "caption", "b64"}}`` as :func:`~pfjax.report.figure_set.report_figures`."""
        if self._value is None:
            self._value = self._worker._collect(self) if self._sent else None
            if self._value is None:  # worker unavailable or failed: draw here
                self._value = _render_here(*self._args)
        return self._value


class FigureWorker:
    """A child process that draws report figures (module docstring). Use as a context manager or
    call :meth:`close`. Requests may be submitted and their results asked for from several threads,
    in any order."""

    def __init__(self, *, python: str = sys.executable):
        self._lock = threading.RLock()  # the pipes, the request count and the pending list
        self._pending: list[FigureRequest] = []
        from pfjax.outputs import mark_temporary

        remove_stale_dirs()
        self._tmp = mark_temporary(Path(tempfile.mkdtemp(prefix=f"{TMP_PREFIX}{os.getpid()}-")))
        self._count = 0
        self._warned = False
        env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONUNBUFFERED": "1"}
        self._stderr = open(self._tmp / "stderr.txt", "w+")  # noqa: SIM115  (held for the child's life, closed in close())
        self._proc: subprocess.Popen[str] | None
        try:
            self._proc = subprocess.Popen(
                [python, "-m", "pfjax.report.figure_worker"],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=self._stderr,
                text=True,
                env=env,
            )
        except OSError as e:
            self._proc = None
            self._warn(f"could not start ({e})")

    def submit(
        self, out_dir: Path, spec, summary: dict, runs_path: Path, names, worst_trajectories: dict | None = None
    ) -> FigureRequest:
        """Ask for figures ``names`` (of :data:`~pfjax.report.figure_set.FIGURES`); returns at once.
        Arguments as :func:`~pfjax.report.figure_set.report_figures`, with the run table's file."""
        args = (Path(out_dir).resolve(), spec, summary, Path(runs_path).resolve(), list(names), worst_trajectories)
        sent = False
        with self._lock:
            if self._proc is not None and self._proc.poll() is not None:
                self._died()
            if self._proc is not None:
                self._count += 1
                req = self._tmp / f"request-{self._count}.pkl"
                req.write_bytes(pickle.dumps(args))
                try:
                    stdin = _pipe(self._proc.stdin)
                    stdin.write(f"{req}\n")
                    stdin.flush()
                    sent = True
                except OSError:  # the pipe broke: the child has exited
                    self._died()
            request = FigureRequest(self, args, sent)
            if sent:
                self._pending.append(request)
        return request

    def _collect(self, request: FigureRequest) -> dict | None:
        """Read the child's answers up to ``request``'s (keeping the earlier requests' answers for
        their own :meth:`FigureRequest.result`); None if the child failed it or died first."""
        with self._lock:
            while request in self._pending:
                head = self._pending.pop(0)
                if self._proc is None:
                    return None
                line = _pipe(self._proc.stdout).readline()
                if not line:
                    self._died()
                    return None
                answer_of_head: dict = json.loads(line)
                head._answer = answer_of_head
                if not answer_of_head.get("ok"):
                    self._warn(f"failed: {answer_of_head.get('error')}")
        answer = request._answer
        if answer is None or not answer.get("ok"):
            return None
        from pfjax.report.figure_set import figure_entries

        return figure_entries(request._args[0], request._args[1], answer["names"])

    def _died(self) -> None:
        """The child has exited: warn with its exit code and last line of stderr; forget its requests."""
        if self._proc is None:
            return
        self._stderr.seek(0)
        err = self._stderr.read().strip().splitlines()
        self._warn(f"exited with code {self._proc.wait()}" + (f": {err[-1]}" if err else ""))
        for pipe in (self._proc.stdin, self._proc.stdout):
            try:
                _pipe(pipe).close()
            except OSError:
                pass
        self._proc = None
        self._pending.clear()

    def _warn(self, why: str) -> None:
        if not self._warned:
            warnings.warn(
                f"pfjax figure worker {why}; drawing the figures in this process", RuntimeWarning, stacklevel=3
            )
            self._warned = True

    def close(self) -> None:
        """Let the child finish its requests and exit; remove its request files."""
        with self._lock:
            if self._proc is not None:
                try:
                    _pipe(self._proc.stdin).close()
                except OSError:
                    pass
                try:
                    self._proc.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    self._proc.kill()
                    self._proc.wait()
                _pipe(self._proc.stdout).close()
                self._proc = None
            self._stderr.close()
            for f in self._tmp.glob("*"):
                f.unlink()
            self._tmp.rmdir()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _render_here(
    out_dir: Path, spec, summary: dict, runs_path: Path, names, worst_trajectories=None
) -> dict[str, dict]:
    import pandas as pd

    from pfjax.report.figure_set import NEEDS_RUNS, report_figures

    runs = pd.read_parquet(runs_path) if set(names) & NEEDS_RUNS else None
    return report_figures(out_dir, spec, summary, runs, worst_trajectories, names=names)


def main() -> None:
    """The child: answer each request line on stdin (module docstring) until stdin closes. Ctrl-C
    is the parent's to handle (it closes stdin): the child ignores SIGINT."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import matplotlib

    matplotlib.use("Agg")
    import pyarrow.parquet  # noqa: F401  (the imports now, while the parent simulates)

    from pfjax.report import figure_set  # noqa: F401

    for line in sys.stdin:
        try:
            done = _render_here(*pickle.loads(Path(line.strip()).read_bytes()))
            msg = {"ok": True, "names": list(done)}
        except Exception as e:  # reported to the parent, which draws the figures itself
            msg = {"ok": False, "error": f"{type(e).__name__}: {e}"}
        sys.stdout.write(json.dumps(msg) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
