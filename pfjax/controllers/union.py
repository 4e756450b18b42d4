"""Several controllers as one: the controller a run uses is data, so runs of different controllers
share one compiled simulator program.

A study compiles each of its simulator programs once per controller kind (the compiled program
holds the controller's code). For its small side computations (the worst-case search's gradient
steps and random search, the float64 re-simulation, the replay of one run), where compilation costs
seconds and the simulation milliseconds (and for the paper reproduction's single runs of its six
controllers), :func:`shared` gives every controller the same controller, :func:`union` of their
kinds, and selects each one's part through its parameters (:class:`UnionParams`)::

    delta_cmd = output_k(params_k, c_k, obs),   k = which,
    c_k' = rate_k(params_k, c_k, obs, delta_cmd, delta),   c_j' = 0 for j != k.

No arithmetic mixes the parts: a run follows its own controller's control law, and its numbers
agree with that controller's own program to rounding (the two programs are compiled apart, so a
multiply-add may round differently; tests/test_union.py). Every part's state starts at its own
``init`` and stays there unless selected.

Where ``which`` is not batched (one run, or a batch vmapped with ``which`` held fixed, as the
falsifier's gradient steps vmap over their starting points only) the step runs the selected part
alone (:func:`jax.lax.switch`). Where every run of a batch carries its own ``which`` (a batch of
scenarios, as the random search and the float64 check simulate), JAX evaluates every part on every
run and keeps the selected one: a run then costs the sum of the parts, and every part must be safe
on any run's observation (no loop whose end depends on the data, no host callback). A value the
unselected parts compute, even a NaN, reaches neither the result nor its gradients. The study's
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
    (those of the unselected parts set their states' ``init`` and, where ``which`` is batched, are
    evaluated but never used: any values of the types and shapes their parts take)."""

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
    ``parts[j]`` for the unselected parts (values of the type and shapes that part takes).

    Raises:
        InputError: ``which`` not an index of ``parts``, ``fill`` not one entry per part, or
            ``params`` (or a ``fill`` entry) not its part's parameter type, naming ``which``,
            ``fill`` or ``gains``.
    """
    from pfjax.errors import InputError, integer

    which = integer("which", which, low=0, high=len(parts) - 1)
    if len(fill) != len(parts):
        raise InputError(f"fill: {len(fill)} parameter sets for {len(parts)} parts", "fill")
    given = tuple(params if j == which else fill[j] for j in range(len(parts)))
    for part, q in zip(parts, given):
        part.check_params(q)
    return UnionParams(jnp.asarray(which, jnp.int32), given)


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
