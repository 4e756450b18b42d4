"""Work in a background thread beside the main one: a study's side jobs
(:class:`pfjax.montecarlo.side_jobs.SideJobs`), the paper reproduction's GA readings.

XLA's compiler and the compiled programs release Python's GIL, so a background thread's compiling
and simulating use the core that the main thread's single-threaded work (tracing, sampling,
writing files) leaves idle. A background task runs on one device (:func:`last_device`) and never
launches a program that spans several: two threads launching such programs can interleave them
differently on each device and deadlock XLA's CPU rendezvous (seen: the process aborted). The
calling thread takes over the tasks the background thread has not started
(:meth:`Background.take_over`), so whichever thread is free works.
"""

from __future__ import annotations

import jax

__all__ = ["Background", "Deferred", "Stealable", "last_device"]


def last_device():
    """The device a background task runs on: the last local one. Only the main thread launches
    programs that span several devices (module docstring). A background task waits for each of
    its programs before it launches the next (the worst-case search's gradient steps and the GA's
    generations do), so a main-thread program waits for that device at most one such program."""
    return jax.local_devices()[-1]


class Background:
    """One background thread (``overlap=True``) whose queued tasks the calling thread can take
    over (:class:`Stealable`); with ``overlap=False`` each task is computed in the calling thread
    when its result is first asked for (:class:`Deferred`)."""

    def __init__(self, name: str, *, overlap: bool = True):
        from concurrent.futures import ThreadPoolExecutor

        self._pool = ThreadPoolExecutor(1, thread_name_prefix=name) if overlap else None
        self._queued: list = []  # tasks the calling thread may take over, in submission order

    def submit(self, fn) -> Stealable | Deferred:
        """``fn()`` queued on the background thread (or deferred)."""
        if self._pool is None:
            return Deferred(fn)
        job = Stealable(self._pool.submit(fn), fn)
        self._queued.append(job)
        return job

    def take_over(self) -> None:
        """Compute here every task the background thread has not started, the latest first."""
        for job in reversed(self._queued):
            job.take_over()

    def close(self) -> None:
        """Cancel the tasks not yet started (the running one finishes)."""
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)


class Stealable:
    """A task submitted to the background thread that the calling thread can take over."""

    def __init__(self, future, fn):
        self._future, self._fn = future, fn

    def take_over(self) -> None:
        """Compute the task here, now, if the background thread has not started it."""
        if not isinstance(self._future, Deferred) and self._future.cancel():
            self._future = Deferred(self._fn)
            self._future.result()

    def result(self):
        self.take_over()
        return self._future.result()


class Deferred:
    """A task computed in the calling thread when its result is first asked for."""

    def __init__(self, fn):
        self._fn, self._done, self._value = fn, False, None

    def result(self):
        if not self._done:
            self._value, self._done = self._fn(), True
        return self._value
