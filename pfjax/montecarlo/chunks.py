"""Finished chunks of a study on disk, so an interrupted study resumes where it stopped.

A study's work is a fixed list of chunks (path x controller x block of run indices, plus the
slip-margin sweep's). Each finished chunk is one Parquet file in the *partial directory*
``<out>/../.<out name>.partial/``, written under a temporary name and ``os.replace``d into
place, so a file either is complete or does not exist (a kill at any instant loses at most the
chunks in flight). ``manifest.json`` there records the config hash, seed and pfjax version; a
re-run of the same command reuses every finished chunk, while a changed config (or pfjax
version) is refused with a one-line :class:`pfjax.config.ConfigError` unless the caller asks to
start afresh. When the study is complete the chunk files are merged, one Parquet row group per
chunk (memory O(chunk)), into the final ``runs.parquet``, and the partial directory is removed.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterable

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

import pfjax
from pfjax.config import ConfigError
from pfjax.montecarlo.config import StudySpec, study_hash


def file_metadata(spec: StudySpec) -> dict[bytes, bytes]:
    """Parquet key-value metadata stamped on every table a study writes: config (strict JSON), hash, seed, version."""
    from pfjax.cli import dumps

    return {
        b"pfjax.config_sha256": study_hash(spec).encode(),
        b"pfjax.config": dumps(spec.model_dump(mode="json")).encode(),
        b"pfjax.seed": str(spec.seed).encode(),
        b"pfjax.version": pfjax.__version__.encode(),
    }


def partial_dir(out: Path) -> Path:
    """Where the unfinished chunks of the study whose results go to ``out`` live."""
    out = Path(out)
    return out.parent / f".{out.name}.partial"


class ChunkStore:
    """The finished chunks of one study (see module docstring).

    Args:
        out: the study's output directory (the chunks live next to it, never inside).
        spec: the validated study; its hash identifies the chunks.
        fresh: discard any unfinished chunks first (``pfjax study --fresh``) instead of resuming.

    Raises:
        ConfigError: the partial directory holds chunks of a different config or pfjax version.
    """

    def __init__(self, out: Path, spec: StudySpec, *, fresh: bool = False):
        self.dir = partial_dir(out)
        self.manifest = {"study": spec.name, "config_sha256": study_hash(spec), "seed": spec.seed,
                         "pfjax_version": pfjax.__version__}
        self.computed = 0  #: chunks simulated by this process
        self.reused = 0  #: chunks found finished on disk (resumed)
        if fresh and self.dir.exists():
            shutil.rmtree(self.dir)
        if self.dir.exists():
            self._check_manifest(out)
        else:
            self.dir.parent.mkdir(parents=True, exist_ok=True)
            tmp = Path(tempfile.mkdtemp(prefix=f"{self.dir.name}-", dir=self.dir.parent))
            (tmp / "manifest.json").write_text(json.dumps(self.manifest, indent=1) + "\n")
            os.replace(tmp, self.dir)

    def _check_manifest(self, out: Path) -> None:
        try:
            old = json.loads((self.dir / "manifest.json").read_text())
        except (OSError, ValueError):
            old = {}
        for key, what in (("config_sha256", "config"), ("pfjax_version", "pfjax version")):
            if old.get(key) != self.manifest[key]:
                raise ConfigError(
                    f"--out: {out} has an interrupted study with a different {what} "
                    f"({str(old.get(key))[:12]} there, {self.manifest[key][:12]} now) in {self.dir}; "
                    f"re-run the original command to resume it, or add --fresh to discard it and start over")

    def assembly_dir(self) -> Path:
        """A fresh private directory inside the partial directory where the final outputs are
        assembled before being renamed to ``out`` (same filesystem); a kill leaves it inside the
        partial directory, and the next run removes it."""
        for stale in self.dir.glob("assembly-*"):
            shutil.rmtree(stale, ignore_errors=True)
        return Path(tempfile.mkdtemp(prefix="assembly-", dir=self.dir))

    def finished(self) -> list[str]:
        """The keys of the chunks finished on disk (sorted)."""
        return sorted(f.stem for f in self.dir.glob("*.parquet") if not f.name.startswith("."))

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.parquet"

    def get(self, key: str, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
        """The chunk ``key``: read back if finished, else ``compute()``d and written atomically."""
        f = self.path(key)
        if f.is_file():
            self.reused += 1
            return pd.read_parquet(f)
        df = compute()
        tmp = f.with_name(f".{f.name}.tmp{os.getpid()}")
        df.to_parquet(tmp, index=False)
        os.replace(tmp, f)
        self.computed += 1
        return df

    def merge(self, keys: Iterable[str], dest: Path, metadata: dict[bytes, bytes]) -> int:
        """Stream the chunks ``keys`` (in that order) into one Parquet file, one row group per chunk;
        returns the number of rows. Memory holds one chunk at a time."""
        writer, n = None, 0
        try:
            for key in keys:
                table = pq.read_table(self.path(key))
                if writer is None:
                    writer = pq.ParquetWriter(dest, table.schema.with_metadata({**(table.schema.metadata or {}), **metadata}))
                writer.write_table(table.cast(writer.schema))
                n += table.num_rows
        finally:
            if writer is not None:
                writer.close()
        if writer is None:  # no chunk: an empty table still records the config
            pq.write_table(pa.table({}).replace_schema_metadata(metadata), dest)
        return n

    def discard(self) -> None:
        """Remove the chunks (after the finished study has been moved into place)."""
        shutil.rmtree(self.dir, ignore_errors=True)
