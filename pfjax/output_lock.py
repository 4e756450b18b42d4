"""One writer at a time for an output directory (:mod:`pfjax.outputs`): an exclusive
``fcntl.flock`` on the lock file ``.<name>.lock`` beside the target, recording the holder's pid,
host, command and start time; the operating system releases it when the process ends.

Only pfjax's own lock file is used, written and removed: a symbolic link (never followed), a
directory or a file that does not hold a lock record (empty, or JSON with the holder's ``pid``) at
that name is refused (:class:`~pfjax.errors.InputError` naming the flag), and left as it is."""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import socket
import stat
from pathlib import Path

from pfjax.errors import InputError

__all__ = ["OutputBusy", "OutputLock", "now_utc", "sibling"]


class OutputBusy(InputError):
    """Another process holds the output's lock (it is writing there now)."""


def sibling(target: Path, kind: str) -> Path:
    """The hidden entry ``.<name>.<kind>`` beside ``target`` (lock file, partial results, staging)."""
    return target.parent / f".{target.name}.{kind}"


def now_utc() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


class OutputLock:
    """An exclusive lock on an output target, held by this process (``fcntl.flock`` on the lock file
    ``.<name>.lock`` beside the target, which records the holder's pid, host, command and start
    time). Released by :meth:`release` or by the end of the process."""

    def __init__(self, target: Path, *, command: str, flag: str = "--out"):
        self.target, self.command, self.flag = Path(target), command, flag
        self.path = sibling(self.target, "lock")
        self._fd: int | None = None

    def acquire(self) -> None:
        import fcntl

        while self._fd is None:
            try:  # O_NOFOLLOW: a link at the lock's name is refused, not followed
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0), 0o644)
            except OSError as e:
                if e.errno in (errno.ELOOP, errno.EISDIR):
                    raise self._foreign() from None
                raise InputError(
                    f"{self.flag}: cannot create pfjax's lock file {self.path}: {e.strerror}", self.flag
                ) from None
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                os.close(fd)
                raise self._foreign()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = self._holder(fd)
                os.close(fd)
                raise OutputBusy(
                    f"{self.flag}: a pfjax {holder.get('command', 'command')} is running into "
                    f"{self.target} (pid {holder.get('pid', '?')} on {holder.get('host', '?')}, started "
                    f"{holder.get('started', '?')}); wait for it to finish, or choose another {self.flag}",
                    self.flag,
                ) from None
            try:  # the file may have been removed by its previous holder after we opened it
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            if not self._is_lock_record(fd):
                os.close(fd)
                raise self._foreign()
            info = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command, "started": now_utc()}
            os.ftruncate(fd, 0)
            os.write(fd, (json.dumps(info) + "\n").encode())
            self._fd = fd

    def _foreign(self) -> InputError:
        return InputError(
            f"{self.flag}: {self.path} (the name of pfjax's lock file for {self.target}) is taken by "
            f"something pfjax did not write; move it away",
            self.flag,
        )

    @staticmethod
    def _is_lock_record(fd: int) -> bool:
        """Whether the file holds what a lock holder writes (or nothing yet)."""
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 4097)
        if not text:
            return True
        try:
            data = json.loads(text.decode())
        except (UnicodeDecodeError, ValueError):
            return False
        return isinstance(data, dict) and "pid" in data and len(text) <= 4096

    @staticmethod
    def _holder(fd: int) -> dict:
        try:
            os.lseek(fd, 0, os.SEEK_SET)
            data = json.loads(os.read(fd, 4096).decode() or "{}")
            return data if isinstance(data, dict) else {}
        except (OSError, ValueError):
            return {}

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            os.unlink(self.path)  # while still held: a waiting process re-checks the inode
        except FileNotFoundError:
            pass
        os.close(self._fd)
        self._fd = None
