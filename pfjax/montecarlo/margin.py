"""The slip-margin sweep: success counts over a grid of slip amplitudes, per controller, axis (rear, front,
joint) and amplitude, all paths pooled (:func:`margin_sweep`), streamed chunk by chunk like the study."""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from pfjax.montecarlo.chunk_runs import simulate_runs
from pfjax.montecarlo.chunks import ChunkSource, file_metadata
from pfjax.montecarlo.config import StudySpec

MARGIN_RUN_OFFSET = 1 << 30  # margin runs draw from their own index range (disjoint from the study's runs)
MARGIN_COLUMNS = ["path", "controller", "axis", "amplitude_deg", "success", "status"]
#: The slip-margin sweep's success counts: per controller, axis and amplitude, paths pooled.
SWEEP_COUNT_KEYS = ["controller", "axis", "amplitude_deg"]


def margin_sweep(
    spec: StudySpec, controllers, *, progress: bool | None = None, store: ChunkSource | None = None, dest=None
) -> pd.DataFrame:
    """Success counts over the slip-amplitude grid, per controller, axis and amplitude (all paths
    pooled): columns ``controller, axis, amplitude_deg, k`` (successes) and ``n`` (runs).

    Run ``j`` at amplitude index ``a`` on axis ``x`` uses run index ``OFFSET + (x * n_amp + a) * n + j``; its
    slip is ``A * sign`` with the sign drawn from the run's own key (so the sweep is deterministic).
    The sweep streams like the study: one chunk of runs in memory at a time; its run rows
    (:data:`MARGIN_COLUMNS`) go to the Parquet file ``dest`` if given. With a ``store``, finished
    chunks of the sweep are resumed like the study's.
    """
    from tqdm import tqdm

    from pfjax.montecarlo.chunks import ParquetAppender

    m = spec.margin
    n, amps = m.n_per_amplitude, np.asarray(m.amplitudes_deg)
    counts = []
    total = len(m.axes) * len(amps) * n * len(spec.paths) * len(controllers)
    sink = ParquetAppender(dest, file_metadata(spec)) if dest is not None else None
    with (
        sink if sink is not None else contextlib.nullcontext(),
        tqdm(
            total=total,
            desc=f"{spec.name}: slip margin",
            unit="run",
            disable=None if progress is None else not progress,
        ) as bar,
    ):
        for xi, axis in enumerate(m.axes):
            runs = (
                MARGIN_RUN_OFFSET
                + (xi * len(amps) + np.repeat(np.arange(len(amps)), n)) * n
                + np.tile(np.arange(n), len(amps))
            )
            amp = np.repeat(amps, n)
            for p in range(len(spec.paths)):
                signs = _signs(spec, p, runs)
                br = amp * signs[:, 0] * (axis in ("rear", "joint"))
                bf = amp * signs[:, 1] * (axis in ("front", "joint"))
                rows_of = lambda df, axis=axis, runs=runs, amp=amp: _margin_rows(df, axis, runs, amp)
                sweep_store = None if store is None else _Project(store, rows_of)
                for _, _, df in simulate_runs(
                    spec, p, runs, controllers, slip_override=(br, bf), store=sweep_store, prefix=f"margin-{axis}"
                ):
                    rows = df if store is not None else rows_of(df)
                    if not rows.empty:  # (empty: a chunk another process computes)
                        if sink is not None:
                            sink.write(rows)
                        counts.append(rows.groupby(SWEEP_COUNT_KEYS, sort=False)["success"].agg(k="sum", n="count"))
                    bar.update(len(df))
    if not counts:
        return pd.DataFrame(columns=SWEEP_COUNT_KEYS + ["k", "n"])
    return pd.concat(counts).groupby(level=SWEEP_COUNT_KEYS, sort=False).sum().reset_index()


def _margin_rows(df: pd.DataFrame, axis: str, runs: np.ndarray, amp: np.ndarray) -> pd.DataFrame:
    df = df.assign(axis=axis, amplitude_deg=np.interp(df["run"].to_numpy(), runs, amp))
    return df[MARGIN_COLUMNS]


class _Project:
    """A view of a ChunkStore that stores ``project(chunk)`` instead of the whole chunk (the sweep keeps 6 columns)."""

    def __init__(self, store: ChunkSource, project):
        self.store, self.project = store, project

    def get(self, key, compute):
        return self.store.get(key, lambda: self.project(compute()))


def _signs(spec: StudySpec, path_index: int, runs: np.ndarray) -> np.ndarray:
    from pfjax.montecarlo.sampling import run_keys

    return np.where(np.asarray(_sign_draws(run_keys(spec.seed, path_index, runs))), 1.0, -1.0)


@jax.jit
def _sign_draws(keys):
    """Per run (rear, front): a fair coin from the run's key (one program; op by op, each operation
    would be compiled on its own)."""
    from pfjax.montecarlo.sampling import Q

    draw = lambda k, q: jax.random.bernoulli(jax.random.fold_in(k, Q[q]))
    return jax.vmap(lambda k: jnp.stack([draw(k, "sign_r"), draw(k, "sign_f")]))(keys)
