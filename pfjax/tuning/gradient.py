"""Gradient tuning: ``jax.value_and_grad`` through the simulator, an optax optimiser, a box.

The parameters live in the box ``lower <= theta <= upper`` (the GA's bounds) and are optimised
in normalised coordinates ``z = (theta - lower) / (upper - lower) in [0, 1]^D`` so that one
learning rate suits gains of different magnitudes. One step::

    J, g = value_and_grad(cost)(theta(z))            # n rollouts, forward (or reverse) mode through lax.scan
    z    <- clip(z + optax_update(g (upper - lower)), 0, 1)    # projected step

The result is the best ``theta`` evaluated (the iterate with the lowest ``J``), not the last.
``n_starts`` starts are descended together (vmapped, one batched call per step). Budget: each
step simulates ``n`` rollouts per start (the batch), so ``n_rollouts = steps * n * n_starts``;
``n_forward_passes`` charges each ``1 + D`` in forward mode, 4 in reverse mode
(:func:`pfjax.numerics.autodiff.forward_passes_per_gradient`). The step is compiled ahead of time;
``wall_s`` excludes it (``compile_s``). :mod:`pfjax.tuning.multistart` builds a reliable tuner from
this step (screening, successive halving, restarts, smoothing). With
a few gains (``mode="auto"``: at most 4) the gradient is taken in forward mode, one tangent per
gain alongside the forward pass (2 gains: 1.6-1.9 forward passes for value and gradient, O(1) memory
in the horizon); with more, in reverse mode (3.2-4.9 forward passes, O(horizon) memory per run for
the scan's carries: the cost vmaps the single-run simulator itself, so its loop checkpoints every
step). Measured: :mod:`pfjax.numerics.autodiff`.

Non-smooth points, and what the gradient is there (JAX's derivative of the active branch):

* **steering saturation** ``clip(delta_cmd, -delta_max, delta_max)``: derivative 0 with respect to
  the command while saturated, so a saturated stretch passes no gradient to the gains (a run
  saturated throughout has zero gradient: the optimiser relies on the unsaturated part of the
  batch, and the box keeps it from running off);
* **|d| in IAE/ITAE**: ``sign(d)`` (0 at ``d = 0`` exactly, a subgradient);
* **angle wrapping** of ``theta_e`` (``atan2``-based): smooth except at ±π, where a run would be
  a half turn off the path (such runs get the failure penalty, whose gradient is 0);
* **projection** (warm-started Newton with clipped steps onto the path): the derivative of its last
  Newton step from the previous iterate held fixed, i.e. the implicit-function derivative of the
  closest point up to the Newton residual (:func:`pfjax.paths.geometry.closest_parameter`); at a
  clipped step the derivative is that of the clip's active side;
* **failures**: a failed run's state is frozen (``jnp.where``), its metrics stop accumulating and
  the constant penalty adds nothing to the gradient; status flips are discontinuities the
  gradient does not see.
* **order statistics** (quantile, CVaR): the gradient of the runs active in the sort.

A non-finite gradient component (none seen in the tests and study; guarded anyway) is replaced by
0 and counted in ``n_nonfinite_grad``.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pfjax import errors
from pfjax.numerics import autodiff

#: The most forward-pass rollout-steps (a gradient rollout-step charged ``1 + D`` in forward mode, 4
#: in reverse; a value-only one 1) a tuning run's padded points may add when its evaluations of
#: several batch shapes share one compiled program: the multi-start tuner's halving rounds and
#: restarts, and its polish on the screening's program (:func:`pfjax.tuning.multistart.multistart_tune`),
#: the GA's children on the population's program (:func:`ga_tune`). A few tenths of a second of
#: simulation, against about a second to compile each further program (docs/design-and-tuning.md).
PAD_FORWARD_PASSES = 10_000_000


def pads_cheaply(forward_passes: int, rollout_steps: int | None) -> bool:
    """Whether ``forward_passes`` padded rollouts (charged as in ``n_forward_passes``) of
    ``rollout_steps`` steps each cost at most :data:`PAD_FORWARD_PASSES` rollout-steps, so a shared
    compiled program is worth them; never for a cost of unknown size (``rollout_steps`` None)."""
    return rollout_steps is not None and int(forward_passes) * int(rollout_steps) <= PAD_FORWARD_PASSES


def pad_rows(a, n: int) -> np.ndarray:
    """``a`` (rows along its first axis) followed by copies of its first row up to ``n`` rows: the
    places of a shared compiled program's extra points or chains, whose results are dropped."""
    a = np.asarray(a)
    return np.concatenate([a, np.repeat(a[:1], n - len(a), axis=0)])


class TuneResult(NamedTuple):
    """The outcome of a tuning run (GA or gradient), in one shape for both."""

    theta: np.ndarray  # (D,) best parameters found
    cost: float  # its cost
    history: np.ndarray  # best cost so far after each iteration (GA: generation; gradient: step)
    history_rollouts: np.ndarray  # rollouts simulated when each history entry was reached
    history_wall_s: np.ndarray  # wall time (s) at each history entry, compilation excluded
    n_rollouts: int  # simulated rollouts in all, value-only or with a gradient
    wall_s: float  # wall time of the whole run, s, compilation excluded
    n_nonfinite_grad: int  # gradient components replaced by 0 (gradient tuning only)
    n_forward_passes: int = 0  # forward-pass equivalents: a rollout with its gradient counts 1 + D (forward mode) or 4
    compile_s: float = 0.0  # ahead-of-time compilation, s (not in wall_s)


def gradient_tune(
    cost: Callable,
    lower,
    upper,
    *,
    theta0=None,
    key=None,
    steps: int = 100,
    n_starts: int = 1,
    n_per_eval: int = 1,
    learning_rate: float = 0.05,
    optimizer: optax.GradientTransformation | None = None,
    progress: bool = False,
    mode: str = "auto",
) -> TuneResult:
    """Minimise ``cost(theta)`` (a traceable scalar function) over the box by projected descent.

    Args:
        cost: ``theta (D,) -> scalar`` (e.g. :func:`pfjax.tuning.cost.batch_cost`).
        lower, upper: ``(D,)`` box.
        theta0: start; ``None`` draws it uniformly in the box from ``key``.
        key: JAX PRNG key for the start (required if ``theta0`` is None).
        steps: gradient steps (each evaluates ``cost`` and its gradient once per start).
        n_starts: independent starts descended together (vmapped: one batched call per step);
            the first is ``theta0`` when given, the others uniform in the box from ``key``.
        n_per_eval: rollouts per ``cost`` call (the batch size), for the budget count.
        learning_rate: adam step in normalised box units, cosine-decayed to a tenth over ``steps``
            (ignored if ``optimizer`` is given).
        optimizer: an optax transformation on the normalised coordinates (default: that adam).
        progress: tqdm bar over the steps.
        mode: differentiation mode, ``"auto"`` (forward mode for at most 4 parameters, reverse
            above), ``"forward"`` or ``"reverse"`` (:func:`pfjax.numerics.autodiff.value_and_grad`).
    """
    lo, hi = errors.box(lower, upper)
    span = hi - lo
    n_starts = errors.integer("n_starts", n_starts, low=1, high=1_000_000)
    errors.integer("steps", steps, low=1, high=1_000_000)
    errors.number("learning_rate", learning_rate, positive=True)
    autodiff.resolve_mode(mode, lo.size)
    z = _starts(theta0, key, n_starts, lo, span)
    opt = optimizer or adam(float(learning_rate), int(steps))
    lo_j, span_j = jnp.asarray(lo), jnp.asarray(span)
    state = opt.init(z)
    t_c = time.perf_counter()
    compiled = _step.lower(z, state, lo_j, span_j, cost=cost, opt=opt, mode=mode).compile()
    compile_s = time.perf_counter() - t_c
    t0 = time.perf_counter()
    best_J, best_z, hist, hist_t, n_bad = _descend(
        lambda z, state: compiled(z, state, lo_j, span_j), z, state, steps, progress, t0
    )
    hist_r = [(k + 1) * n_per_eval * n_starts for k in range(steps)]
    theta = lo + span * best_z
    n_roll = steps * n_per_eval * n_starts
    return TuneResult(
        theta,
        float(best_J),
        np.asarray(hist),
        np.asarray(hist_r, dtype=np.int64),
        np.asarray(hist_t),
        n_roll,
        time.perf_counter() - t0,
        n_bad,
        n_roll * autodiff.forward_passes_per_gradient(lo.size, mode),
        compile_s,
    )


def _starts(theta0, key, n_starts: int, lo: np.ndarray, span: np.ndarray):
    """``(n_starts, D)`` starts in box units: ``theta0`` first when given, the others uniform from ``key``."""
    if key is None and (theta0 is None or n_starts > 1):
        raise errors.InputError("key: required for random starts")
    starts = [] if theta0 is None else [np.asarray(theta0, np.float64)]
    if len(starts) < n_starts:
        u = np.asarray(jax.random.uniform(key, (n_starts - len(starts),) + lo.shape), np.float64)
        starts += list(lo + span * u)
    return jnp.asarray(np.clip((np.stack(starts) - lo) / span, 0.0, 1.0))


def _descend(step, z, state, steps: int, progress: bool, t0: float):
    """``steps`` calls of the compiled ``step``; returns the best cost and its point (box units), the
    best cost so far and the wall time after each step, and the count of non-finite gradients.
    Where no cost is finite, the point is the first start (one point, as always) and the cost inf."""
    best_J, best_z = np.inf, np.asarray(z)[0]
    hist, hist_t, n_bad = [], [], 0
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=steps, desc="gradient", leave=False)
    for _ in range(steps):
        z_k = z
        J, z, state, nb = step(z, state)
        J = np.where(np.isfinite(np.asarray(J)), np.asarray(J), np.inf)
        n_bad += int(nb)
        i = int(np.argmin(J))
        if J[i] < best_J:
            best_J, best_z = float(J[i]), np.asarray(z_k[i])
        hist.append(best_J)
        hist_t.append(time.perf_counter() - t0)
        if bar is not None:
            bar.update(1)
            bar.set_postfix(best=f"{best_J:.5g}")
    if bar is not None:
        bar.close()
    return best_J, best_z, hist, hist_t, n_bad


@functools.lru_cache(maxsize=32)
def adam(learning_rate: float, steps: int) -> optax.GradientTransformation:
    """Adam with the step cosine-decayed from ``learning_rate`` to a tenth of it over ``steps``."""
    return optax.adam(optax.cosine_decay_schedule(learning_rate, max(steps, 1), alpha=0.1))


@functools.partial(jax.jit, static_argnames=("cost", "opt", "mode"))
def _step(z, state, lo, span, *, cost, opt, mode="auto"):
    """One projected step of every start (compiled once per cost function and optimiser; adam is
    elementwise, so one optimiser state of shape (n_starts, D) serves all starts)."""
    J, g = jax.vmap(autodiff.value_and_grad(lambda zz: cost(lo + span * zz), mode=mode))(z)
    bad = ~jnp.isfinite(g)
    g = jnp.where(bad, 0.0, g)
    upd, state = opt.update(g, state, z)
    return J, jnp.clip(optax.apply_updates(z, upd), 0.0, 1.0), state, jnp.sum(bad)


def ga_tune(
    cost_batch,
    lower,
    upper,
    *,
    key,
    options=None,
    n_per_eval: int = 1,
    rollout_steps: int | None = None,
    progress: bool = False,
) -> TuneResult:
    """:func:`pfjax.tuning.ga.ga` wrapped into a :class:`TuneResult` (rollouts = evaluations x batch).

    A :class:`pfjax.tuning.cost.PopulationCost` is compiled ahead of time: for the population's
    ``P`` points and, unless padded, the ``P - E`` children of each generation. ``rollout_steps``:
    the rollout-steps of one evaluation, when known; then the children of a ``PopulationCost`` are
    evaluated on the population's program, padded with copies of the first child whose costs are
    dropped, if the ``E`` padded evaluations per generation add at most :data:`PAD_FORWARD_PASSES`
    rollout-steps to the run: one compilation fewer (the costs are those of independent lanes of
    one vmapped program)."""
    from pfjax.tuning.ga import GAOptions, ga

    options = options or GAOptions()
    P, E = options.population_size, options.elite_count
    compiled = hasattr(cost_batch, "compile")  # a pfjax.tuning.cost.PopulationCost
    pad = compiled and pads_cheaply(E * options.generations, rollout_steps)
    t_c = time.perf_counter()
    if compiled:
        for n in ({P} if pad else {P, P - E}) - {0}:
            cost_batch.compile(n, np.size(lower))
    compile_s = time.perf_counter() - t_c
    t0 = time.perf_counter()
    times = []

    def timed(X):
        f = np.asarray(cost_batch(pad_rows(X, P)))[: len(X)] if pad else cost_batch(X)
        times.append(time.perf_counter() - t0)
        return f

    r = ga(timed, lower, upper, key=key, options=options, progress=progress)
    evals = P + np.arange(options.generations + 1) * (P - E)
    return TuneResult(
        np.asarray(r.x),
        float(r.f),
        r.history_best,
        evals * n_per_eval,
        np.asarray(times),
        r.n_evaluations * n_per_eval,
        time.perf_counter() - t0,
        0,
        r.n_evaluations * n_per_eval,
        compile_s,
    )
