"""Finished chunks of a study on disk, so an interrupted study resumes where it stopped.

A study's work is a fixed list of chunks (path x controller x block of run indices, plus the
slip-margin sweep's). Each finished chunk is one Parquet file in the *partial directory*
``<out>/../.<out name>.partial/``, written under a temporary name and ``os.replace``d into
place, so a file either is complete or does not exist (a kill at any instant loses at most the
chunks in flight). Every chunk file records, in its Parquet metadata, the config hash, seed and
pfjax version it was computed with, and is reused only if all three match the study being run:
no sequence of commands can produce a ``runs.parquet`` that mixes two configurations.
``manifest.json`` there records the same three for the whole directory: a re-run of the same
command reuses every finished chunk, while a changed config (or pfjax version) is refused with a
one-line :class:`pfjax.config.ConfigError` naming ``--out`` unless the caller asks to start afresh
(a partial directory with no finished chunk holds nothing to lose and is replaced silently). When
the study is complete the chunk files are merged, one Parquet row group per chunk (memory
O(chunk)), into the final ``runs.parquet``, and the partial directory is removed.

The partial directory is only touched by the process that holds the output's lock
(:class:`pfjax.outputs.OutputDir`).
"""

from __future__ import annotations

import json
import os
import re
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Protocol

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

import pfjax
from pfjax.config import ConfigError
from pfjax.interrupts import stop_if_interrupted
from pfjax.montecarlo.config import StudySpec, study_hash
from pfjax.outputs import sibling, switch_advice, temporary_dir, unmark
from pfjax.provenance import parquet_metadata
from pfjax.tables import ParquetAppender

#: The Parquet metadata keys that identify what a chunk was computed with.
IDENTITY = (b"pfjax.config_sha256", b"pfjax.seed", b"pfjax.version")
#: The run table's layout, stamped on every chunk beside :data:`IDENTITY`: a chunk of another
#: layout (one written before the sampled inputs were stored in the study's precision) is
#: simulated again on resume, never merged with this layout's chunks into one file.
TABLE_FORMAT = {b"pfjax.run_table_format": b"2"}


def chunk_key(prefix: str, path_index: int, controller_index: int, start: int) -> str:
    """The name of a chunk's file (without ``.parquet``): the study's runs (``prefix`` ``runs``) or a
    margin sweep's (``margin-<axis>``) of one path and controller, from run ``start`` on."""
    return f"{prefix}-p{path_index:03d}-c{controller_index:03d}-{start:010d}"


#: The file names :func:`chunk_key` gives (``.parquet``), and nothing else: a user's Parquet file in
#: the partial directory is never taken for a chunk, whatever its metadata.
CHUNK_FILE = re.compile(r"(?:runs|margin-[a-z]+)-p[0-9]{3,}-c[0-9]{3,}-[0-9]{10,}\.parquet")


def file_metadata(spec: StudySpec) -> dict[bytes, bytes]:
    """Parquet key-value metadata stamped on every table a study writes: config (strict JSON), hash,
    seed, version (:func:`pfjax.provenance.parquet_metadata`)."""
    return parquet_metadata(spec.model_dump(mode="json"), spec.seed, config_sha256=study_hash(spec))


def partial_dir(out: Path) -> Path:
    """Where the unfinished chunks of the study whose results go to ``out`` live."""
    return sibling(Path(out).absolute(), "partial")


class ChunkSource(Protocol):
    """Where a study's chunks come from: :class:`ChunkStore`, or a view of one."""

    def get(self, key: str, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
        """The chunk ``key``: stored, or ``compute()``d."""
        ...


class ChunkStore:
    """The finished chunks of one study (see module docstring).

    Args:
        out: the study's output directory (the chunks live next to it, never inside).
        spec: the validated study; its hash identifies the chunks.
        fresh: discard any unfinished chunks first (``pfjax study --fresh``) instead of resuming.
        flag: the name the output directory goes by in the caller's refusals (``--out``, or
            ``out`` for :func:`pfjax.run_study`, whose advice is then ``pass fresh=True``).

    Raises:
        ConfigError: the partial directory holds chunks of a different config or pfjax version.
    """

    def __init__(self, out: Path, spec: StudySpec, *, fresh: bool = False, flag: str = "--out"):
        self.dir = partial_dir(out)
        self.flag = flag
        self.manifest: dict[str, Any] = {
            "study": spec.name,
            "config_sha256": study_hash(spec),
            "seed": spec.seed,
            "pfjax_version": pfjax.__version__,
        }
        self.identity = {k: v for k, v in file_metadata(spec).items() if k in IDENTITY} | TABLE_FORMAT
        self.computed = 0  #: chunks simulated by this process
        self.reused = 0  #: chunks found finished on disk (resumed)
        if self.dir.is_symlink() or (self.dir.exists() and not self.dir.is_dir()):
            raise ConfigError(
                f"{flag}: {self.dir} (where pfjax keeps a study's finished chunks) exists and is not a "
                f"directory; move it away",
                flag,
            )
        if self.dir.exists():
            self._refuse_foreign(out)  # whatever follows: a directory pfjax did not write is never used
        if self.dir.exists() and (fresh or not self._chunk_files()):
            shutil.rmtree(self.dir)
        if self.dir.exists():
            self._check_manifest(out)
        else:
            self.dir.parent.mkdir(parents=True, exist_ok=True)
            tmp = temporary_dir(Path(out).absolute(), "partial")
            (tmp / "manifest.json").write_text(json.dumps(self.manifest, indent=1) + "\n")
            unmark(tmp)
            os.replace(tmp, self.dir)

    def _chunk_files(self) -> list[Path]:
        return [f for f in self.dir.iterdir() if f.suffix == ".parquet" and not f.name.startswith(".")]

    def _refuse_foreign(self, out: Path) -> None:
        """:class:`~pfjax.config.ConfigError` naming the flag unless the partial directory holds only
        what a study writes there: its manifest (:meth:`_written_by_pfjax`), chunk files stamped
        with a study's identity, and chunk files a kill left half-written under their temporary
        names. Checked before the directory is resumed or removed."""
        where = f"{self.flag}: {self.dir} (where pfjax keeps the finished chunks of {out})"
        foreign = [f.name for f in sorted(self.dir.iterdir()) if not self._written_by_pfjax(f)]
        if foreign:
            raise ConfigError(f"{where} holds {foreign[0]!r}, which pfjax did not write; move it away", self.flag)
        if not (self.dir / "manifest.json").is_file():
            raise ConfigError(f"{where} has no manifest.json, so pfjax did not make it; move it away", self.flag)

    def _written_by_pfjax(self, f: Path) -> bool:
        """Whether ``f`` in the partial directory is a file a study writes there: the manifest (a
        JSON object with exactly the manifest's keys), a chunk (Parquet with a study's config
        hash in its metadata) under a name :func:`chunk_key` gives, or a chunk's temporary file
        (``.<key>.parquet.tmp<pid>``)."""
        if f.is_symlink() or not f.is_file():
            return False
        if f.name == "manifest.json":
            try:
                old = json.loads(f.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                return False
            # the keys of every manifest pfjax has written (a version that adds one reads these too)
            return isinstance(old, dict) and set(old) == set(self.manifest)
        if CHUNK_FILE.fullmatch(f.name):
            try:
                meta = pq.read_schema(f).metadata or {}
            except (OSError, pa.ArrowException):
                return False
            return IDENTITY[0] in meta
        tmp = re.fullmatch(r"\.(.+)\.tmp[0-9]+", f.name)
        return tmp is not None and CHUNK_FILE.fullmatch(tmp.group(1)) is not None

    def _check_manifest(self, out: Path) -> None:
        try:
            old = json.loads((self.dir / "manifest.json").read_text())
        except (OSError, ValueError):
            old = {}
        for key, what in (("config_sha256", "config"), ("pfjax_version", "pfjax version")):
            if old.get(key) != self.manifest[key]:
                raise ConfigError(
                    f"{self.flag}: {out} has an interrupted study with a different {what} "
                    f"({str(old.get(key))[:12]} there, {self.manifest[key][:12]} now) in {self.dir}; "
                    f"re-run the original command to resume it, or {switch_advice(self.flag, 'fresh')} "
                    "to discard it and start over",
                    self.flag,
                )

    def _valid(self, f: Path) -> bool:
        """Whether chunk file ``f`` was computed with this study's config, seed and pfjax version."""
        try:
            meta = pq.read_schema(f).metadata or {}
        except (OSError, pa.ArrowException):
            return False
        return all(meta.get(k) == v for k, v in self.identity.items())

    def finished(self) -> list[str]:
        """The keys of the chunks finished on disk (sorted)."""
        return sorted(f.stem for f in self._chunk_files() if self._valid(f))

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.parquet"

    def get(self, key: str, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
        """The chunk ``key``: read back if finished with this study's identity, else ``compute()``d
        and written atomically (replacing a chunk file of another identity)."""
        f = self.path(key)
        if f.is_file() and self._valid(f):
            self.reused += 1
            return pd.read_parquet(f)
        stop_if_interrupted()  # a Ctrl-C whose exception never arrived: stop before the next chunk
        df = compute()
        tmp = f.with_name(f".{f.name}.tmp{os.getpid()}")
        table = pa.Table.from_pandas(df, preserve_index=False)
        pq.write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), **self.identity}), tmp)
        os.replace(tmp, f)
        self.computed += 1
        return df

    def merge(self, keys: Iterable[str], dest: Path, metadata: dict[bytes, bytes]) -> int:
        """Stream the chunks ``keys`` (in that order) into one Parquet file, one row group per chunk;
        returns the number of rows. Memory holds one chunk at a time."""
        with ParquetAppender(dest, metadata) as sink:
            for key in keys:
                sink.write(pq.read_table(self.path(key)))
        return sink.rows

    def discard(self) -> None:
        """Remove the chunks (after the finished study has been moved into place)."""
        shutil.rmtree(self.dir, ignore_errors=True)
