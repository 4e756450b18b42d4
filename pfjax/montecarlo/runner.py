"""Run a Monte Carlo study: chunks of runs through the jitted simulator, rows streamed to Parquet.

For each path, chunk of run indices and controller: sample the chunk's scenarios (shared by all
controllers), pad the chunk to ``chunk_size`` (one compilation per controller and path shape),
simulate with ``record=False`` (memory independent of the horizon) and append one row per run
to ``runs.parquet``: path, controller, run index, every sampled parameter, every metric, status.
Outputs are written to a temporary directory and moved into place when complete.
"""

from __future__ import annotations

import time

import numpy as np

from pfjax.montecarlo.chunk_runs import (  # noqa: F401  (re-exported: a study's runs, chunk by chunk)
    SHARED_SAMPLES_BYTES,
    add_results,
    batch_size,
    check_record,
    controller_of,
    nominal_wheelbase,
    precision,
    sample_aligned,
    sample_few,
    sim_config,
    simulate_chunk,
    simulate_runs,
    simulate_scenarios,
    with_gains,
)
from pfjax.montecarlo.chunks import ChunkStore, file_metadata
from pfjax.montecarlo.config import StudySpec
from pfjax.montecarlo.margin import (  # noqa: F401  (re-exported: the slip-margin sweep)
    MARGIN_COLUMNS,
    MARGIN_RUN_OFFSET,
    SWEEP_COUNT_KEYS,
    margin_sweep,
)
from pfjax.outputs import OutputDir


def controllers_of(spec: StudySpec, names=None) -> dict:
    """``{name: (controller, gains, flat gains)}`` for the study's controllers (LMI designs
    synthesised), or only those named in ``names``."""
    with precision(spec):
        return {
            c.name: controller_of(c, spec, i)
            for i, c in enumerate(spec.controllers)
            if names is None or c.name in names
        }


def run_study(
    spec: StudySpec,
    out,
    *,
    progress: bool | None = None,
    extra=None,
    fresh: bool = False,
    controllers: dict | None = None,
    overwrite: bool = False,
) -> dict:
    """Run ``spec``, write ``out/runs.parquet`` and return the run table's location and timings.

    ``out``: the output directory, or an :class:`~pfjax.outputs.OutputDir` the caller opened (it
    is committed here, and closed by its owner). A directory path is checked and locked as
    :class:`~pfjax.outputs.OutputDir` describes (``overwrite``: replace another pfjax output).
    Finished chunks are kept in :class:`~pfjax.montecarlo.chunks.ChunkStore` next to ``out``, so
    re-running after an interruption resumes (``fresh=True`` discards them first). ``extra(tmp_dir,
    runs_path, controllers, store)`` is called before the directory is moved into place (the margin
    sweep, summary and report are written there), so a failure leaves nothing half-written at ``out``.
    ``controllers``: :func:`controllers_of` ``(spec)`` if the caller already has them.
    """
    if isinstance(out, OutputDir) and out.is_open:
        return _run_study(spec, out, progress=progress, extra=extra, fresh=fresh, controllers=controllers)
    with out if isinstance(out, OutputDir) else study_output(spec, out, overwrite=overwrite) as output:
        return _run_study(spec, output, progress=progress, extra=extra, fresh=fresh, controllers=controllers)


def study_target(spec: StudySpec, out=None):
    """A study's output directory: ``out``, or ``results/<name>`` (:func:`pfjax.outputs.default_target`)."""
    from pfjax.outputs import default_target

    return default_target(spec.name, out)


def study_output(
    spec: StudySpec,
    out=None,
    *,
    overwrite: bool = False,
    flag: str = "--out",
) -> OutputDir:
    """The (unopened) :class:`~pfjax.outputs.OutputDir` of a study: ``out`` or ``results/<name>``.
    Its refusals name ``out`` as ``flag`` and give their advice in the same words (``--out`` and
    ``--overwrite`` for ``pfjax study``, ``out`` and ``overwrite=True`` for :func:`pfjax.run_study`;
    :func:`pfjax.outputs.switch_advice`)."""
    from pfjax.montecarlo.config import study_hash

    return OutputDir(
        study_target(spec, out),
        command="study",
        config_sha256=study_hash(spec),
        overwrite=overwrite,
        flag=flag,
        extra={"study": spec.name, "seed": spec.seed},
    )


def _run_study(spec: StudySpec, output: OutputDir, *, progress, extra, fresh, controllers) -> dict:
    from tqdm import tqdm

    t0 = time.time()
    controllers = controllers_of(spec) if controllers is None else controllers
    store = ChunkStore(output.target, spec, fresh=fresh, flag=output.flag)
    tmp = output.staging
    with precision(spec):
        total = spec.n_runs * len(spec.paths) * len(controllers)
        keys = []
        with tqdm(total=total, desc=spec.name, unit="run", disable=None if progress is None else not progress) as bar:
            for p in range(len(spec.paths)):
                for _, key, df in simulate_runs(spec, p, np.arange(spec.n_runs), controllers, store=store):
                    keys.append(key)
                    bar.update(len(df))
        store.merge(keys, tmp / "runs.parquet", file_metadata(spec))
        info = {"wall_s_simulation": time.time() - t0, "gains": {k: v[2] for k, v in controllers.items()}}
        if extra is not None:
            info.update(extra(tmp, tmp / "runs.parquet", controllers, store) or {})
    info["chunks"] = {"simulated": store.computed, "resumed": store.reused}
    output.commit()
    store.discard()
    info["wall_s"] = time.time() - t0
    return info
