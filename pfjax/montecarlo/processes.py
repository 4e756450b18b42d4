"""A study over several processes or hosts: what process 0 tells the others before the runs.

Every process runs the same study and calls the same sharded simulator programs in the same
order (each chunk's batch is split over the devices of all processes, see
:mod:`pfjax.sim.sharding`); process 0 writes everything. Two things must therefore be the same
in every process, and process 0 decides both (:func:`lead`, broadcast once, before any chunk):

* **which chunks are already finished.** Process 0 resumes an interrupted run from its partial
  directory (:class:`~pfjax.montecarlo.chunks.ChunkStore`), which the others cannot see (another
  host's disk); they skip exactly the chunks it skips, so the programs stay in step.
* **the controllers' gains.** An LMI design is solved by cvxpy in each process; on hosts with other
  numerical libraries the solutions could differ in the last bits, and each process would simulate
  its share of every chunk with its own gains. The others use process 0's gains instead (as state
  feedback: the same compiled program, see :func:`pfjax.montecarlo.runner.controller_of`), and
  skip the synthesis.

Before that, every process checks that all were given the same study (:func:`check_same_study`:
the config with its ``--set`` values, by its hash), and process 0 opens its output directory. If
process 0 fails before the hand-over (an ``--out`` it refuses, a config whose partial directory
holds another study's chunks, an infeasible design), it sends the error instead
(:func:`refused`, :func:`lead`), and every process stops with it.

The other processes (:func:`follow`) only simulate: no side jobs (worst-case search, float64
check: process 0 runs them on its own device), no summary, no report, nothing written.
"""

from __future__ import annotations

import contextlib

import numpy as np

from pfjax.config import ConfigError
from pfjax.errors import InputError
from pfjax.montecarlo.config import ControllerSpec, StudySpec
from pfjax.sim import sharding


class _Skip:
    """A stand-in for :class:`~pfjax.montecarlo.chunks.ChunkStore` in the processes that do not
    write: a chunk process 0 has finished is skipped (an empty table), any other is simulated
    (its collective programs) and dropped."""

    def __init__(self, finished):
        self.finished, self.computed, self.reused = set(finished), 0, 0

    def get(self, key, compute):
        import pandas as pd

        if key in self.finished:
            self.reused += 1
            return pd.DataFrame()
        compute()
        self.computed += 1
        return pd.DataFrame()


def check_same_study(spec: StudySpec) -> None:
    """Every process's study hash (:func:`pfjax.montecarlo.config.study_hash`), compared in every
    process (a collective, before any chunk): :class:`~pfjax.config.ConfigError`, the same line in
    every process, if one was given another config or other ``--set`` values. Each would otherwise
    simulate its share of every chunk with its own settings, and process 0 would write the mixture
    under its own hash."""
    from pfjax.montecarlo.config import study_hash

    hashes = sharding.every_process(study_hash(spec))
    other = next((i for i, h in enumerate(hashes) if h != hashes[0]), None)
    if other is not None:
        raise ConfigError(
            f"config: process {other}'s study differs from process 0's (config hash {hashes[other][:12]} against "
            f"{hashes[0][:12]}); give every process the same config file and --set values"
        )


@contextlib.contextmanager
def refused(count: int):
    """Around process 0's steps before the hand-over that can refuse (opening ``--out``): an
    error is sent to the other processes (as :func:`lead` sends its own), then raised."""
    try:
        yield
    except Exception as e:
        if count > 1:
            sharding.broadcast_json({"error": str(e), "usage": isinstance(e, InputError)})
        raise


def lead(spec: StudySpec, output, *, fresh: bool = False) -> dict:
    """Process 0's side of the hand-over: open (lock) the study's output
    (:class:`~pfjax.outputs.OutputDir`), open (or resume) its chunk store, synthesise the
    controllers and send the finished chunks' keys and the gains to the other processes. Returns
    :func:`pfjax.montecarlo.runner.controllers_of` ``(spec)`` (to pass on to the study).

    Raises what it raises, after telling the other processes."""
    from pfjax.montecarlo.chunks import ChunkStore
    from pfjax.montecarlo.runner import controllers_of

    try:
        output.open()
        store = ChunkStore(output.target, spec, fresh=fresh, flag=output.flag)
        controllers = controllers_of(spec)
    except Exception as e:
        sharding.broadcast_json({"error": str(e), "usage": isinstance(e, InputError)})
        raise
    gains = {c.name: controllers[c.name][2] for c in spec.controllers}
    sharding.broadcast_json({"finished": store.finished(), "gains": gains})
    return controllers


def follow(spec: StudySpec) -> dict:
    """A non-writing process's study: receive process 0's hand-over (:func:`lead`), then simulate
    the chunks process 0 has not finished, in its order (the runs, then the slip-margin sweep).
    Returns ``{"simulated": n, "resumed": m}`` chunks.

    Raises:
        ConfigError: process 0 stopped on a config error (its message).
        RuntimeError: process 0 stopped on any other error.
    """
    from pfjax import controllers as C
    from pfjax.montecarlo.runner import controllers_of, margin_sweep, precision, simulate_runs

    msg = sharding.broadcast_json(None)
    if "error" in msg:
        raise (ConfigError if msg["usage"] else RuntimeError)(msg["error"])
    designed = lambda c: C.DESIGNS[c.type].controller  # process 0's design, its gains broadcast
    spec = spec.model_copy(
        update={
            "controllers": [
                ControllerSpec(name=c.name, type=designed(c), gains=msg["gains"][c.name]) if c.type in C.DESIGNS else c
                for c in spec.controllers
            ]
        }
    )
    controllers = controllers_of(spec)
    skip = _Skip(msg["finished"])
    with precision(spec):
        for p in range(len(spec.paths)):
            for _ in simulate_runs(spec, p, np.arange(spec.n_runs), controllers, store=skip):
                pass
        if spec.margin.enabled:
            margin_sweep(spec, controllers, progress=False, store=skip)
    return {"simulated": skip.computed, "resumed": skip.reused}
