"""Shard a batch of runs over every device JAX sees (CPU host devices, GPUs, several hosts).

Runs are independent, so the batch axis is split into equal contiguous blocks, one per device
(``jax.sharding.NamedSharding`` over a 1-D mesh named ``"runs"``); XLA compiles the vmapped
simulator once for the per-device block and runs the blocks in parallel, with no communication
until the caller gathers the results. The same code runs on:

* **CPU**: one device per core needs ``--xla_force_host_platform_device_count=N`` in ``XLA_FLAGS``
  *before* JAX initialises its backend. ``import pfjax`` sets it to the number of cores
  (:func:`pfjax.default_host_devices`) when JAX is not yet imported and the user has not set it;
  set ``PFJAX_HOST_DEVICES=1`` (or your own ``XLA_FLAGS``) to opt out. Import pfjax first.
* **GPUs**: every visible GPU is a device; nothing to set (``CUDA_VISIBLE_DEVICES`` selects them).
* **several hosts**: call ``jax.distributed.initialize()`` on every host first (coordinator
  address, number of processes, process id; automatic under SLURM / Cloud TPU); the mesh then
  spans ``jax.devices()`` of all hosts. Each process must pass the same global batch (same
  config and seed), and reads back its own rows (``addressable_shards``) or gathers them.

A batch whose size is not a multiple of the device count is padded by repeating its first run
and the padding is cut off again, so callers see exactly their runs. Inside a JAX transformation
(``jit``, ``grad``) the batch is left as it is: sharding is decided at the outermost call.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "runs"


def mesh(devices=None) -> Mesh:
    """A 1-D mesh over ``devices`` (default: all devices of the default backend, every host)."""
    devices = jax.devices() if devices is None else list(devices)
    return Mesh(np.asarray(devices), (AXIS,))


def _is_traced(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


def _pad(tree, n_to: int):
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    if n == n_to:
        return tree
    return jax.tree_util.tree_map(lambda a: jnp.concatenate([a, jnp.repeat(a[:1], n_to - n, axis=0)]), tree)


def shard_batch(tree, devices=None):
    """Place a batched pytree (leading axis = run) block-wise on ``devices``.

    Returns ``(sharded_tree, n)`` with ``n`` the original batch size (the tree is padded to a
    multiple of the device count). With one device, or under a JAX transformation, the tree is
    returned unchanged.
    """
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    m = mesh(devices)
    k = m.devices.size
    if k == 1 or _is_traced(tree):
        return tree, n
    padded = _pad(tree, -(-n // k) * k)
    sharding = NamedSharding(m, PartitionSpec(AXIS))
    return jax.device_put(padded, sharding), n


def unpad(tree, n: int):
    """The first ``n`` runs of a batched pytree (undoes :func:`shard_batch`'s padding)."""
    if jax.tree_util.tree_leaves(tree)[0].shape[0] == n:
        return tree
    return jax.tree_util.tree_map(lambda a: a[:n], tree)


def device_count(devices=None) -> int:
    return len(jax.devices()) if devices is None else len(list(devices))
