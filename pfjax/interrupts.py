"""Ctrl-C in pfjax's commands, never lost.

Python runs a SIGINT handler in the main thread between two bytecodes, and the
``KeyboardInterrupt`` it raises is printed and dropped (:data:`sys.unraisablehook`) when that
moment falls inside a garbage-collector callback (JAX registers one), a ``__del__`` method or a
weakref callback: the command would then run on to its end and exit 0. :func:`guard`, around a
command's body (:func:`pfjax.errors.command_main`), takes such a dropped ``KeyboardInterrupt``
from the unraisable hook, prints nothing for it, and sends SIGINT again 50 ms later, from a timer
thread, so that it arrives in ordinary code; it also remembers every SIGINT for
:func:`stop_if_interrupted`, which a study calls before each chunk (a backstop: the study stops
at the next chunk, resumable). Once the command ends, nothing is sent again and nothing is
remembered, so code after it (the Python API) never sees a late interrupt.

SIGTERM (a batch system's time limit, ``kill``) stops a command as Ctrl-C does, where the process
has Python's default SIGTERM action: within :func:`guard` it raises :class:`Terminated`, a
``KeyboardInterrupt``, so the same clean-up runs (the staging directory removed, the lock released,
a study's finished chunks kept for the resume) and the command exits 143 instead of being killed.
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import sys
import threading

#: Delay of the second SIGINT after one was dropped, s.
RESEND_S = 0.05


class Terminated(KeyboardInterrupt):
    """SIGTERM within a command (:func:`guard`): handled as Ctrl-C is, told apart by its type."""


class _Command:
    """The running command's interrupt state."""

    def __init__(self):
        self.interrupted = False  # a SIGINT arrived
        self.closing = False  # the command is ending: nothing more is sent or raised
        self.timer: threading.Timer | None = None
        self.signal = signal.SIGINT  # the last signal that stopped it: sent again if dropped
        self.written: str | None = None  # the output it put in place (:func:`wrote`)
        self.nested = 0  # commands run inside it (their guards take no effect): their outputs are theirs


_running: _Command | None = None


@contextlib.contextmanager
def guard():
    """Within: SIGINT raises ``KeyboardInterrupt`` as usual, is remembered, and is sent again if
    Python dropped its exception (module docstring). Takes effect only in the main thread, with
    Python's default SIGINT handler installed and no command already guarded; elsewhere it changes
    nothing. Yields the command's state (what :func:`wrote` recorded is its ``written``), or None
    where it takes no effect."""
    global _running
    if (
        _running is not None
        or threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        outer = _running
        if outer is not None:
            outer.nested += 1
        try:
            yield None
        finally:
            if outer is not None:
                outer.nested -= 1
        return
    cmd = _running = _Command()
    hook = sys.unraisablehook
    sys.unraisablehook = functools.partial(_unraisable, cmd, hook)
    signal.signal(signal.SIGINT, _on_sigint)
    term = signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # else the process's own handler stays
    if term:
        signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield cmd
    finally:
        cmd.closing = True
        if cmd.timer is not None:
            cmd.timer.cancel()
            cmd.timer.join()
        # the module's state first, the handlers last (a Ctrl-C while they are put back raises
        # there): signal.signal runs a pending handler first (ours, which ignores it while closing)
        sys.unraisablehook = hook
        _running = None
        handlers = [(signal.SIGTERM, signal.SIG_DFL)] if term else []
        _restore([*handlers, (signal.SIGINT, signal.default_int_handler)])


def _on_sigint(signum, frame):
    """Python's SIGINT handler, remembering the signal; ignored while the command ends."""
    cmd = _running
    if cmd is None or cmd.closing:
        return
    cmd.interrupted, cmd.signal = True, signal.SIGINT
    raise KeyboardInterrupt


def _on_sigterm(signum, frame):
    """SIGTERM within a command: :class:`Terminated`, remembered as SIGINT is; ignored while the
    command ends."""
    cmd = _running
    if cmd is None or cmd.closing:
        return
    cmd.interrupted, cmd.signal = True, signal.SIGTERM
    raise Terminated


def _unraisable(cmd: _Command, hook, unraisable) -> None:
    """The unraisable hook within :func:`guard`: a dropped ``KeyboardInterrupt`` is sent again;
    anything else goes to the previous hook."""
    if not (issubclass(unraisable.exc_type, KeyboardInterrupt) and cmd is _running):
        hook(unraisable)
        return
    if not cmd.closing and (cmd.timer is None or not cmd.timer.is_alive()):
        cmd.timer = threading.Timer(RESEND_S, _send_again, (cmd,))
        cmd.timer.daemon = True
        cmd.timer.start()


def _send_again(cmd: _Command) -> None:
    if not cmd.closing:
        os.kill(os.getpid(), cmd.signal)


def wrote(target) -> None:
    """Tell the running command that its output is in place (:meth:`pfjax.outputs.OutputDir.commit`,
    within :func:`deferred`): a Ctrl-C or SIGTERM held over the final renames and acted on after them
    then says that the output was written, not that nothing was. An output of a command run inside
    it is that command's, not recorded."""
    if _running is not None and _running.nested == 0:
        _running.written = str(target)


def stop_if_interrupted() -> None:
    """Raise ``KeyboardInterrupt`` in the main thread if the running command got SIGINT (module
    docstring: called before each of a study's chunks)."""
    cmd = _running
    if cmd is not None and cmd.interrupted and threading.current_thread() is threading.main_thread():
        raise Terminated if cmd.signal == signal.SIGTERM else KeyboardInterrupt


@contextlib.contextmanager
def deferred():
    """Within: SIGINT and SIGTERM are held, not acted on, and delivered once the block has run
    (to the handlers in place before it), so that a few steps that must not be split (an output's
    two final renames) run whole. In the main thread only (where Python runs signal handlers);
    elsewhere it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    # a handler installed outside Python (getsignal gives None) cannot be put back: left as it is
    before = {k: h for k in (signal.SIGINT, signal.SIGTERM) if (h := signal.getsignal(k)) is not None}
    for k in before:
        signal.signal(k, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        _restore(list(before.items()))
        for k in dict.fromkeys(held):
            signal.raise_signal(k)


def _restore(handlers: list) -> None:
    """Put ``handlers`` (signal, handler) back, each even if a signal that arrives while the one
    before is put back raises in its handler (a Ctrl-C there): none stays held for good."""
    if handlers:
        try:
            signal.signal(*handlers[0])
        finally:
            _restore(handlers[1:])


def finished(code):
    """``code``, with Ctrl-C ignored from now on, for a process whose command has ended (its outputs
    written, its result printed): a late interrupt then neither breaks into the exit handlers (JAX's
    runtime teardown, with a traceback) nor turns a finished run's exit code into 130. The ``pfjax``
    console script and the study scripts call it as their process ends; the Python API never does.
    In the main thread only (elsewhere it changes nothing). SIGTERM keeps its action: it still ends
    a process that waits in its exit handlers (a multi-process study's shutdown barrier)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


__all__ = ["RESEND_S", "Terminated", "deferred", "finished", "guard", "stop_if_interrupted", "wrote"]
