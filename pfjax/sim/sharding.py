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
* **several hosts** (or several processes on one): call :func:`initialize_distributed` (JAX's
  ``jax.distributed.initialize``: coordinator address, number of processes, process id; automatic
  under SLURM and Open MPI) in every process before any JAX work; the mesh then spans
  ``jax.devices()`` of all processes. Each process must pass the same global batch (same config
  and seed) in the same order, and :func:`gather` copies the whole result to every process.
  ``pfjax study --coordinator/--num-processes/--process-id`` runs a study this way (README).

A batch whose size is not a multiple of the device count is padded by repeating its first run
and the padding is cut off again, so callers see exactly their runs. Inside a JAX transformation
(``jit``, ``grad``) the batch is left as it is: sharding is decided at the outermost call; only a
block size given as a number still splits it into blocks (:func:`plan_batch`; forward-mode
gradients run faster in blocks sized for a value and its tangents, :func:`default_block`).

**Blocks (CPU).** XLA's CPU backend compiles one integrator step into a few dozen loop kernels,
each a pass over the batch. On one device the runs are therefore simulated in blocks of
:func:`cpu_block_bytes` per array (5,000 bytes: 1,250 runs in float32, 625 in float64; 2,500 bytes on
Intel CPUs), one block after
another (``lax.map``). A block's loop is then small enough for XLA to compile it into one function
(the small-loop threshold that ``import pfjax`` raises, :data:`pfjax.SMALL_LOOP_BYTES`) and its
arrays stay in the core's L1 and L2 caches: 1.3x the rollout-steps/s of 10,000-run blocks in
float32 and 1.2x in float64 at 10^5 runs (README, Performance).

**Blocks (GPU).** On a GPU each step's kernels read and write the loop's state in device memory
(about 190 bytes per run in float32 and 370 in float64 for the benchmark's slip model). Large
batches are simulated in blocks of :func:`gpu_block_bytes` per array (:data:`GPU_BLOCK_BYTES`:
1 MB, 250,000 runs in float32, 125,000 in float64), smaller ones at once. Measured on an H200 at
10^6 runs: 1.2x the rollout-steps/s of the whole batch in float32 and 3.4x in float64; half that
block size was slower than the whole batch in float32 (each block pays every step's launch
latency). A reading that fits these numbers, not measured with counters: a 1 MB block's state
(47 MB in float32) stays in the GPU's L2 cache between steps, the whole batch's does not.

Results do not depend on the blocking beyond rounding: every run is computed by the same per-run
code, but each block shape is compiled into its own vector code (measured on CPU: an ulp in a few
runs' metrics with XLA's default vector width; with 512-bit vectors up to a few tens of ulp in
float32 metrics, float64 bit-identical; tests/test_sharding.py; on the H200 every GPU blocking gave
the same per-run IAE to the bit).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from pfjax import errors
from pfjax.numerics import calibration
from pfjax.numerics.cpu import CPUINFO, is_intel

AXIS = "runs"
#: Bytes per batched array in one CPU block (the rule for CPUs other than Intel's:
#: :func:`block_bytes_rule`). Measured (2-core AMD EPYC with AVX-512, 512-bit vectors,
#: 2 devices, the benchmark's slip model at 10^5 runs, M rollout-steps/s): float32 blocks of 312-3,750
#: runs 195-207, 4,000-10,000 runs 150-165, 20,000 runs 154; float64 625 runs 91, 1,250 runs 89,
#: 2,500-5,000 runs 73-76. Blocks past the small-loop threshold fall back to a kernel launch per
#: kernel and step. On an AVX2 CPU with 40 kB blocks and XLA's default loop threshold, 5,000-10,000
#: float32 runs were fastest and 2,500 slower (docs/performance.md).
CPU_BLOCK_BYTES = 5_000
#: Bytes per batched array in one CPU block on Intel CPUs (:func:`block_bytes_rule`). Measured on a
#: 2-core Intel Xeon (family 6, model 207, AVX-512), 512-bit vectors, by ``pfjax calibrate`` (20,000
#: runs of 5 s, M rollout-steps/s, float32 / float64): 2,500 bytes 99.9 / 44.6, 5,000 bytes 96.7 /
#: 42.4, 10,000 bytes 94.8 / 42.0, 20,000 bytes 72.8 / 35.1; ``pfjax bench`` at 10^5 runs, one run
#: each in turn: 114.1 / 47.5 against 107.3 / 44.9 with 5,000 bytes (docs/performance.md).
INTEL_BLOCK_BYTES = 2_500
#: Bytes per batched array in one GPU block (``None``: each device's whole batch in one block),
#: :func:`gpu_block_bytes`; :data:`GPU_BLOCK_ENV` overrides it. Measured on one NVIDIA H200 (jax
#: 0.11.2, the benchmark's slip model, 10^6 runs of 20 s, M rollout-steps/s float32 / float64, best
#: of 3 calls): the whole batch 11,021 / 1,474; 4 MB per array 11,009 / 1,492; 2 MB 9,434 / 4,944;
#: 1 MB 13,190 / 5,051; 0.5 MB 6,687 / 3,262. Every blocking gave the same per-run IAE to the bit.
#: Measured on that GPU only: one with a smaller L2 cache may want smaller blocks (docs/performance.md).
GPU_BLOCK_BYTES: int | None = 1_000_000
#: Environment variable: bytes per batched array in one GPU block (``0``: each device's whole batch
#: at once), read when a batch is planned.
GPU_BLOCK_ENV = "PFJAX_GPU_BLOCK_BYTES"
#: Runs per block are rounded up to a multiple of this (blocks of more runs than this). XLA's CPU
#: code for an odd number of runs per device is about 3x slower (measured, float32: 50,001 runs per
#: device 10.8 M rollout-steps/s, 50,002 runs 34.5; 1,251 runs 14.6, 1,252 runs 44.3).
ALIGN = 8


class Layout(NamedTuple):
    """How a padded batch is evaluated (static: it fixes the compiled program).

    ``mesh``: the devices the batch is split over (``None``: one device, or under a transformation);
    ``blocks``: blocks per device, evaluated one after another.

    ``runs``: the runs of a traced batch on each device, padding included, in all its blocks
    (reverse mode through the loop over blocks stores every block's steps; counted as if the batch
    were split over every device, as :func:`plan_batch` places one), which decide the loop's
    checkpoints (:func:`pfjax.sim.loop.checkpoint_segment`; 0: a placed batch, which no
    transformation differentiates).

    ``shares``, ``size``: a traced batch's split (``shares = 0``: a placed batch, padded and split
    before the call). The outer call decided where the runs are, so the program leaves them there:
    the runs are taken as ``shares`` contiguous shares (the devices' when the run count is a multiple
    of their number, else one), each padded at its end to ``blocks * size`` runs (copies of the
    share's first run, cut off again), and evaluated in interleaved blocks (block ``j``: runs
    ``j, j + blocks, ...``), so that every block holds ``size`` runs of every share.
    """

    mesh: Mesh | None
    blocks: int
    shares: int = 0
    size: int = 0
    runs: int = 0


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
    if all(isinstance(a, np.ndarray) for a in jax.tree_util.tree_leaves(tree)):
        return jax.tree_util.tree_map(lambda a: np.concatenate([a, np.repeat(a[:1], n_to - n, axis=0)]), tree)
    return _pad_jit(tree, n_to)


# One program for the whole tree (compiled once per tree shape): padding or cutting leaf by leaf
# dispatches a few small programs per leaf, each compiled on first use (measured 0.57 s against
# 0.11 s for a 2,500-run scenario and its result).
@partial(jax.jit, static_argnums=1)
def _pad_jit(tree, n_to: int):
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    return jax.tree_util.tree_map(lambda a: jnp.concatenate([a, jnp.repeat(a[:1], n_to - n, axis=0)]), tree)


@partial(jax.jit, static_argnums=1)
def _head_jit(tree, n: int):
    return jax.tree_util.tree_map(lambda a: a[:n], tree)


def shard_batch(tree, devices=None):
    """Place a batched pytree (leading axis = run) block-wise on ``devices``.

    Returns ``(sharded_tree, n)`` with ``n`` the original batch size (the tree is padded to a
    multiple of the device count). With one device, or under a JAX transformation, the tree is
    returned unchanged.
    """
    tree, n, _ = plan_batch(tree, devices, block=None, align=1)
    return tree, n


def default_block(tree, devices=None, tangents: int = 0) -> int | None:
    """Runs per block: :func:`cpu_block_bytes` per array of the tree's floating dtype on CPU devices,
    :func:`gpu_block_bytes` on GPUs, ``None`` (no blocks) on any other platform.

    ``tangents``: forward-mode tangents each value carries (``D`` for the gradient in ``D``
    parameters, :func:`pfjax.numerics.autodiff.value_and_grad`). A value and its tangents share one
    array's budget, so a block holds ``1 + tangents`` times fewer runs and its loop stays as small
    as the forward pass's. Measured (the benchmark's gradient in K, and for D = 3, 4 also in the two
    slip angles' scale, float32, 2,000 runs, 2 devices, a 2-core AMD EPYC of CPU family 26; value and
    gradient over the forward pass, best of 5 interleaved rounds, two sittings): with 512-bit
    vectors, D = 1 / 2 / 3 / 4 took 1.44-1.46x / 1.85-1.91x / 2.92-3.04x / 3.59-3.66x with each
    device's 1,000 runs in one block, 1.33-1.34x / 1.59-1.64x / 2.49-2.52x / 2.90-3.00x in blocks
    of this rule's size; with XLA's default width, D = 1 / 2 1.32-1.33x / 1.61-1.62x whole against
    1.31x / 1.58-1.59x in blocks. Reverse mode gains less in blocks (its stored steps are the same
    in total, so the loop checkpoints them in the same segments, :func:`pfjax.sim.loop.checkpoint_segment`):
    at 2,000 runs 3.53x / 3.60x / 3.67x in blocks of 336 / 500 / 250 runs against 3.65-3.77x whole, for
    1-1.5 s more compilation, so ``tangents=0`` gives it the forward pass's blocks (one per device
    at that batch).
    """
    if int(tangents) < 0:
        raise ValueError(f"tangents: must be at least 0, got {tangents}")
    platform = block_platform(devices)
    if platform is None:
        return None
    floats = [
        a.dtype
        for a in jax.tree_util.tree_leaves(tree)
        if hasattr(a, "dtype") and jnp.issubdtype(a.dtype, jnp.floating)
    ]
    itemsize = max((np.dtype(d).itemsize for d in floats), default=4)
    per_array = cpu_block_bytes(itemsize) if platform == "cpu" else gpu_block_bytes()
    if not per_array:
        return None
    return max(1, per_array // (itemsize * (1 + int(tangents))))


def block_platform(devices=None) -> str | None:
    """The platform whose block rule applies to ``devices`` (default: every device JAX sees):
    ``"cpu"`` (:func:`cpu_block_bytes`), ``"gpu"`` (:func:`gpu_block_bytes`), or ``None`` on any
    other platform (no blocks). The one place that tells CPU and GPU blocks apart, for
    :func:`default_block` and for the benchmark's machine record."""
    devices = jax.devices() if devices is None else list(devices)
    platform = devices[0].platform
    return platform if platform in ("cpu", "gpu") else None


def gpu_block_bytes(environ=None) -> int | None:
    """Bytes per batched array in one GPU block: :data:`GPU_BLOCK_ENV` where set (``0``: ``None``),
    else :data:`GPU_BLOCK_BYTES`; ``None``: each device's whole batch at once. A value that is not
    a whole number is ignored with a warning naming the variable."""
    from pfjax.host import whole_number

    environ = os.environ if environ is None else environ
    n = whole_number(environ, GPU_BLOCK_ENV, "bytes", -1)
    if n < 0:
        return GPU_BLOCK_BYTES
    return n or None


@functools.cache  # read once per file
def block_bytes_rule(cpuinfo: str = CPUINFO) -> int:
    """Bytes per batched array in one CPU block without a calibration: :data:`INTEL_BLOCK_BYTES` on
    Intel CPUs, :data:`CPU_BLOCK_BYTES` on others (the evidence is in their comments)."""
    return INTEL_BLOCK_BYTES if is_intel(cpuinfo) else CPU_BLOCK_BYTES


def cpu_block_bytes(itemsize: int) -> int:
    """Bytes per batched array in one CPU block: this CPU's calibration where ``pfjax calibrate``
    measured one (:mod:`pfjax.numerics.calibration`), else the rule (:func:`block_bytes_rule`)."""
    return calibration.block_bytes(itemsize) or block_bytes_rule()


def plan_batch(tree, devices=None, block: int | str | None = "auto", align: int = ALIGN):
    """Pad and place a batch for :func:`map_runs`: ``(placed_tree, n, layout)``.

    ``n`` is the original batch size. The batch is split over the devices (as :func:`shard_batch`)
    and each device's share into ``layout.blocks`` equal blocks of at most ``block`` runs
    (``"auto"``: :func:`default_block`; ``None``: one block per device), rounded up to a multiple
    of ``align`` runs when a block has more. The padding (repeats of the first run) is less than
    ``align + 1`` runs per block and device.

    Under a JAX transformation the tree is returned as it is (the outer call decided its placement):
    with ``block`` ``"auto"`` or ``None`` in one block; with a number of runs in blocks of at most
    that many runs per device (``devices`` taken as the devices its runs are split over), padded and
    split inside the program so that the runs stay on their devices (:class:`Layout`; when the run
    count is not a multiple of the devices, the padding moves runs between them once, before the
    loop). Forward-mode gradients pay for it (:func:`default_block` with ``tangents``).
    ``block``: a number of runs >= 1, ``"auto"`` or ``None`` (:class:`~pfjax.errors.InputError`
    naming ``block`` otherwise).
    """
    if block is not None and not (isinstance(block, str) and block == "auto"):
        block = errors.integer("block", block, low=1)
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    m = mesh(devices)
    k = m.devices.size
    if _is_traced(tree):
        return tree, n, traced_layout(n, None if block is None or isinstance(block, str) else int(block), k, align)
    if block == "auto":
        block = default_block(tree, m.devices.flat)
    per_device = -(-n // k)
    blocks = 1 if block is None else _block_count(per_device, int(block))
    size = _block_size(per_device, blocks, align)
    padded = _pad(tree, k * blocks * size)
    if k == 1:
        return padded, n, Layout(None, blocks)
    return jax.device_put(padded, NamedSharding(m, PartitionSpec(AXIS))), n, Layout(m, blocks)


def traced_layout(n: int, block: int | None, devices: int, align: int = ALIGN) -> Layout:
    """The :class:`Layout` of a traced batch of ``n`` runs over ``devices`` devices in blocks of at
    most ``block`` runs per device (``None``: one block; :func:`plan_batch`): its ``blocks``, its
    ``runs`` per device and loop and, in blocks, its ``shares`` and ``size`` (runs of each share per
    block)."""
    per_device = -(-n // devices)
    blocks = 1 if block is None else _block_count(per_device, block)
    if blocks == 1:
        return Layout(None, 1, runs=per_device)
    shares = devices if n % devices == 0 else 1
    size = _block_size(n // shares, blocks, align)
    return Layout(None, blocks, shares, size, runs=-(-blocks * size * shares // devices))


def _block_count(per_device: int, block: int) -> int:
    """Blocks of at most ``block`` runs for a device's ``per_device`` runs (at least one)."""
    return max(1, -(-per_device // block))


def _block_size(runs: int, blocks: int, align: int) -> int:
    """Runs per block of ``runs`` in ``blocks`` blocks, rounded up to a multiple of ``align`` when
    a block has more than ``align`` runs."""
    size = -(-runs // blocks)
    return -(-size // align) * align if size > align else size


def map_runs(fn: Callable[[Any], Any], tree, layout: Layout):
    """``vmap(fn)`` over the leading axis of a batch placed by :func:`plan_batch` (call under ``jit``).

    Each device evaluates its share (``shard_map`` over ``layout.mesh``) in ``layout.blocks``
    blocks, one after another (``lax.map`` of the vmapped ``fn``); a traced batch's shares
    (``layout.shares``) are padded, split into interleaved blocks and cut again here.
    """
    if layout.shares:
        return _map_shares(fn, tree, layout)

    def local(t):
        if layout.blocks == 1:
            return jax.vmap(fn)(t)
        return join_blocks(jax.lax.map(jax.vmap(fn), split_blocks(t, layout.blocks)))

    if layout.mesh is None:
        return local(tree)
    spec = PartitionSpec(AXIS)
    return jax.shard_map(local, mesh=layout.mesh, in_specs=spec, out_specs=spec, check_vma=False)(tree)


def _map_shares(fn: Callable[[Any], Any], tree, layout: Layout):
    """:func:`map_runs` of a traced batch (:class:`Layout`'s ``shares`` and ``size``): every array
    keeps its runs' order along the run axis, so the outer call's split over devices holds."""
    shares, per_share = layout.shares, layout.blocks * layout.size
    n = jax.tree_util.tree_leaves(tree)[0].shape[0]
    m = n // shares

    def pad(a):
        a = a.reshape((shares, m) + a.shape[1:])
        a = jnp.concatenate([a, jnp.repeat(a[:, :1], per_share - m, axis=1)], axis=1)
        return a.reshape((shares * per_share,) + a.shape[2:])

    def cut(a):
        return a.reshape((shares, per_share) + a.shape[1:])[:, :m].reshape((n,) + a.shape[1:])

    padded = jax.tree_util.tree_map(pad, tree)
    out = jax.lax.map(jax.vmap(fn), split_blocks(padded, layout.blocks, interleaved=True))
    return jax.tree_util.tree_map(cut, join_blocks(out, interleaved=True))


def split_blocks(tree, blocks: int, interleaved: bool = False):
    """The leading (run) axis of every leaf as ``(blocks, runs per block)``: contiguous shares, or
    interleaved (block ``j``: runs ``j, j + blocks, j + 2 blocks, ...``). The run count must be a
    multiple of ``blocks``; :func:`join_blocks` undoes it."""

    def split(a):
        n = a.shape[0]
        if interleaved:
            return jnp.swapaxes(a.reshape((n // blocks, blocks) + a.shape[1:]), 0, 1)
        return a.reshape((blocks, n // blocks) + a.shape[1:])

    return jax.tree_util.tree_map(split, tree)


def join_blocks(tree, interleaved: bool = False):
    """The runs of :func:`split_blocks`'s blocks back in their order along one leading axis."""

    def join(a):
        if interleaved:
            a = jnp.swapaxes(a, 0, 1)
        return a.reshape((a.shape[0] * a.shape[1],) + a.shape[2:])

    return jax.tree_util.tree_map(join, tree)


def unpad(tree, n: int):
    """The first ``n`` runs of a batched pytree (undoes :func:`shard_batch`'s padding).

    A batch spread over several CPU devices of this process is cut on the host and put back on JAX's
    default device:
    cutting it in a program re-shards it, which takes a collective (every device meets at a
    rendezvous), and a device busy with another thread's work (a study's side jobs) can keep the
    others waiting there until XLA's CPU runtime aborts the process (40 s; seen with the default
    study). Copying a shard is no such meeting."""
    leaves = jax.tree_util.tree_leaves(tree)
    if leaves[0].shape[0] == n:
        return tree
    if all(isinstance(a, np.ndarray) for a in leaves):
        return jax.tree_util.tree_map(lambda a: a[:n], tree)
    if not _is_traced(tree) and any(_spans_devices(a) for a in leaves) and all(_on_this_host_cpu(a) for a in leaves):
        return jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a)[:n]), tree)
    return _head_jit(tree, n)


def _spans_devices(a) -> bool:
    sharding = getattr(a, "sharding", None)
    return sharding is not None and len(sharding.device_set) > 1


def _on_this_host_cpu(a) -> bool:
    """Whether ``a`` lies on this process's CPU devices only (the rendezvous abort is XLA's CPU
    runtime's; an array spanning other processes' devices cannot be read here, and a GPU's result
    stays on the GPUs)."""
    sharding = getattr(a, "sharding", None)
    return (
        sharding is not None
        and a.is_fully_addressable
        and all(d.platform == "cpu" for d in sharding.device_set)
        and not jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key)
    )


#: Seconds a process waits for the coordinator (and process 0 for the others) by default.
COORDINATOR_TIMEOUT_S = 60


def reach_coordinator(coordinator: str, process_id: int, timeout_s: float) -> None:
    """Check, before JAX tries (JAX aborts the whole process when it cannot connect), that this
    process can take part: process 0 can listen on the coordinator's port, the others can connect
    to it within ``timeout_s`` seconds (retrying while process 0 starts up). Raises
    :class:`~pfjax.errors.InputError` naming ``coordinator``."""
    import socket
    import time

    from pfjax.errors import InputError

    host, _, port = coordinator.rpartition(":")
    host = host.strip("[]")
    if process_id == 0:
        try:
            with socket.create_server(("", int(port)), reuse_port=hasattr(socket, "SO_REUSEPORT")):
                pass
        except OSError as e:
            raise InputError(f"coordinator: process 0 cannot listen on port {port} ({e.strerror})") from None
        return
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with socket.create_connection((host, int(port)), timeout=min(5.0, max(timeout_s, 0.1))):
                return
        except OSError as e:
            if time.monotonic() >= deadline:
                raise InputError(
                    f"coordinator: could not reach {coordinator} within {timeout_s:g} s "
                    f"({e.strerror or type(e).__name__}); is process 0 running?"
                ) from None
            time.sleep(0.2)


def check_distributed(
    coordinator: str | None, num_processes: int | None, process_id: int | None, timeout_s: float
) -> None:
    """The arguments of :func:`initialize_distributed`, checked before anything waits:
    :class:`~pfjax.errors.InputError` naming ``coordinator`` (``HOST:PORT``, a port in 1..65535),
    ``num_processes`` (>= 1), ``process_id`` (``0 .. num_processes - 1``) or ``timeout_s`` (finite,
    > 0 s)."""
    from pfjax import errors
    from pfjax.errors import InputError

    errors.number("timeout_s", timeout_s, positive=True, unit=" s")
    if coordinator is not None:
        host, _, port = str(coordinator).rpartition(":")
        if not host or not port.isdigit():
            raise InputError(f"coordinator: expected HOST:PORT, got {coordinator!r}", "coordinator")
        if not 1 <= int(port) <= 65535:
            raise InputError(f"coordinator: expected a port in 1..65535, got {port} in {coordinator!r}", "coordinator")
    if num_processes is not None:
        errors.integer("num_processes", num_processes, low=1)
    if process_id is not None:
        high = None if num_processes is None else num_processes - 1
        if errors.is_number(process_id) and high is not None and not 0 <= process_id <= high:
            raise InputError(f"process_id: expected 0..{high}, got {process_id}", "process_id")
        errors.integer("process_id", process_id, low=0)


#: Whether this process has joined a multi-process run (:func:`initialize_distributed`).
_joined = False


def initialize_distributed(
    coordinator: str | None = None,
    num_processes: int | None = None,
    process_id: int | None = None,
    timeout_s: float = COORDINATOR_TIMEOUT_S,
) -> None:
    """Join a multi-process JAX run (several hosts, or several processes on one host).

    ``jax.distributed.initialize`` with the given coordinator (``host:port`` of process 0), number
    of processes and this process's id; all ``None`` lets JAX detect them (SLURM, Open MPI). Call it
    in every process before any JAX work. CPU devices exchange data through Gloo (JAX's default CPU
    backend has no cross-process collectives); GPUs use NCCL as usual. The arguments are checked
    first (:func:`check_distributed`). With an explicit coordinator, :func:`reach_coordinator`
    checks it, and JAX waits at most ``timeout_s`` seconds for the processes to register; process
    0 whose peers do not all register in that time is ended by JAX (exit code 134, JAX's own
    message), which no Python code can catch.

    JAX's preemption service is turned off: it would take SIGTERM (``kill``, ``timeout``, a batch
    system's cancel) for a notice and run on; SIGTERM ends the process as usual, and an
    interrupted study resumes from its finished chunks.
    """
    global _joined
    check_distributed(coordinator, num_processes, process_id, timeout_s)
    if coordinator is not None and process_id is not None:
        reach_coordinator(coordinator, process_id, timeout_s)
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    jax.config.update("jax_enable_preemption_service", False)
    jax.distributed.initialize(
        coordinator_address=coordinator,
        num_processes=num_processes,
        process_id=process_id,
        initialization_timeout=max(1, int(math.ceil(timeout_s))),
    )
    _joined = True


def joined() -> bool:
    """Whether this process has joined a multi-process run (:func:`initialize_distributed`)."""
    return _joined


def every_process(text: str) -> list[str]:
    """``text`` (ASCII, at most 256 characters) of every process, in process order: a collective
    that every process must call at the same point. In a single process, ``[text]``."""
    if jax.process_count() == 1:
        return [text]
    from jax.experimental import multihost_utils

    raw = np.zeros(256, np.uint8)
    b = text.encode("ascii")[:256]
    raw[: len(b)] = np.frombuffer(b, np.uint8)
    rows = np.asarray(multihost_utils.process_allgather(raw), dtype=np.uint8).reshape(-1, 256)
    return [bytes(r).rstrip(b"\0").decode("ascii") for r in rows]


def gather(tree):
    """A NumPy copy of a (sharded) result pytree in this process: ``jax.device_get`` when every
    shard is here, else an all-gather over processes (every process must call it, in the same
    order, as for the program that made the result)."""
    leaves = jax.tree_util.tree_leaves(tree)
    if all(not isinstance(a, jax.Array) or a.is_fully_addressable for a in leaves):
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    return jax.tree_util.tree_map(np.asarray, multihost_utils.process_allgather(tree, tiled=True))


def broadcast_json(obj=None):
    """Process 0's ``obj`` (any JSON value) in every process; the others pass ``None``. Every
    process must call it at the same point (a collective: its length, then its UTF-8 bytes).
    In a single process it returns ``obj`` unchanged."""
    import json

    if jax.process_count() == 1:
        return obj
    from jax.experimental import multihost_utils

    lead = jax.process_index() == 0
    data = np.frombuffer(json.dumps(obj).encode(), dtype=np.uint8) if lead else None
    n = int(multihost_utils.broadcast_one_to_all(np.int32(len(data) if lead else 0)))
    data = multihost_utils.broadcast_one_to_all(data if lead else np.zeros(n, np.uint8))
    return json.loads(np.asarray(data, dtype=np.uint8).tobytes().decode())


def device_count(devices=None) -> int:
    return len(jax.devices()) if devices is None else len(list(devices))
