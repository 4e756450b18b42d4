"""Provenance: what every output of pfjax records about how it was made.

:func:`stamp` is the one record (pfjax and JAX versions, the config's SHA-256, the seed, the
machine) that a study's ``summary.json`` carries at its top level; :func:`parquet_metadata` is the
same record as Parquet key-value metadata (with the config itself as strict JSON), stamped on every
table pfjax writes (:func:`pfjax.tables.write_parquet`). Same config and seed, same hash: the hash
is over the canonical JSON of the validated config (defaults filled in, keys sorted).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform


def config_hash(cfg: dict) -> str:
    """SHA-256 of the canonical JSON of ``cfg`` (keys sorted, no spaces, -0.0 as 0.0: the same run
    whichever zero was typed)."""
    from pfjax.jsonio import clean  # the outputs' own canonical numbers (a config holds no NaN)

    return hashlib.sha256(json.dumps(clean(cfg), sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def machine() -> str:
    """One line: CPU architecture and OS, the JAX devices (of every process, with their number when
    there are several: the CPUs are then this process's host's), the JAX and Python versions."""
    import jax

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    n = jax.process_count()
    here = f" on process {jax.process_index()}'s host" if n > 1 else ""
    over = f" over {n} processes" if n > 1 else ""
    return (
        f"{platform.machine()} {platform.system()}, {cores} CPU(s){here}, {jax.device_count()} "
        f"{jax.default_backend()} device(s){over}, jax {jax.__version__}, Python {platform.python_version()}"
    )


def stamp(config: dict, seed: int | None = None) -> dict:
    """The provenance record of an output made from ``config`` (a JSON-able dict) and ``seed``."""
    import pfjax

    return {
        "pfjax_version": pfjax.__version__,
        "config_sha256": config_hash(config),
        "seed": seed,
        "machine": machine(),
        "cpu_settings": cpu_settings(),
    }


#: The units of the numbers :func:`stamp` records (a summary's or a command's ``units`` map takes
#: them from here; "1": dimensionless).
STAMP_UNITS: dict[str, str] = {
    "seed": "1 (the random seed)",
    "cpu_settings": "vector_width bits (null: XLA's default), block_bytes bytes",
}


def cpu_settings() -> dict:
    """The CPU settings the simulator programs ran with: the vector width asked of XLA (None: its
    default), the bytes per batched array in a CPU block per precision, how the sine-cosine pair is
    shared between kernels per precision (:func:`pfjax.numerics.elementary.sincos_sharing`), and
    where they came from
    (``"calibrated"``: ``pfjax calibrate``'s measurement on this CPU; ``"rules"``: the stated defaults;
    ``"; vector width from PFJAX_VECTOR_WIDTH"`` added where that variable sets the width:
    :func:`pfjax.numerics.compiler.settings_source`). Results depend on them only through rounding."""
    from pfjax.numerics import compiler, elementary
    from pfjax.sim.sharding import cpu_block_bytes

    return {
        "vector_width": compiler.OPTIONS.get("xla_cpu_prefer_vector_width"),
        "block_bytes": {"float32": cpu_block_bytes(4), "float64": cpu_block_bytes(8)},
        "sincos_sharing": {d: elementary.sincos_sharing(d) for d in ("float32", "float64")},
        "source": compiler.settings_source(),
    }


def parquet_metadata(
    config: dict, seed: int | list[int] | None = None, *, config_sha256: str | None = None
) -> dict[bytes, bytes]:
    """Parquet key-value metadata: ``pfjax.config_sha256``, ``pfjax.config`` (strict JSON),
    ``pfjax.seed`` (the seed as a decimal integer; a study of several seeds, their JSON list;
    ``null`` for none) and ``pfjax.version``."""
    import pfjax
    from pfjax.jsonio import dumps

    return {
        b"pfjax.config_sha256": (config_sha256 or config_hash(config)).encode(),
        b"pfjax.config": dumps(config).encode(),
        b"pfjax.seed": (str(seed) if isinstance(seed, int) else dumps(seed)).encode(),
        b"pfjax.version": pfjax.__version__.encode(),
    }
