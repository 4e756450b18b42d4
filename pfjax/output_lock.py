"""One writer at a time for an output directory (:mod:`pfjax.outputs`): an exclusive
``fcntl.flock`` on the lock file ``.<name>.lock`` beside the target, recording the holder's pid,
host, command and start time; the operating system releases it when the process ends.

Only pfjax's own lock file is used, written and removed: it appears at its name locked and with
its record already in it (on a file system without hard links it is created empty and locked at
once, and an empty file is looked at again for :data:`EMPTY_WAITS` x :data:`EMPTY_WAIT_S`); a
symbolic link (never followed), a directory or a file that does not hold a whole lock record
(:data:`RECORD_KEYS`) at that name is refused (:class:`~pfjax.errors.InputError` naming the flag),
and left as it is. On a file system without hard links, a pfjax killed in the instant between
creating its lock file and writing its record leaves an empty file, which is then refused so too."""

from __future__ import annotations

import datetime as _dt
import errno
import json
import os
import socket
import stat
import time
from pathlib import Path

from pfjax.errors import InputError

__all__ = ["OutputBusy", "OutputLock", "now_utc", "sibling"]


#: An empty file at the lock's name is looked at again this many times, this far apart (s), before
#: it is taken for something pfjax did not write: on a file system without hard links another
#: pfjax creates its lock file empty and locks it an instant later.
EMPTY_WAITS, EMPTY_WAIT_S = 20, 0.01

#: What a lock file holds: the holder's pid, host, command and start time (UTC, ISO 8601).
RECORD_KEYS = frozenset({"pid", "host", "command", "started"})


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

        waits = 0
        while self._fd is None:
            created, fd = self._create()
            if fd is None:  # the name is taken: a lock file of another pfjax process, or not pfjax's
                try:  # O_NOFOLLOW: a link at the lock's name is refused, not followed
                    fd = os.open(self.path, os.O_RDWR | getattr(os, "O_NOFOLLOW", 0))
                except FileNotFoundError:  # removed by its holder meanwhile: try again
                    continue
                except OSError as e:
                    if e.errno in (errno.ELOOP, errno.EISDIR):
                        raise self._foreign() from None
                    raise self._cannot(e) from None
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
            if not created and not self._is_lock_record(fd):
                empty = os.fstat(fd).st_size == 0
                os.close(fd)
                if empty and waits < EMPTY_WAITS:  # another pfjax's, between its create and its lock
                    waits += 1
                    time.sleep(EMPTY_WAIT_S)
                    continue
                raise self._foreign()
            if not created:  # a lock file left by a writer that was killed: this process's record now
                os.ftruncate(fd, 0)
                os.lseek(fd, 0, os.SEEK_SET)
                os.write(fd, self._record())
            self._fd = fd

    def _record(self) -> bytes:
        info = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command, "started": now_utc()}
        return (json.dumps(info) + "\n").encode()

    def _create(self) -> tuple[bool, int | None]:
        """``(True, fd)`` of a new lock file holding this process's record, or ``(False, None)``
        when the name is taken. The file appears at its name locked and with the record already in
        it (written and locked under a temporary name, then hard-linked, which fails when the name
        exists), so a lock file is never free and empty: only a file with a whole record is ever
        taken over or removed. On a file system without hard links, created in place (``O_EXCL``),
        locked and written at once (another process that opens it between the two finds it held)."""
        import fcntl

        tmp = self.path.with_name(f"{self.path.name}.{os.getpid()}.{id(self):x}.tmp")
        try:
            fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
        except OSError as e:
            raise self._cannot(e) from None
        try:  # locked before its name appears: another process finds it held, never free and empty
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.write(fd, self._record())
            try:
                os.link(tmp, self.path)
            except FileExistsError:
                os.close(fd)
                return False, None
            except OSError:  # no hard links here
                os.close(fd)
                try:
                    fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o644)
                except FileExistsError:
                    return False, None
                # at once, waiting out another pfjax that opened it meanwhile and is letting it go
                # (an empty file is not a record: it closes it, EMPTY_WAITS)
                fcntl.flock(fd, fcntl.LOCK_EX)
                os.write(fd, self._record())
            return True, fd
        finally:
            tmp.unlink(missing_ok=True)

    def _cannot(self, e: OSError) -> InputError:
        return InputError(f"{self.flag}: cannot create pfjax's lock file {self.path}: {e.strerror}", self.flag)

    def _foreign(self) -> InputError:
        return InputError(
            f"{self.flag}: {self.path} (the name of pfjax's lock file for {self.target}) is taken by "
            f"something pfjax did not write; move it away",
            self.flag,
        )

    @staticmethod
    def _is_lock_record(fd: int) -> bool:
        """Whether the file holds the record a lock holder writes: a JSON object with its ``pid``,
        ``host``, ``command`` and ``started`` (anything else, an empty file included, is not pfjax's)."""
        os.lseek(fd, 0, os.SEEK_SET)
        text = os.read(fd, 4097)
        try:
            data = json.loads(text.decode())
        except (UnicodeDecodeError, ValueError):
            return False
        return isinstance(data, dict) and data.keys() >= RECORD_KEYS and len(text) <= 4096

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
