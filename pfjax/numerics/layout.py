"""Per-run pytrees as scalars, so XLA's CPU backend vectorises loop updates over the runs.

Under ``vmap`` a per-run leaf of shape ``(k,)`` becomes a ``(runs, k)`` array. When such an array is
a ``lax.scan`` / ``while_loop`` carry, or the cotangent of a loop-invariant input that reverse mode
accumulates in the backward loop's carry, every step rewrites it in a kernel over ``(runs, k)``,
which XLA's CPU backend evaluates element by element along the short ``k`` axis instead of as
vectors over the runs: measured, the cotangent of the slip benchmark's gain ``K`` (``k = 2``) was
one kernel taking 29 % of the backward step (README, Performance). Split into ``k`` scalars per run,
each update is a ``(runs,)`` array operation.

:func:`as_scalars` splits a tree's small array leaves into tuples of scalars and returns the
function that rebuilds the tree; inside a loop body, rebuild, compute, and split again.
:func:`first_true` and :func:`all_true` are ``jnp.select`` and ``jnp.all`` over a handful of per-run
conditions written elementwise, for the same reason: ``jnp.select`` stacks its conditions and takes
an ``argmax`` over them, and ``jnp.all`` of a per-run ``(k,)`` array is a reduction over the short
axis, both evaluated run by run.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

#: Largest leaf (elements per run) that :func:`as_scalars` splits; larger leaves stay whole (a
#: sampled slip sequence of hundreds of values is read by a gather, not updated every step).
SCALAR_LEAF_MAX = 16


def as_scalars(tree, max_size: int = SCALAR_LEAF_MAX):
    """Split each array leaf of ``tree`` with 1 to ``max_size`` elements (and at least one axis) into a
    tuple of its scalar elements (row-major order).

    Returns:
        ``(parts, join)``: ``parts`` is ``tree``'s leaves, split or whole, in flattening order, and
        ``join(parts)`` rebuilds a tree of the same structure, shapes and dtypes from such parts (the
        split leaves stacked back, under any tracing). Splitting a tree of the same structure and
        shapes again gives parts of the same structure, so ``parts`` can be a loop carry.
    """
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    shapes = [tuple(np.shape(a)) for a in leaves]
    split = [len(s) > 0 and 0 < int(np.prod(s)) <= max_size for s in shapes]
    parts = [tuple(jnp.ravel(jnp.asarray(a))) if sp else a for a, sp in zip(leaves, split)]

    def join(parts):
        rebuilt = [jnp.stack(p).reshape(s) if sp else p for p, s, sp in zip(parts, shapes, split)]
        return jax.tree_util.tree_unflatten(treedef, rebuilt)

    return parts, join


def first_true(conditions, values, default):
    """``values[i]`` for the first ``conditions[i]`` that holds, else ``default``, elementwise: the
    result of ``jnp.select(conditions, values, default)`` as a chain of ``jnp.where`` (no stacked
    conditions, no ``argmax``). The result has ``default``'s dtype (give a typed default)."""
    out = jnp.asarray(default)
    for cond, value in reversed(list(zip(conditions, values))):
        out = jnp.where(cond, jnp.asarray(value, out.dtype), out)
    return out


def all_true(conditions):
    """Elementwise AND of an iterable of boolean arrays (``jnp.all`` of their stack, without the
    stack and the reduction over its short axis)."""
    return functools.reduce(jnp.logical_and, conditions)
