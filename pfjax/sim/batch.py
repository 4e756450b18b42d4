"""Batched entry points of the simulators on :mod:`pfjax.sim.loop`: one single-run function, ``vmap``-ed
over the leading axis of a batch of scenarios, split over devices and cache-sized blocks
(:mod:`pfjax.sim.sharding`), compiled with :func:`pfjax.numerics.compiler.jit` and called.

Each simulator module (the slip vehicle :mod:`pfjax.sim.simulate`, the dynamic vehicle
:mod:`pfjax.sim.dynamic`, formation tracking :mod:`pfjax.tracking.simulate`) builds its compiled
program with :func:`program` (one program per module, registered under the module's name) and calls it
with :func:`call`; a recording simulator checks its memory first with :func:`check_record`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from pfjax import errors, resources
from pfjax.numerics import compiler
from pfjax.sim import sharding


def program(run_one: Callable[..., Any], *, module: str, name: str, static: tuple[str, ...]):
    """The jitted ``vmap(run_one)`` over a batch placed by :func:`pfjax.sim.sharding.plan_batch`.

    ``run_one(sc, **kwargs)`` is one run (pure, unbatched); its keyword arguments ``static`` (a
    controller, a config: hashable) and the batch's ``layout`` are static arguments of the program,
    so it compiles once per their values, the batch's shape, device set and block count. The program
    is registered as ``module.name`` (:data:`pfjax.numerics.compiler.PROGRAMS`) and keeps that
    name in its compiled module.
    """

    def run_batch(scenarios, *, layout: sharding.Layout = sharding.Layout(None, 1), **kwargs):
        return sharding.map_runs(lambda sc: run_one(sc, **kwargs), scenarios, layout)

    run_batch.__module__ = module
    run_batch.__name__ = run_batch.__qualname__ = name
    return compiler.jit(run_batch, static_argnames=(*static, "layout"))


def call(jitted, scenarios, *, devices=None, block: int | str | None = "auto", **static):
    """``jitted`` (from :func:`program`) on a batch of scenarios (leading axis of every leaf), sharded
    over ``devices`` (default: every device JAX sees) and, on CPU, in blocks of ``block`` runs
    (``"auto"``, or ``None`` for one block); the padding runs are cut off the result. Under
    ``jit``/``grad`` the batch is not re-sharded or blocked (the outer call decides)."""
    placed, n, layout = sharding.plan_batch(scenarios, devices, block)
    return sharding.unpad(jitted(placed, layout=layout, **static), n)


def check_record(scenarios, n_steps: int, *, copies: int = 1) -> None:
    """Refuses (:class:`~pfjax.errors.InputError` naming ``record``) to record ``N + 1 = n_steps + 1``
    samples of every run of a concrete batch when ``copies`` trajectories of that size per run would
    not fit in memory (:func:`pfjax.resources.check_memory`); traced batches are not checked."""
    if errors.is_traced(scenarios):
        return
    n_runs = int(np.shape(jax.tree_util.tree_leaves(scenarios)[0])[0])
    resources.check_memory(
        "record",
        n_runs * copies * resources.run_bytes(n_steps, record=True),
        f"recording {n_runs} runs of {n_steps + 1} samples",
        "simulate with record=False (the metrics need no trajectory), or fewer runs",
    )
