"""One writer at a time for an output directory (:mod:`pfjax.outputs`): an exclusive
``fcntl.flock`` on the lock file ``.<name>.lock`` beside the target, recording the holder's pid,
host, command and start time; the operating system releases it when the process ends."""

from __future__ import annotations

import datetime as _dt
import json
import os
import socket
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
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
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
            info = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command, "started": now_utc()}
            os.ftruncate(fd, 0)
            os.write(fd, (json.dumps(info) + "\n").encode())
            self._fd = fd

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
