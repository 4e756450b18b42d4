"""A persistent XLA compilation cache for pfjax's commands, studies and tests.

Compiling a batched simulation takes seconds (the scan body is large) while running a small one
takes milliseconds, so a second ``pfjax track`` or a re-run study would spend most of its time
compiling what it compiled before. :func:`enable` points JAX's persistent compilation cache
(``jax_compilation_cache_dir``) at a directory, so a program compiled once is loaded from disk by
every later process (same program, same JAX version and devices; the cache key covers them, so a
changed pfjax never loads a stale program).

The directory is ``$PFJAX_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/pfjax/xla`` (default
``~/.cache/pfjax/xla``); ``PFJAX_CACHE_DIR=off`` disables it, and a cache the user configured
through JAX (``JAX_COMPILATION_CACHE_DIR``) is left as it is. Only compilations longer than
``min_compile_s`` are stored: 0.5 s by default, 0 for ``pfjax``'s commands, whose small host-side
programs (a scenario's arrays) would otherwise compile again in every process.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "PFJAX_CACHE_DIR"
OFF = ("off", "0", "none", "false")


def default_dir(environ=None) -> Path | None:
    """The cache directory :func:`enable` uses (None: disabled)."""
    environ = os.environ if environ is None else environ
    value = environ.get(ENV, "").strip()
    if value.lower() in OFF:
        return None
    if value:
        return Path(value).expanduser()
    base = environ.get("XDG_CACHE_HOME", "").strip() or str(Path.home() / ".cache")
    return Path(base) / "pfjax" / "xla"


def usable(target: Path | None) -> Path | None:
    """``target`` created if need be, or None if it is None or cannot be written."""
    if target is None:
        return None
    try:
        target.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return target if os.access(target, os.W_OK) else None


def enable(path: str | Path | None = None, *, min_compile_s: float | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache in ``path`` (default :func:`default_dir`).

    Args:
        path: the cache directory (default :func:`default_dir`).
        min_compile_s: the shortest compilation stored, s. ``None``: 0.5 s for a cache this call
            turns on, unchanged for pfjax's own cache already on (``import pfjax`` turns it on with
            0.5 s); a cache configured through JAX by the user is left as it is either way.

    Returns the directory in use, or None when disabled, already configured through JAX, or not
    writable (the cache is an optimisation: nothing fails without it).
    """
    import jax

    configured = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # a flag, not in the stubs
    if configured:
        if min_compile_s is not None and Path(configured) == default_dir():
            jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_s))
        return Path(configured)
    target = usable(Path(path) if path is not None else default_dir())
    if target is None:
        return None
    jax.config.update("jax_compilation_cache_dir", str(target))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5 if min_compile_s is None else min_compile_s)
    return target


# ------------------------------------------------------------------------------ designs


def _source_hash(package: str) -> str:
    """SHA-256 of the ``.py`` files of a pfjax subpackage (a changed synthesis never reads a design
    computed by the old one)."""
    import hashlib

    root = Path(__file__).resolve().parent / package
    h = hashlib.sha256()
    for f in sorted(root.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def design_dir(environ=None) -> Path | None:
    """Where computed designs are kept: ``designs/`` beside the compilation cache (None: disabled
    with it, ``PFJAX_CACHE_DIR=off``)."""
    xla = default_dir(environ)
    return None if xla is None else xla.parent / "designs"


def memoized_design(name: str, args: dict, compute) -> dict:
    """``compute()`` (a design's scalar gains, a dict of floats), kept on disk by ``name``, ``args``,
    the synthesis code and the solver versions, so a later process reads it instead of importing
    cvxpy and solving the LMIs again (seconds). Nothing fails without the cache: a missing,
    unreadable or unwritable directory just computes."""
    import hashlib
    import json
    from importlib import metadata

    where = usable(design_dir())
    if where is None:
        return compute()
    versions: dict[str, str | None] = {}
    for dist in ("cvxpy", "clarabel", "numpy", "scipy"):
        try:
            versions[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            versions[dist] = None
    key = json.dumps([name, args, versions, _source_hash("synthesis")], sort_keys=True)
    file = where / f"{name}-{hashlib.sha256(key.encode()).hexdigest()[:24]}.json"
    try:
        stored = json.loads(file.read_text(encoding="utf-8"))
        if stored.get("key") == key:
            return {k: float(v) for k, v in stored["gains"].items()}
    except (OSError, ValueError, AttributeError, TypeError):
        pass
    gains = compute()
    try:
        tmp = file.with_name(f".{file.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps({"key": key, "gains": gains}), encoding="utf-8")
        os.replace(tmp, file)
    except OSError:
        pass
    return gains
