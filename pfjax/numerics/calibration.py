"""CPU-dependent settings chosen by measurement: runs per CPU block, the vector width and the
sharing of the sine-cosine pair.

Three settings of pfjax's CPU programs depend on the CPU more than on anything else:

* the **block** of runs a device simulates at once (:mod:`pfjax.sim.sharding`), in bytes per
  batched array: small enough that a block's loop stays in the core's caches and under XLA's
  small-loop threshold, large enough to amortise the per-block work;
* the **vector width** XLA's CPU backend generates code for (:mod:`pfjax.numerics.compiler`);
* how the **sine-cosine pair** is handed to the fused kernels that read it, per precision
  (:func:`pfjax.numerics.elementary.sincos_sharing`: divided by an exact 1 as one complex number,
  as two reals, or not at all; a vector division costs more on some CPUs than recomputing).

Without a calibration pfjax uses rules stated with their evidence in those modules (5,000 bytes
per block; 512-bit vectors where the CPU has AVX-512; the pair as two reals on Intel CPUs, as one
complex number on others). A calibration written before the sharing was measured has no
``sincos_sharing`` and leaves it to the rule. ``pfjax calibrate`` measures the
benchmark problem's throughput over the candidates on this CPU (:mod:`pfjax.bench.calibrate`) and
writes the best to ``<directory>/<cpu key>.json`` (a file there that is not a pfjax calibration
is never replaced); every later process on a CPU of the same
identity (vendor, family, model, model name, vector flags) and the same JAX version reads it at
import. ``PFJAX_CALIBRATION=off`` ignores the file; ``PFJAX_VECTOR_WIDTH`` still overrides the
width. The directory is ``$PFJAX_CALIBRATION_DIR``, else ``$XDG_CACHE_HOME/pfjax/calibration``
(default ``~/.cache/pfjax/calibration``), whatever ``PFJAX_CACHE_DIR`` says. A file that is
unreadable (not JSON, nested too deeply to parse), not a calibration, or not a file at all (a
directory at its path) is ignored with one warning line naming it.

Results depend on the block and the width only through rounding (each block shape is compiled
into its own vector code; :mod:`pfjax.sim.sharding`); a study records the settings it ran with.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import secrets
import tempfile
import warnings
from pathlib import Path

from pfjax import errors
from pfjax.numerics.cpu import VECTOR_FLAGS, cpu_info

ENV = "PFJAX_CALIBRATION"
DIR_ENV = "PFJAX_CALIBRATION_DIR"
OFF = ("off", "0", "none", "false")
#: ``PFJAX_CALIBRATION`` values that leave it on (unset or empty included); any other warns.
ON = ("", "on", "1", "true", "yes")
#: The file format written by :func:`save` (a file of another version is ignored).
VERSION = 1
#: Vector widths a calibration may choose, bits (besides None: XLA's default): the register widths
#: of SSE, AVX and AVX-512, the values of XLA's ``xla_cpu_prefer_vector_width``
#: (:mod:`pfjax.numerics.compiler`; :func:`pfjax.bench.calibrate.widths` measures 512).
WIDTHS = (128, 256, 512)
#: What reading a calibration file may raise besides a bad format: the file system's errors, JSON
#: that does not parse or decode (``ValueError``), and JSON nested deeper than Python's recursion
#: limit (``RecursionError``, e.g. ``[[[...]]]`` 100,000 deep).
_UNREADABLE = (OSError, ValueError, RecursionError)


def cpu_key(cpuinfo: str | None = None, jax_version: str | None = None) -> str:
    """The identity a calibration holds for: vendor, family and model numbers, and a hash of the
    model name, the vector flags and the JAX version (``"authenticamd-25-17-1a2b3c4d"``)."""
    import jax

    info = cpu_info() if cpuinfo is None else cpu_info(cpuinfo)
    flags = sorted(set(info.get("flags", "").split()) & VECTOR_FLAGS)
    ident = json.dumps([info.get("model name", ""), flags, jax_version or jax.__version__])
    head = "-".join(info.get(k, "unknown").lower().replace(" ", "") for k in ("vendor_id", "cpu family", "model"))
    return f"{head}-{hashlib.sha256(ident.encode()).hexdigest()[:8]}"


def directory(environ=None) -> Path | None:
    """Where calibrations are kept: ``$PFJAX_CALIBRATION_DIR``, else
    ``$XDG_CACHE_HOME/pfjax/calibration`` (default ``~/.cache/pfjax/calibration``); None: disabled
    by ``PFJAX_CALIBRATION=off``. The compilation cache's ``PFJAX_CACHE_DIR`` plays no part."""
    environ = os.environ if environ is None else environ
    value = environ.get(ENV, "").strip().lower()
    if value in OFF:
        return None
    if value not in ON:  # a typo is not silent: on, with a warning naming the variable
        _warn(
            f"{ENV}={environ.get(ENV)!r} not understood (expected one of {', '.join((*ON[1:], *OFF))}); calibration on"
        )
    given = environ.get(DIR_ENV, "").strip()
    if given:
        return Path(given).expanduser()
    base = environ.get("XDG_CACHE_HOME", "").strip() or str(Path.home() / ".cache")
    return Path(base).expanduser() / "pfjax" / "calibration"


#: How the sine-cosine pair may be shared between kernels (:data:`pfjax.numerics.elementary.SINCOS_SHARING`;
#: written out here, which :mod:`pfjax.numerics.elementary` imports).
SHARINGS = ("complex", "real", "none")
#: The variable that sets the sharing over a calibration and the rule.
SHARING_ENV = "PFJAX_SINCOS_SHARING"


def sharing_from_env(environ=None, warn: bool = True) -> str | None:
    """The sine-cosine sharing :data:`SHARING_ENV` sets: one of :data:`SHARINGS` (stripped, any
    case), ``None`` where it is unset or empty. A value that is not one of them is ignored
    (``None``), with a warning naming the variable unless ``warn`` is false."""
    environ = os.environ if environ is None else environ
    value = environ.get(SHARING_ENV, "").strip().lower()
    if value in SHARINGS:
        return value
    if value and warn:
        warnings.warn(f"{SHARING_ENV}: value {value!r} ignored, expected one of {', '.join(SHARINGS)}", stacklevel=4)
    return None


def _valid(data) -> bool:
    try:
        width = data["vector_width"]
        blocks = data["block_bytes"]
        sharing = data.get("sincos_sharing")  # absent in a calibration that did not measure it
        return (
            data["version"] == VERSION
            and (width is None or (type(width) is int and width in WIDTHS))
            and all(type(blocks[d]) is int and 64 <= blocks[d] <= 10**9 for d in ("float32", "float64"))
            and (sharing is None or all(sharing[d] in SHARINGS for d in ("float32", "float64")))
        )
    except (KeyError, TypeError, AttributeError):
        return False


def _warn(message: str) -> None:
    """One line on stderr, ``pfjax:0: UserWarning: <message>``, as pfjax's other warnings about the
    user's files and settings (:func:`pfjax.errors.deprecated`), not a line of pfjax's source that
    happened to read the file."""
    warnings.warn_explicit(message, UserWarning, "pfjax", 0, module="pfjax")


@functools.cache
def load(path: str | None = None) -> dict | None:
    """This CPU's calibration (``{"vector_width", "block_bytes": {"float32", "float64"}, ...}``) or
    None (none written, disabled, or unreadable: then with one warning naming the file). Read once
    per process (``path``: a file to read instead, for tests)."""
    if path is None:
        where = directory()
        if where is None:
            return None
        file = where / f"{cpu_key()}.json"
    else:
        file = Path(path)
    if not file.exists():
        return None
    if not file.is_file():  # a directory (or a device, a socket) at the file's path
        _warn(f"{file}: calibration ignored, not a file")
        return None
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except _UNREADABLE as e:
        _warn(f"{file}: calibration ignored, unreadable ({errors.one_line(e)})")
        return None
    if not _valid(data):
        _warn(f"{file}: calibration ignored, not a pfjax calibration of version {VERSION}")
        return None
    if path is None and data.get("cpu_key") != cpu_key():  # measured on another CPU (a copied file)
        _warn(f"{file}: calibration ignored, measured on another CPU ({data.get('cpu_key')!r}, this one {cpu_key()!r})")
        return None
    return data


def block_bytes(itemsize: int) -> int | None:
    """The calibrated bytes per batched array in one CPU block for floats of ``itemsize`` bytes
    (None: no calibration)."""
    cal = load()
    if cal is None:
        return None
    return int(cal["block_bytes"]["float64" if itemsize >= 8 else "float32"])


def sincos_sharing(dtype_name: str) -> str | None:
    """The calibrated sharing of the sine-cosine pair (one of :data:`SHARINGS`) for ``"float32"`` or
    ``"float64"`` programs (None: no calibration, or one that did not measure it)."""
    cal = load()
    sharing = None if cal is None else cal.get("sincos_sharing")
    return None if sharing is None else sharing.get("float64" if dtype_name == "float64" else "float32")


def vector_width() -> tuple[bool, int | None]:
    """``(calibrated, width)``: whether a calibration decides the width, and the width in bits it
    chose (None: XLA's default)."""
    cal = load()
    return (False, None) if cal is None else (True, cal["vector_width"])


def _ours(data, key: str) -> bool:
    """Whether ``data`` (a file's JSON) is a calibration pfjax wrote for ``key``: one :func:`load`
    reads, or a pfjax calibration of another format version for the same CPU key."""
    if _valid(data):
        return True
    return isinstance(data, dict) and data.get("cpu_key") == key and type(data.get("version")) is int


def _replaceable(file: Path) -> None:
    """An :class:`~pfjax.errors.InputError` naming ``PFJAX_CALIBRATION_DIR`` and ``file`` unless a
    calibration may be written there: nothing there yet, or a pfjax calibration (:func:`_ours`).
    Anything else (a directory, a symbolic link, the user's notes, an unreadable file) is never
    replaced."""
    from pfjax.errors import InputError

    if not file.exists() and not file.is_symlink():
        return
    if file.is_symlink():  # pfjax writes no links: the user's, even to a calibration
        raise InputError(
            f"{DIR_ENV}: {file} is a symbolic link, which pfjax does not replace; "
            f"remove it or set {DIR_ENV} to another directory",
            DIR_ENV,
        )
    if file.is_dir() or not file.is_file():
        raise InputError(
            f"{DIR_ENV}: {file} is not a file, so the calibration cannot be written there; "
            f"remove it or set {DIR_ENV} to another directory",
            DIR_ENV,
        )
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except _UNREADABLE:
        data = None
    if not _ours(data, file.stem):
        raise InputError(
            f"{DIR_ENV}: {file} is not a pfjax calibration, so pfjax does not replace it; "
            f"move it away or set {DIR_ENV} to another directory",
            DIR_ENV,
        )


def writable_directory(environ=None, key: str | None = None) -> Path:
    """:func:`directory`, made and checked before anything is measured: an
    :class:`~pfjax.errors.InputError` naming the environment variable when calibrations are off, the
    directory cannot be made or a file cannot be written in it (a uniquely named probe file is
    created and removed), or the calibration file of ``key`` (default this CPU's, :func:`cpu_key`) is
    there as something pfjax does not replace (a directory, a file that is not a pfjax calibration:
    :func:`_replaceable`). The directory, pfjax's own cache directory, is left in place."""
    from pfjax.errors import InputError

    environ = os.environ if environ is None else environ
    where = directory(environ)
    if where is None:
        raise InputError(
            f"{ENV}: calibrations are off ({ENV}={environ.get(ENV, '').strip()}), so none would be kept; "
            f"unset it, or measure with --dry-run",
            ENV,
        )
    try:
        where.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".pfjax-probe-", suffix=".tmp", dir=where)  # a new name, never the user's
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise InputError(
            f"{DIR_ENV}: {where} cannot be made and written ({e.strerror or e}); set {DIR_ENV} to a writable directory",
            DIR_ENV,
        ) from None
    _replaceable(where / f"{cpu_key() if key is None else key}.json")
    return where


def save(result: dict, path: Path | None = None) -> Path:
    """Write a calibration (``result`` as :func:`pfjax.bench.calibrate.calibrate` returns it) to
    ``path`` (default: this CPU's file in :func:`writable_directory`), atomically; returns the path.
    Only a missing file or a pfjax calibration is replaced (:func:`_replaceable`). A write that
    fails is an :class:`~pfjax.errors.InputError` naming ``PFJAX_CALIBRATION_DIR``, and leaves the
    previous file, if any, and no temporary file."""
    from pfjax.errors import InputError

    if path is None:
        path = writable_directory(key=result["cpu_key"]) / f"{result['cpu_key']}.json"
    else:
        _replaceable(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # a new name (O_EXCL: never a file pfjax did not write), readable as the umask allows
        name = path.with_name(f".{path.name}.{os.getpid()}.{secrets.token_hex(6)}.tmp")
        fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        tmp = name
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(json.dumps(result, indent=1) + "\n")
        os.replace(tmp, path)
    except BaseException as e:
        if tmp is not None:
            with contextlib.suppress(OSError):
                tmp.unlink()
        if isinstance(e, OSError):
            raise InputError(
                f"{DIR_ENV}: {path} cannot be written ({e.strerror or e}); set {DIR_ENV} to a writable directory",
                DIR_ENV,
            ) from None
        raise
    load.cache_clear()
    return path
