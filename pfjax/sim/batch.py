"""Batched entry points of the simulators on :mod:`pfjax.sim.loop`: one single-run function, ``vmap``-ed
over the leading axis of a batch of scenarios, split over devices and cache-sized blocks
(:mod:`pfjax.sim.sharding`), compiled with :func:`pfjax.numerics.compiler.jit` and called.

Each simulator module (the slip vehicle :mod:`pfjax.sim.simulate`, the dynamic vehicle
:mod:`pfjax.sim.dynamic`, formation tracking :mod:`pfjax.tracking.simulate`) builds its two compiled
entry points with :func:`programs`: the batched :func:`program` (registered under the module's
name), which it calls with :func:`call`, and the single run :func:`one_run`, which a command that
simulates one run (``pfjax simulate``, ``pfjax track``) calls because it traces in less than half
the time of a batch of one. A recording simulator checks its memory first with
:func:`check_record`.
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

    ``run_one(sc, runs=..., **kwargs)`` is one run (pure, unbatched; ``runs``: the layout's runs per
    device in all blocks, which decide its reverse-mode checkpoints, :func:`pfjax.sim.loop.run`);
    its keyword arguments ``static`` (a controller, a config: hashable) and the batch's ``layout``
    are static arguments of the program, so it compiles once per their values, the batch's shape,
    device set and block count. The program is registered as ``module.name``
    (:data:`pfjax.numerics.compiler.PROGRAMS`) and keeps that name in its compiled module.
    """

    def run_batch(scenarios, *, layout: sharding.Layout = sharding.Layout(None, 1), **kwargs):
        return sharding.map_runs(lambda sc: run_one(sc, runs=layout.runs, **kwargs), scenarios, layout)

    run_batch.__module__ = module
    run_batch.__name__ = run_batch.__qualname__ = name
    return compiler.jit(run_batch, static_argnames=(*static, "layout"))


def one_run(run_one: Callable[..., Any], *, module: str, name: str, static: tuple[str, ...]):
    """The jitted ``run_one`` itself, for one run without a batch axis (``run_one`` and ``static``
    as in :func:`program`).

    A batch of one costs the batched program's tracing, which ``vmap`` more than doubles: for the
    slip simulator 0.58-0.66 s of tracing and 0.19 s of lowering against 0.22-0.29 s and 0.11-0.15 s
    unbatched, with compilation about the same (1.0-1.6 s; three runs each on a 2-core AMD EPYC,
    jax 0.10.2). Tracing and lowering are paid in every process, with the compiled program in the
    persistent cache too: they are most of a warm one-run command's start-up. The per-run code is the
    same; XLA compiles it into other machine code, which may round a step's arithmetic differently
    in its last bit (measured: at most 1 ulp in a metric of ``pfjax simulate``; tests/test_sharding.py
    compares every simulator's single-run and batched programs). Compiled with
    XLA's default options: a single run has no batch axis to vectorise.
    """

    def run(scenario, **kwargs):
        return run_one(scenario, **kwargs)

    run.__module__ = module
    run.__name__ = run.__qualname__ = name
    return jax.jit(run, static_argnames=static)


def programs(run_one: Callable[..., Any], *, module: str, static: tuple[str, ...]):
    """A simulator module's two compiled entry points of ``run_one``: ``(batched, single)``, the
    :func:`program` registered as ``module._simulate_vmapped`` and the :func:`one_run` named
    ``module._simulate_one``."""
    return (
        program(run_one, module=module, name="_simulate_vmapped", static=static),
        one_run(run_one, module=module, name="_simulate_one", static=static),
    )


def call(jitted, scenarios, *, devices=None, block: int | str | None = "auto", **static):
    """``jitted`` (from :func:`program`) on a batch of scenarios (leading axis of every leaf),
    sharded over ``devices`` (default: every device JAX sees) and in blocks of ``block`` runs
    (``"auto"``: :func:`pfjax.sim.sharding.default_block`, or ``None`` for one block); the padding
    runs are cut off the result. Under ``jit``/``grad`` the batch is not re-sharded, and is blocked
    only when ``block`` is a number of runs (:func:`pfjax.sim.sharding.plan_batch`)."""
    placed, n, layout = sharding.plan_batch(scenarios, devices, block)
    return sharding.unpad(jitted(placed, layout=layout, **static), n)


def vehicle_programs(simulate: Callable[..., Any], *, module: str):
    """:func:`programs` of a controlled vehicle's ``simulate(controller, sc, config, *, runs)`` (the
    slip and the dynamic vehicle): the controller and the config static, ``runs`` from the layout."""
    return programs(
        lambda sc, *, controller, config, runs=1: simulate(controller, sc, config, runs=runs),
        module=module,
        static=("controller", "config"),
    )


def check_record(
    scenarios, n_steps: int, *, copies: int = 1, key: str = "record", runs: int | None = None, hint: str | None = None
) -> None:
    """Refuses (:class:`~pfjax.errors.InputError` naming ``key``, default ``record``) to record
    ``N + 1 = n_steps + 1`` samples of every run of a concrete batch when ``copies`` trajectories of
    that size per run would not fit in memory (:func:`pfjax.resources.check_memory`); traced batches
    are not checked. ``runs``: the caller's own run count, when the batch holds padding runs too
    (the message says both); ``hint``: what to do instead, in the caller's words."""
    if errors.is_traced(scenarios):
        return
    n_runs = int(np.shape(jax.tree_util.tree_leaves(scenarios)[0])[0])
    told = n_runs if runs is None else int(runs)
    resources.check_memory(
        key,
        n_runs * copies * resources.run_bytes(n_steps, record=True),
        f"recording {told} runs" + (f" (padded to {n_runs})" if told != n_runs else "") + f" of {n_steps + 1} samples",
        hint or "simulate with record=False (the metrics need no trajectory), or fewer runs",
    )
