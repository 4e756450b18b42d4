"""The one simulation loop: a ``lax.scan`` over the samples of one run of any fixed-step system, or
a ``lax.while_loop`` over the same samples for a run that ends at an event (``until_done``).

What the loop owns (the same for every system):

* the ``lax.scan`` over samples ``k = 0..n-1`` (run until done: the ``lax.while_loop``) and its
  named carry, :class:`LoopCarry`;
* the run's status: each sample's own health code, the first failure winning
  (:func:`pfjax.sim.status.first_failure`), and the failure time (the failing sample's time);
* freezing: once the run has failed its state is kept as it was before the failing step;
* the running metrics hook (called on every sample, told whether the run is still live);
* the recording switch (``record=False``: no trajectory, memory independent of the horizon);
* optionally, the run's small inputs as scalars inside the loop
  (:func:`pfjax.numerics.layout.as_scalars`) and a reverse-mode checkpoint policy for the loop body,
  with the samples in checkpointed segments when the carry of every sample would not fit in memory
  the allocator reuses (:func:`checkpoint_segment`).

What a system (a new vehicle model) supplies: a :class:`System` of pure single-run functions of the
run's ``inputs`` (a pytree, e.g. a scenario; static settings are closed over, e.g. with
``functools.partial``)::

    init(inputs)                          -> Start(state, metrics, zero, aux)
    step(inputs, carry, k)                -> Sample(state, health, time, out, aux, keep)
    update(inputs, metrics, sample, live, was_live) -> metrics
    record(inputs, sample, state)         -> one sample of the trajectory (a pytree of scalars)
    finish(inputs, run: Run)              -> the system's result

``step`` reads the current :class:`LoopCarry` (``carry.state``, ``carry.aux``), proposes the next
state and returns its sample's own health code (0: healthy) and time ``t`` (s). The loop then sets

    status_k    = status_{k-1} if status_{k-1} != OK else health_k          (first failure wins)
    fail_time   = t_k at the sample where status first leaves OK             (else ``no_failure``)
    live_k      = status_k == OK
    state_{k+1} = proposed if live_k and not keep_k else state_k             (frozen after a failure)
    aux_{k+1}   = sample.aux                                                 (never frozen)

``update`` accumulates the metrics (``live``: after this sample's check; ``was_live``: before it),
``record`` gives the sample's trajectory entry from the sample and the state carried on, and
``finish`` builds the result from :class:`Run` (final state, metrics, int32 status, failure time,
stacked records or ``None``). The status is carried as a float code (see
:func:`~pfjax.sim.status.first_failure`); ``Run.status`` is its int32 value.

Status codes, one table for every system on this loop. A status is an integer code to the outside;
``live`` is the code of a run still going (:attr:`System.live`): ``0`` for the fixed-horizon systems
(:class:`pfjax.sim.status.Status`, the slip vehicle's, and ``pfjax.tracking.simulate.TrackStatus``,
the focus-point tracker's, share the codes ``0-3``), ``-1`` for the parking robot
(``pfjax.parking.simulate.Status``, whose runs stop at an event)::

    code  Status (slip vehicle, pfjax.sim.simulate)   TrackStatus (tracker)          parking Status (pfjax.parking)
    -1    -                                           -                              running (live; never an output)
    0     ok: ran the whole horizon (live)            ok: ran the whole horizon      converged: |x| + sqrt(y² + tan²θ) < tol
    1     nonfinite: pose or measurement NaN/inf      nonfinite: follower NaN/inf    timeout: t ≥ t_max
    2     diverged: |d| > SimConfig.d_fail (m)        diverged: |z~| > z_fail (m)    too_many_switches: > max_switches
    3     singular: 1 - kappa d <= SINGULAR_TOL       singular: |det M / (l p)|      heading_limit: |θ| ≥ π/2
                                                      < sing_tol (no inverse)
    4     path_end: closest point at the domain end   -                              nonfinite: state NaN/inf
    5     -                                           -                              stuck: reversing in place
    6     -                                           -                              start_overlap: body on an obstacle

``SINGULAR_TOL`` is :data:`pfjax.sim.status.SINGULAR_TOL`, the tracker's ``sing_tol`` is
``TrackConfig.sing_tol`` and the shared codes ``0-3`` of ``TrackStatus`` are :class:`~pfjax.sim.status.Status`'s.

The dynamic vehicle (:mod:`pfjax.sim.dynamic`, CommonRoad's single-track model) uses the slip
vehicle's :class:`~pfjax.sim.status.Status` with the same checks on its rear axle's measurement (and
every entry of its state finite), in the same order (check, then step). The slip vehicle checks the
sample's current state (check, then step; its last sample ``k = N`` only measures, ``keep``); the
tracker checks the state after its step (step, then check, at ``t_{k+1}``). Its failure time is NaN
for a run that never fails, the tracker's ``inf``.

**Event-terminated runs** (``run(..., until_done=True)``): a run that ends at an event (the parking
robot: converged, stuck, timeout, ...) rather than at a fixed horizon is a ``lax.while_loop`` over
the same sample (step, status, metrics, freezing) while the status is ``live`` and ``k < n``
(``LoopCarry.k`` counts the samples); vmapped, it runs until every run of the batch has stopped, each
run's carry kept from its own stop on. Recorded, it stays a ``lax.scan`` over all ``n`` samples (the
records have a static shape), so a system run until done leaves what its result reads unchanged
once stopped (the loop freezes ``state``, not ``aux``). The
parking robot's sample is one scanner period (a direction-switch decision, logged, then ``n_sub``
RK4 steps); a period can end in a stop and keeps its last RK4 steps, so its whole carry is ``aux``
(not frozen by the loop) and it freezes its state step by step itself. Its speed on this loop
against a ``lax.while_loop`` of its own: :mod:`pfjax.parking.simulate`'s docstring (no cost beyond
noise).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import Array

from pfjax.numerics.layout import as_scalars
from pfjax.sim.status import Status, first_failure


class Start(NamedTuple):
    """A run's start, from :attr:`System.init`."""

    state: Any  # the state at sample 0 (frozen after a failure)
    metrics: Any  # the running metrics before sample 0
    zero: Array  # a zero of the run's float type: the status starts at it, the failure time at zero + no_failure
    aux: Any = None  # carried on unfrozen (e.g. a sampled controller's held command)
    status: Array | None = None  # float code of the status at the start (None: zero, i.e. OK)


class Sample(NamedTuple):
    """What :attr:`System.step` returns for sample ``k``."""

    state: Any  # the proposed next state (kept only while the run is live)
    health: Array  # this sample's own status code (int; 0: healthy)
    time: Array  # s, the sample's time (the failure time if it is the run's first failure)
    out: Any  # what update and record read (the system's own pytree)
    aux: Any = None  # the next unfrozen carry
    keep: Array | None = None  # bool: keep the state although the run is live (a measure-only sample)


class LoopCarry(NamedTuple):
    """The ``lax.scan`` carry between samples."""

    state: Any  # the system's state (frozen after a failure)
    aux: Any  # the system's unfrozen carry
    metrics: Any  # running metrics
    status: Array  # float code of the status (exact small integers)
    fail_time: Array  # s, time of the first failure (no_failure while none)
    k: Any = None  # int, samples done (the event-terminated mode only; None in a scan)


class Run(NamedTuple):
    """The loop's outcome, handed to :attr:`System.finish`."""

    state: Any  # final (or frozen) state
    aux: Any  # final unfrozen carry
    metrics: Any  # running metrics after the last sample
    status: Array  # int32 status code
    failed: Array  # bool, status != OK
    fail_time: Array  # s
    records: Any  # stacked records, shape (n, ...) per leaf; None without recording


class System(NamedTuple):
    """A fixed-step system, as pure single-run functions (see the module docstring)."""

    init: Callable[[Any], Start]
    step: Callable[[Any, LoopCarry, Array], Sample]
    update: Callable[[Any, Any, Sample, Array, Array], Any]
    record: Callable[[Any, Sample, Any], Any]
    finish: Callable[[Any, Run], Any]
    no_failure: float  # fail_time of a run that never fails (NaN or inf)
    live: int = Status.OK  # the status code of a run still going (the status table)


#: Carry bytes over all samples of the runs on one device (every block's) beyond which reverse mode
#: checkpoints the loop in segments (:func:`checkpoint_segment`). Placed between the measurements on
#: the benchmark problem (4,001 samples, a 100-byte float32 carry of which reverse mode stores 28
#: bytes, 2 devices; :mod:`pfjax.bench`): 250 runs per device (100 MB of carry) took 3.15x the
#: forward pass per sample and 3.46x in segments; 350 runs (140 MB) 4.58x against 3.53x.
SEGMENT_BYTES = 128 * 2**20


def checkpoint_segment(n_samples: int, carry_bytes: int, runs: int) -> int:
    """Samples per checkpointed segment of a reverse-differentiated loop: 0 (every sample its own
    checkpoint) for a run alone (``runs`` 0 or 1) and unless ``runs * n_samples * carry_bytes``
    exceeds :data:`SEGMENT_BYTES`; then the largest divisor of ``n_samples`` from
    ``ceil(sqrt(n_samples))`` down to half of it, or where none is, ``ceil(sqrt(n_samples))`` itself
    (the last ``n_samples mod S`` samples then loop on their own: a second copy of the step in the
    program, about 2 s more to compile on the benchmark).

    Reverse mode through a loop of per-sample checkpoints stores the carry of every sample and runs
    the loop, then each sample again and its transpose. Stored for thousands of runs over thousands
    of samples, that buffer is allocated afresh at each call (glibc's ``malloc`` maps anything above
    32 MiB, page by page) and streamed twice through memory. In segments of ``S`` samples reverse mode
    stores the carry at every segment's start and, segment by segment, recomputes the segment's
    samples to store their carries: ``n / S + S`` carries instead of ``n`` (least at ``S = sqrt(n)``)
    for one more forward pass. Measured on the benchmark problem (2,000 float32 runs, 4,001
    samples, 2 devices, 512-bit vectors; 16, 32 and 64 samples per segment within 3 % of each
    other): 3.7-3.8x the forward pass against 4.8-4.9x; float64 3.5x against 4.2x. Below the
    threshold the extra forward pass costs more than the memory saves. The reverse-mode program's
    tracing, lowering and compilation from a cold cache took 3.8 s for 4,096 samples (64 segments
    of 64) and 5.7-5.9 s for 4,097 (63 of 65 and a loop of 2), against 2.6 s per step.

    ``runs``: the runs on one device, in every block (reverse mode through a loop over blocks stores
    every block's steps; a ``vmap`` hides them from the loop; 0 or 1 for a run alone). The loop
    cannot tell whether it is differentiated, so a traced batch's forward pass and forward-mode
    derivatives get the segments too: the same run time, a larger program (on the benchmark, 1.8 s
    against 0.9 s for the forward pass and 3.3 s against 2.1 s for the forward-mode gradient in
    blocks, from a cold cache, with a loop for the last samples). Values are the same bit for bit
    and derivatives to rounding (the same arithmetic, compiled into other machine code: 8e-8
    relative in float32, 3e-16 in float64).
    """
    if runs <= 1 or runs * n_samples * carry_bytes <= SEGMENT_BYTES:
        return 0
    root = math.isqrt(n_samples - 1) + 1  # ceil(sqrt(n))
    whole = [s for s in range(root, (root + 1) // 2 - 1, -1) if n_samples % s == 0]
    return whole[0] if whole else root


def _tree_bytes(tree) -> int:
    return sum(int(np.size(a)) * jnp.result_type(a).itemsize for a in jax.tree_util.tree_leaves(tree))


def _start(system: System, inputs) -> LoopCarry:
    """The loop's carry before sample 0."""
    start = system.init(inputs)
    status = start.zero if start.status is None else start.status
    return LoopCarry(start.state, start.aux, start.metrics, status, start.zero + system.no_failure)


def carry_bytes(system: System, inputs) -> int:
    """Bytes of one run's loop carry (``inputs``: one run's, arrays or ``jax.ShapeDtypeStruct``;
    nothing is computed): what :func:`checkpoint_segment` weighs."""
    return _tree_bytes(jax.eval_shape(lambda x: _start(system, x), inputs))


def _scan(body, carry, n_samples: int, segment: int):
    """``lax.scan(body, carry, arange(n_samples))``, in checkpointed segments of ``segment``
    samples (the last ``n_samples mod segment`` samples on their own) when ``segment > 1``."""
    if segment <= 1 or segment >= n_samples:
        return jax.lax.scan(body, carry, jnp.arange(n_samples))
    m, rest = divmod(n_samples, segment)
    part = jax.checkpoint(lambda c, ks: jax.lax.scan(body, c, ks), prevent_cse=False)
    carry, records = jax.lax.scan(part, carry, jnp.arange(m * segment).reshape(m, segment))
    records = jax.tree_util.tree_map(lambda a: a.reshape((m * segment,) + a.shape[2:]), records)
    if rest:
        carry, tail = jax.lax.scan(body, carry, jnp.arange(m * segment, n_samples))
        records = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a, b]), records, tail)
    return carry, records


def freeze(live, new, old):
    """``new`` where ``live``, else ``old``, leaf by leaf (NaN-safe: a select, no arithmetic)."""
    return jax.tree_util.tree_map(lambda a, b: jnp.where(live, a, b), new, old)


def _sample(system: System, inputs, carry: LoopCarry, k, record: bool):
    """One sample: the system's step, the status, the metrics, freezing and the record."""
    s = system.step(inputs, carry, k)
    was_live = carry.status == system.live
    status, fail_time = first_failure(carry.status, carry.fail_time, s.health, s.time, system.live)  # a float code
    live = status == system.live
    metrics = system.update(inputs, carry.metrics, s, live, was_live)
    state = freeze(live if s.keep is None else live & ~s.keep, s.state, carry.state)
    rec = system.record(inputs, s, state) if record else None
    return LoopCarry(state, s.aux, metrics, status, fail_time), rec


def run(
    system: System,
    inputs,
    n_samples: int,
    *,
    record: bool,
    until_done: bool = False,
    scalar_inputs: bool = False,
    checkpoint_policy=None,
    runs: int = 1,
):
    """Run one system over samples ``k = 0..n_samples-1`` (pure, unbatched; vmap it).

    Args:
        system: the system's functions.
        inputs: the run's inputs (a pytree; handed to every function of ``system``).
        n_samples: number of samples (static); with ``until_done``, the most samples.
        record: stack every sample's :attr:`System.record` (static).
        until_done: stop at the first sample whose status is not ``system.live`` (a
            ``lax.while_loop``; see the module docstring). Recorded, the loop still scans all
            ``n_samples`` samples.
        scalar_inputs: hand ``step``, ``update`` and ``record`` the inputs rebuilt inside the loop
            from scalars (:func:`pfjax.numerics.layout.as_scalars`), so reverse mode accumulates the
            cotangents of small per-run leaves as ``(runs,)`` arrays.
        checkpoint_policy: ``None``, or a ``jax.checkpoint`` policy: reverse mode then stores the
            carry (and what the policy saves) per sample and recomputes the sample; for many
            ``runs`` over many samples, in checkpointed segments (:func:`checkpoint_segment`).
        runs: the runs on this one's device, this one included, in every block (the ``vmap``
            around it; static): with a checkpoint policy, it decides the segments.

    Returns:
        ``system.finish(inputs, Run(...))``.
    """
    carry = _start(system, inputs)
    if scalar_inputs:
        parts, join = as_scalars(inputs)
        body = lambda c, k: _sample(system, join(parts), c, k, record)
    else:
        body = lambda c, k: _sample(system, inputs, c, k, record)
    segment = 0
    if checkpoint_policy is not None:
        body = jax.checkpoint(body, prevent_cse=False, policy=checkpoint_policy)
        segment = checkpoint_segment(n_samples, _tree_bytes(carry), runs)
    if until_done and not record:
        final = jax.lax.while_loop(
            lambda c: (c.status == system.live) & (c.k < n_samples),
            lambda c: body(c, c.k)[0]._replace(k=c.k + 1),
            carry._replace(k=jnp.asarray(0)),
        )
        records = None
    else:
        final, records = _scan(body, carry, n_samples, segment)
    return system.finish(
        inputs,
        Run(
            final.state,
            final.aux,
            final.metrics,
            final.status.astype(jnp.int32),
            final.status != system.live,
            final.fail_time,
            records,
        ),
    )


# ----------------------------------------------------------------------------- batches of runs
def stack(items):
    """Stack a list of pytrees with identical structure along a new leading axis: NumPy arrays, one
    per leaf, built on the host (``simulate_batch`` places them on the devices).

    In NumPy because JAX would compile one small program per leaf shape and item count
    (``jnp.stack``): 13 compilations in the paper reproduction, 4.6 s by JAX's compile log."""
    items = list(items)
    first = jax.tree_util.tree_structure(items[0])
    for i, item in enumerate(items[1:], 1):
        if jax.tree_util.tree_structure(item) != first:
            raise ValueError(
                f"stack: item {i} has a different structure from item 0 (e.g. a slip profile with other "
                f"terms present: give every run the same terms, zeros where unused)"
            )
    return jax.tree_util.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *items)


def unstack(tree, i: int):
    """Run ``i`` of a batched pytree (arrays stay on their device; NumPy leaves stay NumPy).

    One jitted gather for the whole tree: indexing each leaf from Python would dispatch (and
    compile) one program per leaf shape, seconds for a batch with trajectories."""
    leaves = jax.tree_util.tree_leaves(tree)
    if all(isinstance(a, np.ndarray) for a in leaves):
        return jax.tree_util.tree_map(lambda a: a[i], tree)
    if isinstance(i, (int, np.integer)) and leaves and not -leaves[0].shape[0] <= i < leaves[0].shape[0]:
        raise IndexError(f"unstack: run {i} is out of range for a batch of {leaves[0].shape[0]}")
    return _take(tree, i)


@jax.jit
def _take(tree, i):
    return jax.tree_util.tree_map(lambda a: a[i], tree)
