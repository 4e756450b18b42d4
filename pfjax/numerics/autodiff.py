"""Value and gradient of a scalar function, by forward or reverse mode chosen from the parameter count.

A simulated loss ``J(theta)`` of ``D`` parameters has two ways to its gradient:

* **forward mode**: ``D`` Jacobian-vector products ``dJ = J'(theta) e_i`` (``jax.jvp``, vmapped over
  the basis vectors ``e_i``), evaluated alongside the forward pass. Cost about ``1 + c D`` forward
  passes, memory independent of the horizon.
* **reverse mode** (``jax.value_and_grad``): one backward pass through the ``lax.scan``, which
  recomputes every step (``jax.checkpoint``) and stores the carry per step: a fixed multiple of
  the forward pass whatever ``D``, memory O(horizon) per run.

Measured on the benchmark problem (slip model, 2,000 runs, 4,000 steps, float32, 2 CPU devices;
README, Performance): forward mode costs 1.33 / 2.19 / 3.03 / 4.87 forward passes for D = 1 / 2 / 4 / 8
(value and all D derivatives, CPU time), reverse mode 3.2-3.4 for any D (see :data:`FORWARD_MAX`;
about 5 % less since reverse mode saves the projection's last-but-one Newton iterate).
``mode="auto"`` therefore takes forward mode up to :data:`FORWARD_MAX` parameters (controller
gains) and reverse mode above it (a falsifier's scenario parameters). Both give the same derivative
up to rounding (tested).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax.flatten_util import ravel_pytree

#: Parameters up to which ``mode="auto"`` uses forward mode. Measured on the benchmark (CPU time,
#: value and gradient over the forward pass): forward mode 1.33 / 2.19 / 3.03 / 4.87 for D = 1 / 2 /
#: 4 / 8, reverse mode 3.2-3.4 for any D, so the crossover is about 5 (it was about 12, with forward
#: 8, before the simulator computed its command, steering and closest point once, which made reverse
#: mode about 30 % cheaper and forward mode about 13 % dearer).
FORWARD_MAX = 4
MODES = ("auto", "forward", "reverse")


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
        ``params``. Works under ``jit`` and ``vmap``.
    """
    resolve_mode(mode, 0)  # validate early

    def vg(params, *args):
        flat, unravel = ravel_pytree(params)
        if flat.size == 0 or resolve_mode(mode, flat.size) == "reverse":
            return jax.value_and_grad(fun, has_aux=has_aux)(params, *args)
        f = lambda v: fun(unravel(v), *args)
        basis = jnp.eye(flat.size, dtype=flat.dtype)
        if has_aux:
            value, dirs, aux = jax.vmap(lambda t: jax.jvp(f, (flat,), (t,), has_aux=True), out_axes=(None, 0, None))(
                basis
            )
            return (value, aux), unravel(dirs)
        value, dirs = jax.vmap(lambda t: jax.jvp(f, (flat,), (t,)), out_axes=(None, 0))(basis)
        return value, unravel(dirs)

    return vg
