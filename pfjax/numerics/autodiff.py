"""Value and gradient of a scalar function, by forward or reverse mode chosen from the parameter count.

A simulated loss ``J(theta)`` of ``D`` parameters has two ways to its gradient:

* **forward mode**: ``D`` Jacobian-vector products ``dJ = J'(theta) e_i`` along the basis vectors,
  evaluated alongside the forward pass. Cost about ``1 + c D`` forward passes, memory independent
  of the horizon.
* **reverse mode** (``jax.value_and_grad``): one backward pass through the ``lax.scan``, which
  recomputes every step (``jax.checkpoint``) and stores the carry per step, or for many runs over
  many steps per segment of steps (:func:`pfjax.sim.loop.checkpoint_segment`): a fixed multiple of
  the forward pass whatever ``D``, memory O(horizon) per run (O(sqrt(horizon)) in segments).

Measured on the benchmark problem (slip model, 2,000 runs, 4,000 steps, float32, 2 CPU devices,
a 2-core AMD EPYC of CPU family 26 (Zen 5), jax 0.10.2; wall time of the value and all ``D``
derivatives over the forward pass, each function timed in a window of consecutive calls,
:func:`pfjax.bench.timing.interleaved`): forward mode 1.44-1.46 / 1.85-1.91 / 2.92-3.04 /
3.59-3.66 for D = 1 / 2 / 3 / 4 with each device's runs in one block, 1.33-1.34 / 1.59-1.65 /
2.49-2.52 / 2.90-3.00 in blocks sized for a value and its tangents
(:func:`pfjax.sim.sharding.default_block`); reverse mode 3.71-3.73 for any D, in checkpointed
segments (docs/performance.md, Gradients). ``mode="auto"`` therefore takes forward mode up to
:data:`FORWARD_MAX` parameters (controller gains) and reverse mode above it (a falsifier's scenario
parameters). Both give the same derivative up to rounding (tested).

**How the tangents travel** (:data:`NESTED_MAX`). ``D`` tangents as one batch (``vmap`` of
``jax.jvp`` over the basis) are arrays of shape ``(D, runs)`` beside the ``(runs,)`` primal values,
and XLA's CPU backend puts the two shapes in separate kernels: batched, the second tangent cost
0.87 forward passes where the first cost 0.45 (nested, 0.41). Nested ``jax.jvp`` calls, one
direction each, keep every array at the primal's shape; they also trace the ``2^D - 1 - D`` higher
derivatives that nothing reads, which XLA removes from the loop but which lengthen compilation.
Measured as above (one block per device, no compilation cache; gradient over the forward pass,
then compile time): D = 2: 1.86x nested against 2.32x batched, 1.92 against 1.38 s; D = 3: 2.45x
against 3.01x, 2.55 against 1.64 s. Nested up to D = 2, where one program compiles in about the
same time. A tuning run compiles several, and there the nesting cost some compilation and saved no
run time where the batch is small: ``pfjax tune --method gradient --controller pi --scenario
paper-all`` (9 runs) compiled in 25.1 and 25.9 s against 24.7 and 25.3 s batched, ran in
0.97-0.99 s both ways, and reached the same gains; a test's short tunings took 23.4-23.7 s against
21.3-22.4 s (no compilation cache, two runs each, alternated).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

#: Parameters up to which ``mode="auto"`` uses forward mode. Measured on the benchmark (module
#: docstring): forward mode 3.59-3.66 forward passes for D = 4 in one block per device (2.90-3.00 in
#: blocks), reverse mode 3.71-3.73 for any D. Forward mode's cost grows by about half a forward pass
#: per parameter, so the crossover lies at D = 4 whole and between D = 5 and 6 in blocks at that batch; not
#: measured at other batches (at 250 runs per device reverse mode took 3.15 forward passes).
FORWARD_MAX = 4
MODES = ("auto", "forward", "reverse")
#: Parameters up to which forward mode nests one ``jax.jvp`` per direction instead of batching the
#: directions (module docstring: faster at every D measured, but its compilation grows as 2^D).
NESTED_MAX = 2


def resolve_mode(mode: str, n_params: int) -> str:
    """``"forward"`` or ``"reverse"`` for ``n_params`` scalar parameters."""
    if mode not in MODES:
        raise ValueError(f"mode: must be one of {', '.join(MODES)}, got {mode!r}")
    if mode == "auto":
        return "forward" if n_params <= FORWARD_MAX else "reverse"
    return mode


def forward_passes_per_gradient(n_params: int, mode: str = "auto") -> int:
    """Forward-pass equivalents of one rollout with its gradient: ``1 + n_params`` in forward mode
    (the value and one tangent per parameter), 4 in reverse mode (the forward loop, then the
    recomputed step and its transpose)."""
    return 1 + n_params if resolve_mode(mode, n_params) == "forward" else 4


def value_and_grad(fun: Callable, *, mode: str = "auto", has_aux: bool = False) -> Callable:
    """Like ``jax.value_and_grad(fun, has_aux=has_aux)`` (first argument only), by ``mode``.

    Args:
        fun: ``fun(params, *args) -> scalar`` (or ``(scalar, aux)`` with ``has_aux``); ``params`` a
            pytree of floating arrays.
        mode: ``"forward"``, ``"reverse"`` or ``"auto"`` (forward for at most :data:`FORWARD_MAX`
            scalar parameters).

    Returns:
        ``g(params, *args) -> (value, grad)`` or ``((value, aux), grad)``, ``grad`` shaped like
        ``params`` and of its leaves' dtypes (as ``jax.grad``'s, whatever the value's precision).
        Works under ``jit`` and ``vmap``. Parameters that are not all real floating (complex,
        integer) go to ``jax.value_and_grad`` whatever ``mode``, which takes complex ones and
        refuses integer ones; a value that is not a real scalar is refused with JAX's
        ``TypeError`` in either mode.
    """
    resolve_mode(mode, 0)  # validate early

    def vg(params, *args):
        flat, unravel = ravel_pytree(params)
        if flat.size == 0 or resolve_mode(mode, flat.size) == "reverse" or not _real_floating(params):
            return jax.value_and_grad(fun, has_aux=has_aux)(params, *args)
        f = lambda v: fun(unravel(v), *args)
        basis = jnp.eye(flat.size, dtype=flat.dtype)
        if flat.size <= NESTED_MAX:
            (value, *dirs), aux = _nested_jvp(f if has_aux else lambda v: (f(v), None), flat, basis)
            dirs = jnp.stack(dirs)
        elif has_aux:
            value, dirs, aux = _batched_jvp_with_aux(f, flat, basis)
        else:
            value, dirs = jax.vmap(lambda t: jax.jvp(f, (flat,), (t,)), out_axes=(None, 0))(basis)
        _check_output(value)
        grad = unravel(dirs.astype(flat.dtype))  # each leaf back to its own dtype
        return ((value, aux), grad) if has_aux else (value, grad)

    return vg


def _batched_jvp_with_aux(f: Callable, x, basis) -> tuple:
    """``(f(x), (f'(x) e_i)_i, aux)`` for ``f(x) -> (scalar, aux)``, the directions as one batch
    (``vmap`` of ``jax.jvp``). A batched function returns only JAX values, so the aux's other
    leaves (a name, a Python number) leave it by the one trace and join its arrays after."""
    static: list = []

    def one(t):
        value, tangent, aux = jax.jvp(f, (x,), (t,), has_aux=True)
        leaves, treedef = jax.tree_util.tree_flatten(aux)
        is_array = [_jax_value(leaf) for leaf in leaves]
        static[:] = [treedef, is_array, [leaf for leaf, a in zip(leaves, is_array) if not a]]
        return value, tangent, [leaf for leaf, a in zip(leaves, is_array) if a]

    value, dirs, arrays = jax.vmap(one, out_axes=(None, 0, None))(basis)
    treedef, is_array, others = static
    arrays, others = iter(arrays), iter(others)
    return value, dirs, jax.tree_util.tree_unflatten(treedef, [next(arrays if a else others) for a in is_array])


def _real_floating(params) -> bool:
    """Whether every leaf is real floating: forward mode's basis tangents are real, so a complex
    parameter would get the derivative along its real axis only, an integer one float0 tangents."""
    return all(jnp.issubdtype(jnp.result_type(leaf), jnp.floating) for leaf in jax.tree_util.tree_leaves(params))


def _jax_value(leaf) -> bool:
    """Whether an aux leaf is a JAX value a batched function may return: a JAX array, or a NumPy
    array or scalar of a numeric or boolean dtype (not strings, objects or dates)."""
    if isinstance(leaf, jax.Array):
        return True
    if isinstance(leaf, (np.ndarray, np.generic)):
        return bool(jnp.issubdtype(leaf.dtype, jnp.number) or jnp.issubdtype(leaf.dtype, jnp.bool_))
    return False


def _check_output(value) -> None:
    """``jax.grad``'s refusal of a value that is not a real scalar (forward mode would return the
    Jacobian of a vector, or float0 tangents of an integer)."""
    if jnp.shape(value) != ():
        raise TypeError(f"Gradient only defined for scalar-output functions. Output had shape: {jnp.shape(value)}.")
    if not jnp.issubdtype(jnp.result_type(value), jnp.floating):
        raise TypeError(f"value_and_grad requires a real-valued output, got {jnp.result_type(value)}")


def _nested_jvp(f: Callable, x, basis) -> tuple[tuple, object]:
    """``((f(x), f'(x) e_1, ..., f'(x) e_D), aux)`` for ``f(x) -> (scalar, aux)``, by one
    ``jax.jvp`` per basis vector ``e_i``, each around the previous (module docstring); of each
    level's tangents only the new direction's first derivative is kept."""

    def level(g, e):
        def lifted(v):
            values, tangents, aux = jax.jvp(g, (v,), (e,), has_aux=True)
            return (*values, tangents[0]), aux

        return lifted

    g = lambda v: (lambda out: ((out[0],), out[1]))(f(v))
    for e in basis:
        g = level(g, e)
    return g(x)
