"""Output directories: written whole or not at all, never over anything pfjax did not write.

Every pfjax command and study that writes files (``pfjax study``, ``report``, ``bench``, the
study scripts) writes them through :class:`OutputDir`:

1. **The target is checked before anything is computed or written** (:func:`check_target`):

   - it may not exist yet, or be an empty directory;
   - or it is a directory pfjax wrote: it holds the marker file ``.pfjax-output.json`` (the
     command, config hash, pfjax version, time, and every file pfjax wrote there with its size,
     modification time and SHA-256). It is replaced when it holds the output of the same command
     and config (a re-run); another command's or config's output is replaced only with
     ``overwrite=True`` (``--overwrite``), and so is one whose files changed since pfjax wrote them
     (:func:`as_written`: a file of another size or contents; one copied with new times, by ``cp
     -r`` or an archive, is unchanged);
   - anything else is refused: a file, a symbolic link, a non-empty directory without the marker,
     the current directory or one that contains it, the home directory, a filesystem root, a path
     ending in ``.`` or ``..``, and, even with ``overwrite``, a marked directory that also holds
     files the marker does not list or a symbolic link where it lists a file (pfjax writes no
     links).

   A refusal is an :class:`~pfjax.errors.InputError` naming the flag (``--out``), and nothing is
   touched. A Python function passes its own name for it (``flag="out"``), so its refusals name its
   argument and advise ``pass overwrite=True``, not ``add --overwrite`` (:func:`switch_advice`).
2. **One writer at a time.** The target's lock file ``.<name>.lock`` beside it is held with
   ``fcntl.flock`` for the whole command, so a second process writing to the same target is
   refused (:class:`OutputBusy`, naming the running process's pid and start time). The operating
   system releases the lock when the process ends, however it ends: a killed run never leaves a
   stale lock.
3. **Assembled beside the target, moved into place when complete.** Files are written to a
   private staging directory ``.<name>.pfjax-staging-*`` beside the target (same filesystem),
   the marker is written last, and :meth:`OutputDir.commit` renames it into place, with the mode
   and group of the directory it replaces (``0o777`` less the umask when new); Ctrl-C and SIGTERM
   are held during its two renames (:func:`pfjax.interrupts.deferred`), and a previous output a
   kill left aside between them is put back by the next writer. A mount point is refused, empty
   or not (it cannot be replaced). A run that
   stops early (an error, Ctrl-C, a kill) leaves the previous output as it was; its staging
   directory is removed on the way out, or, after a kill, by the next run that holds the lock
   (with any half-created partial directory ``.<name>.partial-*`` of a study's chunks). Each such
   temporary directory holds the file ``.pfjax-temporary`` from its creation until it is moved
   into place (:func:`temporary_dir`), and only a directory holding it is removed: an entry of the
   same name that pfjax did not make is left as it is, and so is a lock file pfjax did not write
   (a symbolic link, a directory or a file of other content at ``.<name>.lock`` is refused). A
   temporary directory's mark is removed last (:func:`remove_temporary`): a file the filesystem
   will not let go of leaves it marked, with one warning, and the next run tries again.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import stat
import tempfile
from pathlib import Path

from pfjax import interrupts
from pfjax.errors import InputError
from pfjax.output_lock import OutputBusy, OutputLock, now_utc, sibling

__all__ = [
    "MARKER",
    "NAME_PATTERN",
    "OutputBusy",
    "OutputDir",
    "OutputLock",
    "check_name",
    "check_target",
    "glob_escape",
    "read_marker",
    "sibling",
    "switch_advice",
]

MARKER = ".pfjax-output.json"
#: Version of the marker's format (its ``format`` field).
MARKER_FORMAT = 2
STAGING = "pfjax-staging"
_OLD = "pfjax-old"
#: The file that marks a temporary directory as pfjax's (:func:`temporary_dir`).
TEMP_MARK = ".pfjax-temporary"

#: Names of studies and outputs: a letter or digit, then letters, digits, ``_``, ``.``, ``-``.
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def default_target(name: str, out=None) -> Path:
    """The directory an output goes to: ``out``, else ``results/<name>`` under the current
    directory (every command, study script and API function that writes a named output)."""
    return Path("results") / name if out is None else Path(out)


def check_name(key: str, name) -> str:
    """A study or output name used as a directory name: 1-100 characters, a letter or digit first,
    then letters, digits, ``_``, ``.`` or ``-`` (so never ``.``, ``..``, empty, hidden, or with a
    path separator)."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise InputError(
            f"{key}: expected a name of 1-100 letters, digits, '_', '.' or '-' starting with a "
            f"letter or digit (it names a directory), got {name!r}",
            key,
        )
    return name


def read_marker(directory: Path) -> dict | None:
    """The marker of a pfjax output directory, or None if it has none (or an unreadable one)."""
    try:
        m = json.loads((Path(directory) / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(m, dict) or not isinstance(m.get("files"), dict) or not isinstance(m.get("dirs"), list):
        return None
    return m


def file_sha256(path) -> str:
    """The SHA-256 of a file's contents, hex (read in blocks of 1 MiB); remembered for the process
    by the file's device, inode, size and modification time, so that the checks of one command read
    a large file once."""
    st = os.stat(path)
    state = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    if state not in _DIGESTS:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        _DIGESTS[state] = h.hexdigest()
    return _DIGESTS[state]


_DIGESTS: dict[tuple, str] = {}


def as_written(listed: dict, name: str, st: os.stat_result, path=None) -> bool:
    """Whether file ``name`` (its ``stat``; ``path``, the file itself) is as pfjax wrote it, by the
    marker's ``files`` entry (``listed``: ``[size, mtime_ns, sha256]``; a marker of format 1 has no
    hash): the same size, and the same modification time or, where the time differs (a copy made
    with new times, an archive extracted), the same contents. A file of the same size and time is
    taken as written without reading it."""
    entry = listed.get(name)
    if not isinstance(entry, list) or len(entry) < 2 or entry[0] != st.st_size:
        return False
    if entry[1] == st.st_mtime_ns:
        return True
    digest = entry[2] if len(entry) > 2 else None
    if not (isinstance(digest, str) and path is not None and stat.S_ISREG(st.st_mode)):
        return False
    try:
        return file_sha256(path) == digest
    except OSError:  # a file that cannot be read is not known to be as written
        return False


def _entries(directory: Path) -> tuple[dict[str, os.stat_result], set[str]]:
    """Files (and links) and directories under ``directory``, as paths relative to it."""
    files, dirs = {}, set()
    for root, dnames, fnames in os.walk(directory):
        rel = Path(root).relative_to(directory)
        for d in list(dnames):
            p = Path(root) / d
            if p.is_symlink():  # a link to a directory is an entry, not a place to walk
                dnames.remove(d)
                files[str(rel / d)] = p.lstat()
            else:
                dirs.add(str(rel / d))
        for f in fnames:
            files[str(rel / f)] = (Path(root) / f).lstat()
    files.pop(MARKER, None)
    return files, dirs


#: The study scripts' outputs by the ``command`` their markers record, and the script that writes
#: each (the other commands are ``pfjax`` subcommands).
SCRIPTS = {
    "paper-reproduction": "studies/paper_reproduction.py",
    "parking-study": "studies/parking.py",
    "vehicle-tracking": "studies/vehicle_tracking.py",
    "kinematic-vs-dynamic": "studies/kinematic_vs_dynamic.py",
    "rare-events": "studies/rare_events.py",
    "tuning-study": "studies/tuning_ga_vs_gradient.py",
}


def _describe(marker: dict) -> str:
    sha = str(marker.get("config_sha256") or "")[:12]
    command = str(marker.get("command", "?"))
    runner = f"python {SCRIPTS[command]}" if command in SCRIPTS else f"pfjax {command}"
    return f"the output of `{runner}`" + (f" (config {sha})" if sha else "")


def check_target(
    target,
    *,
    command: str,
    config_sha256: str | None,
    overwrite: bool = False,
    flag: str = "--out",
) -> Path:
    """Check that ``target`` may receive a new output of ``command`` (see the module docstring).

    Touches nothing. Returns the target as an absolute path (symbolic links in its parents
    resolved). Raises :class:`~pfjax.errors.InputError` naming ``flag``, whose advice to replace
    the target is in the same words (:func:`switch_advice`).
    """
    resolved = target_path(target, flag)
    if not resolved.exists():
        return resolved
    _check_contents(
        resolved,
        target,
        command=command,
        config_sha256=config_sha256,
        overwrite=overwrite,
        flag=flag,
    )
    return resolved


def switch_advice(flag: str, option: str) -> str:
    """How to turn on the switch ``option`` (``overwrite``, ``fresh``) in the words of a caller whose
    output directory goes by ``flag``: ``"add --fresh"`` beside a command line's ``--out``, ``"pass
    fresh=True"`` beside a Python argument ``out``."""
    return f"add --{option}" if flag.startswith("-") else f"pass {option}=True"


def target_path(target, flag: str) -> Path:
    """The target as an absolute path, if it names a directory of its own whose parent pfjax may
    write into (not a root, the home or current directory, a symbolic link); raises InputError."""
    given = Path(target)
    last = str(target).rstrip("/" + os.sep).rsplit(os.sep, 1)[-1].rsplit("/", 1)[-1]
    if str(target).strip() == "" or last in ("", ".", ".."):
        if str(target).strip() and last == "":  # only separators: '/', '//'
            raise InputError(
                f"{flag}: {target} is a filesystem root; pfjax writes only into a directory of its own", flag
            )
        why = "it is empty" if not str(target).strip() else f"it ends in {last!r}"
        raise InputError(
            f"{flag}: {str(target)!r} does not name a new directory ({why}); give a directory name such as "
            "results/my_study",
            flag,
        )
    path = Path(os.path.abspath(given))
    resolved = path.parent.resolve() / path.name
    if resolved == Path(resolved.anchor):
        raise InputError(f"{flag}: {target} is a filesystem root; pfjax writes only into a directory of its own", flag)
    if resolved == Path.home().resolve():
        raise InputError(f"{flag}: {target} is the home directory; pfjax writes only into a directory of its own", flag)
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        raise InputError(
            f"{flag}: {target} is the current directory or contains it; give a directory of its own "
            f"such as results/my_study",
            flag,
        )
    for parent in resolved.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{flag}: {parent} is not a directory (cannot create {resolved.name} in it)", flag)
            if not os.access(parent, os.W_OK | os.X_OK):
                raise InputError(f"{flag}: {parent} is not writable", flag)
            break
    if resolved.is_symlink():
        raise InputError(f"{flag}: {target} is a symbolic link; give the directory it points to, or another name", flag)
    return resolved


def _check_contents(
    resolved: Path,
    target,
    *,
    command: str,
    config_sha256: str | None,
    overwrite: bool,
    flag: str,
):
    """An existing target may be replaced only if empty, or holding only what pfjax wrote there
    (unchanged, of the same command and config unless ``overwrite``); raises InputError."""
    if not resolved.is_dir():
        raise InputError(f"{flag}: {target} exists and is not a directory", flag)
    try:
        empty = not any(resolved.iterdir())
    except OSError as e:
        raise InputError(f"{flag}: {target} cannot be read ({e.strerror})", flag) from None
    if os.path.ismount(resolved):  # replaced whole at the end, which a mount point cannot be, empty or not
        raise InputError(
            f"{flag}: {target} is a mount point, which pfjax cannot replace with its output; "
            f"give a directory inside it ({Path(target) / 'run1'})",
            flag,
        )
    if empty:
        return
    marker = read_marker(resolved)
    if marker is None:
        raise InputError(
            f"{flag}: {target} is not empty and was not written by pfjax (it has no {MARKER}); "
            f"choose another {flag}, or empty it yourself",
            flag,
        )
    files, dirs = _entries(resolved)
    listed = marker["files"]
    links = sorted(f for f, st in files.items() if f in listed and stat.S_ISLNK(st.st_mode))
    foreign = sorted(set(files) - set(listed)) + links + sorted(dirs - set(marker["dirs"]))
    if foreign:
        more = f" and {len(foreign) - 1} more" if len(foreign) > 1 else ""
        raise InputError(
            f"{flag}: {target} holds {foreign[0]!r}{more}, which pfjax did not write there; move it "
            f"away or choose another {flag} (pfjax never deletes what it did not write)",
            flag,
        )
    if not overwrite:  # with overwrite a changed file is replaced: no verdict needed
        changed = [f for f, st in files.items() if not as_written(listed, f, st, resolved / f)]
        advice = switch_advice(flag, "overwrite")
        if changed:
            raise InputError(
                f"{flag}: {target}/{changed[0]} changed after pfjax wrote it; {advice} to replace "
                f"{target}, or choose another {flag}",
                flag,
            )
        if marker.get("command") != command or marker.get("config_sha256") != config_sha256:
            raise InputError(
                f"{flag}: {target} holds {_describe(marker)}; {advice} to replace it, or choose another {flag}",
                flag,
            )


class OutputDir:
    """One output directory being written (see the module docstring); a context manager.

    Example::

        with OutputDir("results/my_study", command="study", config_sha256=h) as out:
            (out.staging / "summary.json").write_text(text)
            out.commit()

    Args:
        target: the directory the output goes to.
        command: what writes it (``"study"``, ``"bench"``, ``"paper-reproduction"``, ...), recorded in
            the marker; a re-run of the same command and config replaces its own output.
        config_sha256: the hash of the config the output comes from (recorded in the marker).
        overwrite: replace a pfjax output of another command or config, or one whose files changed.
        flag: the flag or argument named in error messages (``--out``; ``out`` from Python, whose
            refusals then advise ``pass overwrite=True``, :func:`switch_advice`).
        extra: more fields for the marker (e.g. the study name, the seed).
    """

    def __init__(
        self,
        target,
        *,
        command: str,
        config_sha256: str | None,
        overwrite: bool = False,
        flag: str = "--out",
        extra: dict | None = None,
    ):
        self.command, self.config_sha256, self.overwrite, self.flag = command, config_sha256, overwrite, flag
        self.target = check_target(
            target,
            command=command,
            config_sha256=config_sha256,
            overwrite=overwrite,
            flag=flag,
        )
        self.extra = dict(extra or {})
        self._lock = OutputLock(self.target, command=command, flag=flag)
        self._staging: Path | None = None
        self._kept_changed: set[str] = set()  # files start_from_existing kept that pfjax did not write as they are
        self.committed = False

    # -- life cycle
    @property
    def is_open(self) -> bool:
        """Whether this process holds the target's lock (between :meth:`open` and :meth:`close`)."""
        return self._lock._fd is not None

    def open(self) -> OutputDir:
        """Take the lock (re-checking the target under it), remove staging directories that killed
        runs left behind. Idempotent."""
        if self.is_open:
            return self
        self.target.parent.mkdir(parents=True, exist_ok=True)
        self._lock.acquire()
        try:
            _restore_stranded(self.target)
            check_target(
                self.target,
                command=self.command,
                config_sha256=self.config_sha256,
                overwrite=self.overwrite,
                flag=self.flag,
            )
            for stale in own_temporary_dirs(self.target):  # nobody else holds this target's lock
                remove_temporary(stale)
        except BaseException:
            self._lock.release()
            raise
        return self

    def __enter__(self) -> OutputDir:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Remove the staging directory if it was not committed; release the lock."""
        if self._staging is not None and not self.committed:
            remove_temporary(self._staging)
        self._lock.release()

    # -- writing
    @property
    def staging(self) -> Path:
        """The private directory the output is assembled in (created on first use)."""
        if not self.is_open:
            raise RuntimeError("OutputDir: open() it (or use it as a context manager) before writing")
        if self._staging is None:
            self._staging = temporary_dir(self.target, STAGING)
        return self._staging

    def start_from_existing(self, keep) -> None:
        """Fill the staging directory with the current output's files for which ``keep(relative
        path)`` is true (hard links where the filesystem allows, else copies): to rewrite part of an
        output (``pfjax report``) and still replace it whole. A kept file that changed since pfjax
        wrote it (replaced with ``overwrite``) is kept as it is but left out of the new marker: it is
        the user's from now on, and no later run replaces it without its owner moving it away."""
        current = read_marker(self.target) if self.target.is_dir() else None
        listed = (current or {}).get("files", {})
        for rel in listed:
            src = self.target / rel
            if keep(rel) and src.is_file() and not src.is_symlink():
                if not as_written(listed, rel, src.lstat(), src):
                    self._kept_changed.add(rel)
                dst = self.staging / rel
                dst.parent.mkdir(parents=True, exist_ok=True)
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)

    def commit(self, **extra) -> Path:
        """Write the marker (with ``extra`` fields) and move the staging directory into place,
        replacing the previous output. Returns the target."""
        staging = self.staging
        unmark(staging)
        files, dirs = _entries(staging)
        marker = {
            "format": MARKER_FORMAT,
            "command": self.command,
            "config_sha256": self.config_sha256,
            **self.extra,
            **extra,
            "pfjax_version": _version(),
            "written": now_utc(),
            "files": {
                f: [st.st_size, st.st_mtime_ns, file_sha256(staging / f)]
                for f, st in sorted(files.items())
                if f not in self._kept_changed
            },
            "dirs": sorted(dirs),
        }
        (staging / MARKER).write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")
        _take_mode(staging, self.target)  # mkdtemp makes it private
        old = None
        if self.target.exists():
            check_target(
                self.target,
                command=self.command,
                config_sha256=self.config_sha256,
                overwrite=self.overwrite,
                flag=self.flag,
            )  # nothing foreign arrived meanwhile
            old = temporary_dir(self.target, _OLD)
        with interrupts.deferred():  # never between the two renames (a kill there: _restore_stranded)
            if old is not None:
                try:
                    os.replace(self.target, old / "output")
                except OSError as e:  # e.g. an immutable target, another user's in a sticky directory
                    remove_temporary(old)
                    raise self._cannot_replace(e) from None
            try:
                os.replace(staging, self.target)
            except OSError as e:
                if old is not None:  # the previous output back into place, as it was
                    os.replace(old / "output", self.target)
                    remove_temporary(old)
                raise self._cannot_replace(e) from None
            self.committed = True
            interrupts.wrote(self.target)
            if old is not None:  # before a held signal is acted on: nothing left beside the output
                remove_temporary(old)
        return self.target

    def _cannot_replace(self, e: OSError) -> InputError:
        """The one-line error of a final rename the operating system refused: the new output is
        not written, the previous one (if any) is as it was."""
        return InputError(
            f"{self.flag}: cannot move the new output into {self.target}: {e.strerror or e}; nothing there was changed",
            self.flag,
        )


def _take_mode(staging: Path, target: Path) -> None:
    """Give the staging directory the mode (and group) of the directory it replaces, a user's
    empty one or a previous output, so that replacing it changes neither who may read it nor its
    group; a new output gets ``0o777`` less the umask, as ``mkdir`` would."""
    try:
        st = os.stat(target)
    except OSError:
        staging.chmod(0o777 & ~_umask())
        return
    try:
        os.chown(staging, -1, st.st_gid)
    except OSError:  # not a group of this user's: the mode still says who may read
        pass
    staging.chmod(stat.S_IMODE(st.st_mode))


def _umask() -> int:
    """This process's umask (from ``/proc/self/status`` where Linux gives it; else set and reset)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _restore_stranded(target: Path) -> None:
    """A previous output that a run killed between its two final renames left in its
    ``.<name>.pfjax-old-*`` directory, with nothing at ``target``: moved back into place (under
    the target's lock), so that the next run finds it as it was."""
    if target.exists() or target.is_symlink():
        return
    for old in own_temporary_dirs(target):
        if old.name.startswith(f".{target.name}.{_OLD}-") and _whole(old / "output"):
            os.replace(old / "output", target)
            remove_temporary(old)
            return


def _whole(output: Path) -> bool:
    """Whether ``output`` is a pfjax output with every file its marker lists: one a kill left aside
    whole, not the rest of one :func:`remove_temporary` could not finish removing."""
    marker = read_marker(output) if output.is_dir() else None
    return marker is not None and all((output / f).is_file() for f in marker["files"])


def remove_temporary(directory: Path) -> bool:
    """Remove a :func:`temporary_dir` (a staging directory, a previous output set aside), its mark
    last: what cannot be removed (a file the filesystem keeps) stays in a directory still marked as
    pfjax's, which the next run that holds the target's lock tries again (:func:`own_temporary_dirs`),
    with one warning naming it. Returns whether it is gone."""
    import warnings

    for child in list(directory.iterdir()) if directory.is_dir() else []:
        if child.name != TEMP_MARK:
            if child.is_dir() and not child.is_symlink():
                shutil.rmtree(child, ignore_errors=True)
            else:
                try:
                    child.unlink()
                except OSError:
                    pass
    left = [c.name for c in directory.iterdir() if c.name != TEMP_MARK] if directory.is_dir() else []
    if left:
        warnings.warn(
            f"pfjax could not remove {directory / left[0]}; the next run into its output tries again, "
            f"or remove {directory} yourself",
            RuntimeWarning,
            stacklevel=2,
        )
        return False
    shutil.rmtree(directory, ignore_errors=True)
    return not directory.exists()


def temporary_dir(target: Path, kind: str) -> Path:
    """A new temporary directory ``.<name>.<kind>-*`` beside ``target`` (same filesystem), marked as
    pfjax's by :data:`TEMP_MARK`, so that a later run that finds it left by a kill may remove it
    (:func:`is_temporary`); :func:`unmark` takes the mark out before the directory is moved into place."""
    return mark_temporary(Path(tempfile.mkdtemp(prefix=f".{Path(target).name}.{kind}-", dir=Path(target).parent)))


def own_temporary_dirs(target: Path) -> list[Path]:
    """The :func:`temporary_dir` directories of ``target`` itself, left by a run that was killed:
    ``.<name>.<kind>-`` and mkdtemp's 8 characters, nothing more, and still marked. A glob such as
    ``.exp.partial-*`` would also match the live ``.exp.partial-v2.pfjax-staging-*`` of another
    target, ``exp.partial-v2``, whose lock this run does not hold."""
    own = re.compile(rf"\.{re.escape(target.name)}\.(?:{STAGING}|{_OLD}|partial)-[a-z0-9_]{{8}}")
    return [
        p for p in target.parent.glob(f".{glob_escape(target.name)}.*") if own.fullmatch(p.name) and is_temporary(p)
    ]


def mark_temporary(directory: Path) -> Path:
    """Put :data:`TEMP_MARK` (this process's pid and the time) in a directory pfjax just made."""
    (directory / TEMP_MARK).write_text(json.dumps({"pid": os.getpid(), "created": now_utc()}) + "\n", encoding="utf-8")
    return directory


def is_temporary(path: Path) -> bool:
    """Whether ``path`` is a directory (not a link) that :func:`temporary_dir` made and nobody released."""
    mark = path / TEMP_MARK
    return path.is_dir() and not path.is_symlink() and mark.is_file() and not mark.is_symlink()


def unmark(directory: Path) -> None:
    """Take :data:`TEMP_MARK` out of a :func:`temporary_dir` before it is moved into place."""
    (directory / TEMP_MARK).unlink(missing_ok=True)


def glob_escape(name: str) -> str:
    """``name`` with glob's special characters escaped."""
    return re.sub(r"([*?\[])", r"[\1]", name)


def _version() -> str:
    from pfjax import __version__

    return __version__
