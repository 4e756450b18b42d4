"""Several controllers as one: the controller a run uses is data, so runs of different controllers
share one compiled simulator program.

A study compiles each of its simulator programs once per controller kind (the compiled program
holds the controller's code). For its small side computations (the worst-case search's gradient
steps and random search, the float64 re-simulation, the replay of one run), where compilation costs
seconds and the simulation milliseconds, :func:`shared` gives every controller of the study the
same controller, :func:`union` of the study's kinds, and selects each one's part through its
parameters (:class:`UnionParams`)::

    delta_cmd = output_k(params_k, c_k, obs),   k = which,
    c_k' = rate_k(params_k, c_k, obs, delta_cmd, delta),   c_j' = 0 for j != k.

The selection is exact (no arithmetic mixes the parts), and every part's state starts at its own
``init`` and stays there unless selected. For one run (and a batch whose runs share ``which``, as a
vmapped search over starting points does) ``which`` is a single number and the step runs only the
selected part (:func:`jax.lax.switch`); where each run of a batch carries its own ``which``, JAX
evaluates every part and keeps the selected one, so a run costs the sum of the parts. The study's
runs therefore keep one program per kind.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import Array

from pfjax.controllers.base import Controller, Observation

__all__ = ["UnionParams", "shared", "union", "union_params"]


class UnionParams(NamedTuple):
    """The parameters of a :func:`union`: the selected part's index and every part's parameters
    (those of the unselected parts are evaluated, never used: any finite values of their shapes)."""

    which: Array  # int32, index of the part that steers
    parts: tuple  # each part's parameter pytree, in the union's order


@functools.cache
def union(parts: tuple[Controller, ...]) -> Controller:
    """The controller that runs ``parts[which]`` (module docstring). Cached: the same parts give
    the same controller object, which is what a compiled program is keyed on."""

    def init(p: UnionParams):
        return tuple(part.init(q) for part, q in zip(parts, p.parts))

    def output(p: UnionParams, c, obs: Observation) -> Array:
        branches = [functools.partial(_output_of, part, k) for k, part in enumerate(parts)]
        return jax.lax.switch(p.which, branches, p, c, obs)

    def rate(p: UnionParams, c, obs: Observation, delta_cmd: Array, delta: Array):
        branches = [functools.partial(_rate_of, part, k) for k, part in enumerate(parts)]
        return jax.lax.switch(p.which, branches, p, c, obs, delta_cmd, delta)

    name = "union(" + ",".join(part.name for part in parts) + ")"
    return Controller(name, init, output, rate, UnionParams)


def _output_of(part: Controller, k: int, p: UnionParams, c, obs: Observation) -> Array:
    return part.output(p.parts[k], c[k], obs)


def _rate_of(part: Controller, k: int, p: UnionParams, c, obs, delta_cmd, delta):
    own = part.rate(p.parts[k], c[k], obs, delta_cmd, delta)
    zero = lambda tree: jax.tree_util.tree_map(jnp.zeros_like, tree)
    return tuple(own if j == k else zero(cj) for j, cj in enumerate(c))


def union_params(parts: tuple[Controller, ...], which: int, params, fill: tuple) -> UnionParams:
    """:class:`UnionParams` selecting ``parts[which]`` with ``params``; ``fill[j]``: parameters of
    ``parts[j]`` for the unselected parts (finite values of the shapes that part takes)."""
    return UnionParams(
        jnp.asarray(which, jnp.int32), tuple(params if j == which else fill[j] for j in range(len(parts)))
    )


def shared(controllers: dict) -> dict:
    """``{name: (controller, gains, flat)}`` (a study's controllers, as
    :func:`pfjax.montecarlo.chunk_runs.controller_of` gives them) with one controller for all: the
    :func:`union` of their distinct controllers, each one's gains as :class:`UnionParams` (the
    unselected parts filled with the first gains of their kind). Returned unchanged where the
    controllers are all one kind already."""
    kinds: list[Controller] = []
    fill: list = []
    for ctrl, gains, _ in controllers.values():
        if ctrl not in kinds:
            kinds.append(ctrl)
            fill.append(gains)
    if len(kinds) < 2:
        return controllers
    parts = tuple(kinds)
    one = union(parts)
    return {
        name: (one, union_params(parts, parts.index(ctrl), gains, tuple(fill)), flat)
        for name, (ctrl, gains, flat) in controllers.items()
    }
