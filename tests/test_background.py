"""pfjax.background: a background thread whose unstarted tasks the caller takes over, or tasks
deferred to the caller (overlap off)."""

from __future__ import annotations

import threading

import jax

from pfjax.background import Background, Deferred, Stealable, last_device


def test_the_caller_takes_over_unstarted_tasks_latest_first_and_close_cancels_the_rest():
    started, gate, ran = threading.Event(), threading.Event(), []
    main = threading.main_thread()

    def job(name):
        def fn():
            if name == "first":
                started.set()
                gate.wait(10)
            ran.append((name, threading.current_thread() is main))
            return name

        return fn

    thread = Background("pfjax-test")
    first, second, third = (thread.submit(job(n)) for n in ("first", "second", "third"))
    assert all(isinstance(j, Stealable) for j in (first, second, third))
    assert started.wait(10)
    thread.take_over()  # the background thread is held in the first: the caller computes the others
    assert ran == [("third", True), ("second", True)]
    gate.set()
    assert [j.result() for j in (first, second, third)] == ["first", "second", "third"]
    assert ran[-1] == ("first", False) and len(ran) == 3

    held = threading.Event()
    thread = Background("pfjax-test")
    running = threading.Event()
    busy = thread.submit(lambda: running.set() or held.wait(10))
    assert running.wait(10)
    thread.submit(lambda: ran.append("queued"))
    thread.close()  # cancels the queued task; the running one finishes
    held.set()
    assert busy.result() is True
    assert "queued" not in ran


def test_without_overlap_a_task_runs_in_the_caller_when_first_asked_for():
    ran = []
    thread = Background("pfjax-test", overlap=False)
    job = thread.submit(lambda: ran.append(threading.current_thread() is threading.main_thread()) or len(ran))
    assert isinstance(job, Deferred) and ran == []
    assert job.result() == 1 and job.result() == 1 and ran == [True]
    thread.close()


def test_background_tasks_run_on_the_last_local_device():
    assert last_device() == jax.local_devices()[-1]
