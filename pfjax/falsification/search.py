"""Worst-case search: gradient ascent through the simulator (a falsifier) and its random-sampling baseline.

For a controller ``C`` with gains ``g`` on a path, find the scenario ``x`` in the search space
(:mod:`pfjax.falsification.space`: slip bounded by ``A`` with bandwidth ``f_max``, initial conditions in a
box) that maximises an error measure ``J(x)`` of the simulated run (``SimConfig(record=False)``):

* ``"iae"`` (default) ``int |d| dt``; ``"ise"`` ``int d^2 dt``; ``"itae"`` ``int t |d| dt``;
* ``"max_abs_d"`` ``max_k |d_k|`` and ``"late_max_abs_d"`` (the max from ``success_from`` on) are
  non-smooth: their gradient is that of the one sample attaining the max (a subgradient), so
  each step pushes only that sample, and the maximiser can jump between samples.

:func:`falsify` maximises ``J(x(z))`` over the unconstrained parameters ``z`` with adam
(``b2 = 0.9``; step cosine-decayed from ``lr`` to ``lr/10``), from ``n_restarts`` random starts
vmapped into one batch. One ascent step (value and gradient of the batch, adam, best so far) is
one jitted function, compiled once per controller, config and array shapes (the objective is a
traced index) and reused by every step and by later calls of the same shapes.

Gradients are taken through the simulator's ``lax.scan`` in reverse mode, or in forward mode when
a scenario has at most 4 parameters (``autodiff.FORWARD_MAX``; :func:`pfjax.numerics.autodiff.value_and_grad`);
the projection contributes the closest point's implicit-function derivative. At the steering
saturation ``clip``, the rate limit, the angle wrap and the projection's step clips JAX
differentiates the active branch (the derivative of one side of the kink; on the saturated
branch the steering's derivative with respect to the command is 0, so a saturated stretch of a
run passes no gradient back through the controller). A non-finite gradient component is
replaced by 0 and counted (``n_nonfinite_grad``): a failed run freezes its state, so its
metrics stay finite, but the derivative of a run through a singularity need not be.

Ranking: a run whose status is not ``OK`` (diverged, singular, left the path's domain, non-finite)
is a falsifying scenario in itself and ranks above every healthy run; among failed runs, and among
healthy ones, the larger ``J`` wins (a NaN ``J`` ranks lowest), and of equals the first found.
``objective`` in the results is ``J`` of the chosen run; ``history`` is ``J`` of the best run so
far, which grows while the best run keeps its kind and may fall once, where the first failed run
takes the lead from a healthy one.

Budget: one *rollout* is one simulated scenario. The falsifier spends ``n_restarts * steps``
rollouts, each a forward pass *and* its derivative (``n_gradients``; reverse mode through the
scan costs about 5 forward passes and stores the scan's carries, O(horizon) memory per run);
:func:`random_search` spends ``n_samples`` forward-only rollouts. Equal ``n_rollouts`` is equal
scenario count, not equal compute.
"""

from __future__ import annotations

import contextlib
import dataclasses
from functools import partial
from typing import NamedTuple, get_args

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax import Array

from pfjax import errors
from pfjax.arrays import Leaf
from pfjax.controllers.base import Controller
from pfjax.falsification.space import (
    RawParams,
    SearchSpace,
    build_scenario,
    ic_from_raw,
    init_raw,
    sample,
    search_space,
    slip_from_raw,
)
from pfjax.models.slip import Pose, SlipParams
from pfjax.montecarlo.analysis_config import FalsifierSpec
from pfjax.numerics import autodiff
from pfjax.sim.simulate import Scenario, SimConfig, SimResult, simulate, simulate_batch, simulate_one, unstack
from pfjax.sim.status import Status

#: The metrics a search can maximise: a study's ``[falsifier] objective`` choices.
OBJECTIVES = get_args(FalsifierSpec.model_fields["objective"].annotation)
#: A study's ``[falsifier]`` defaults (objective, starts, steps), which :func:`falsify` takes too.
_SEARCH = FalsifierSpec()


class FalsifierResult(NamedTuple):
    """The worst scenario found and how the search got there.

    Attributes:
        objective: ``J`` of the worst run, in the objective's unit (m·s for ``iae``, m for
            ``max_abs_d``; :data:`pfjax.tables.COLUMNS`).
        status: that run's status code, an int32 (:class:`pfjax.sim.status.Status`; its name:
            :attr:`status_name`).
        slip: ``(n, 2)`` rad, its slip sequence (rear, front), each value held for ``seq_dt``.
        seq_dt: s, how long each slip value is held.
        ic: ``(3,)``: its start's lateral offset ``d0`` (m), heading error ``theta_e0`` (rad) and
            path parameter ``u0``.
        pose0: its start pose (x m, y m, heading rad).
        scenario: the run itself (re-simulate it with :func:`worst_trajectory`).
        history: ``J`` of the best run so far after ``history_rollouts[i]`` rollouts.
        history_rollouts: rollouts spent at each history entry (ints).
        n_rollouts: scenarios simulated.
        n_gradients: of those, how many also ran the backward pass.
        n_nonfinite_grad: gradient components that were not finite (replaced by 0).
        restarts: every start's last scenario (slip ``(R, n, 2)`` rad, ``ic`` ``(R, 3)``), or None.
    """

    objective: Array  # () J of the worst run (units of the objective: m s for IAE)
    status: Array  # () int32, that run's pfjax.sim.status.Status
    slip: Array  # (n, 2) rad, its slip sequence (rear, front), held for seq_dt each
    seq_dt: Array  # () s
    ic: Array  # (3,) its d0 m, theta_e0 rad, u0 (path parameter)
    pose0: Pose  # m, m, rad, its start pose
    scenario: Scenario  # the run itself (re-simulate with worst_trajectory)
    history: Array  # (n_hist,) J of the best run after history_rollouts[i] rollouts
    history_rollouts: Array  # (n_hist,) int, rollouts spent at each history entry
    n_rollouts: int  # simulated scenarios
    n_gradients: int  # of those, how many also ran the backward pass
    n_nonfinite_grad: int  # gradient components that were not finite (replaced by 0)
    restarts: tuple[Array, Array] | None = None  # falsify: every start's last (slip (R, n, 2) rad, ic (R, 3))

    @property
    def status_name(self) -> str:
        """The worst run's status by name (``ok``, ``diverged``, ...; :data:`pfjax.sim.STATUS_NAMES`)."""
        from pfjax.sim.status import STATUS_NAMES

        return STATUS_NAMES[int(self.status)]


class _Best(NamedTuple):
    failed: Array  # () bool: the run's status is not OK
    score: Array  # () J, -inf if NaN
    value: Array  # () J
    status: Array  # () int32
    raw: RawParams


def _rank(value: Leaf, status: Leaf, xp=jnp) -> tuple[Leaf, Leaf]:
    """The ranking key (module docstring) of runs: ``(failed, J)``, ``J`` -inf where NaN; ``xp``:
    ``jnp``, or ``np`` for host arrays."""
    return status != Status.OK, xp.where(xp.isnan(value), -xp.inf, value)


def _beats(failed_new, score_new, failed_old, score_old):
    """Whether a run ranks above another: failed above healthy, then the larger ``J``."""
    return (failed_new & ~failed_old) | ((failed_new == failed_old) & (score_new > score_old))


def _first_best(failed: Leaf, score: Leaf, xp=jnp):
    """Index of the best run of a batch by :func:`_rank`'s key, the first of equals."""
    index = xp.arange(score.shape[0])
    return xp.lexsort((-index, score, failed.astype(xp.int32)))[-1]


def check_settings(**settings) -> None:
    """:class:`~pfjax.errors.InputError` naming the argument for a value of a search's settings
    (``slip_bound_deg``, ``f_max_hz``, ``objective``, ``n_restarts``, ``steps``, ``lateral_offset``,
    ``heading_error_deg``) that a study config's ``[falsifier]`` table refuses: its schema
    (:class:`pfjax.montecarlo.analysis_config.FalsifierSpec`) holds the limits, so a search is judged
    alike from a config, a library call and the API."""
    from pfjax.config import load_model
    from pfjax.montecarlo.analysis_config import FalsifierSpec

    load_model(FalsifierSpec, data=settings)


def _setup(path, gains, config, slip_bound_deg, f_max_hz, ic_bounds, objective, params, noise, space_kw):
    check_settings(slip_bound_deg=slip_bound_deg, f_max_hz=f_max_hz, objective=objective)
    space = search_space(
        horizon=config.n_steps * config.dt,
        slip_bound_deg=slip_bound_deg,
        f_max_hz=f_max_hz,
        ic_bounds=ic_bounds,
        **space_kw,
    )
    arr = lambda tree: jax.tree_util.tree_map(jnp.asarray, tree)
    params = SlipParams() if params is None else params
    base = Scenario(
        pose0=Pose(0.0, 0.0, 0.0),
        slip=None,
        params=arr(params),
        path=arr(path),
        gains=arr(gains),
        noise=None if noise is None else arr(noise),
    )
    return space, base, config


# The search's own small steps are jitted, each one program: op by op, JAX compiles every operation
# of a new shape on its own (a search of new shapes compiled 81 programs, now 23: tests/test_falsify.py).
_build_scenario = jax.jit(build_scenario)


@jax.jit
def _from_raw(space: SearchSpace, raw: RawParams) -> tuple[Array, Array]:
    return slip_from_raw(space, raw.slip), ic_from_raw(space, raw.ic)


@partial(jax.jit, static_argnames="n")
def _repeat(tree, n: int):
    """``n`` copies of an unbatched pytree along a new leading axis."""
    return jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (n,) + jnp.shape(a)), tree)


def _result(
    space, base, seq, ic, value, status, history, history_rollouts, n_rollouts, n_gradients, n_nonfinite, restarts=None
):
    sc = _build_scenario(space, seq, ic, base)
    return FalsifierResult(
        objective=value,
        status=jnp.asarray(status, jnp.int32),
        slip=seq,
        seq_dt=space.seq_dt,
        ic=ic,
        pose0=sc.pose0,
        scenario=sc,
        history=jnp.asarray(history),
        history_rollouts=jnp.asarray(history_rollouts),
        n_rollouts=int(n_rollouts),
        n_gradients=int(n_gradients),
        n_nonfinite_grad=int(n_nonfinite),
        restarts=restarts,
    )


def _cosine_lr(lr: float, steps: int) -> np.ndarray:
    """Adam's step per iteration: ``lr`` cosine-decayed to ``lr/10`` over ``steps``."""
    k = np.arange(steps)
    return lr * (0.1 + 0.9 * 0.5 * (1.0 + np.cos(np.pi * k / max(steps - 1, 1))))


#: Adam's direction with ``b2 = 0.9`` (optax's default 0.999 remembers the large early gradients of
#: the slip amplitude for ~1000 steps and so crawls along the flat directions that remain, e.g.
#: the absolute phase of a worst-case sinusoid; 0.9 found a larger J on every seed tried).
_ADAM = optax.scale_by_adam(b2=0.9)
_adam_init = jax.jit(_ADAM.init)


def _objective(metrics, which: Array) -> Array:
    """``J = metrics[OBJECTIVES[which]]`` (``which`` traced: one compile serves every objective)."""
    return jnp.stack([getattr(metrics, name) for name in OBJECTIVES])[which]


@partial(jax.jit, static_argnames=("controller", "config"))
def _ascent_step(
    raw: RawParams,
    opt_state,
    best: _Best,
    lr: Array,
    which: Array,
    space: SearchSpace,
    base: Scenario,
    *,
    controller: Controller,
    config: SimConfig,
):
    """One adam step on ``-J`` for every start of the batch; keeps the best run evaluated so far.

    Returns ``(raw, opt_state, best, n_nonfinite)``, the last the number of gradient components
    that were not finite (replaced by 0).
    """

    def run(r: RawParams):
        sc = build_scenario(space, slip_from_raw(space, r.slip), ic_from_raw(space, r.ic), base)
        res = simulate(controller, sc, config)
        return _objective(res.metrics, which), res.status

    (value, status), grad = jax.vmap(autodiff.value_and_grad(run, has_aux=True))(raw)
    failed, score = _rank(value, status)
    i = _first_best(failed, score)
    better = _beats(failed[i], score[i], best.failed, best.score)
    pick = lambda new, old: jnp.where(better, new, old)
    best = _Best(
        pick(failed[i], best.failed),
        pick(score[i], best.score),
        pick(value[i], best.value),
        pick(status[i], best.status),
        jax.tree_util.tree_map(lambda a, b: pick(a[i], b), raw, best.raw),
    )
    leaves = jax.tree_util.tree_leaves(grad)
    n_nonfinite = sum(jnp.sum(~jnp.isfinite(g)) for g in leaves)
    descent = jax.tree_util.tree_map(lambda g: -jnp.where(jnp.isfinite(g), g, 0.0), grad)  # of -J
    direction, opt_state = _ADAM.update(descent, opt_state)
    raw = jax.tree_util.tree_map(lambda p, u: p - lr * u, raw, direction)
    return raw, opt_state, best, n_nonfinite


def falsify(
    controller: Controller,
    gains,
    path,
    *,
    config: SimConfig,
    slip_bound_deg: float,
    f_max_hz: float,
    ic_bounds: dict,
    objective: str = _SEARCH.objective,
    n_restarts: int = _SEARCH.n_restarts,
    steps: int = _SEARCH.steps,
    lr: float = 0.2,
    key: Array,
    params: SlipParams | None = None,
    noise=None,
    n_freq: int = 8,
    with_constant: bool = True,
    seq_dt: float = 0.05,
) -> FalsifierResult:
    """Gradient ascent on ``J`` over slip profiles and initial conditions (module docstring).

    Args:
        controller: the controller under test (static).
        gains: its parameter pytree.
        path: a path shape from :mod:`pfjax.paths`.
        config: simulator settings (``record`` is forced off).
        slip_bound_deg: slip amplitude bound ``A`` per axle, deg.
        f_max_hz: slip bandwidth, Hz (0: constant slip).
        ic_bounds: ``{"d": (lo, hi) m, "theta_e_deg": (lo, hi) deg, "u": (lo, hi)}``
            (:func:`pfjax.falsification.space.search_space`).
        objective: one of :data:`OBJECTIVES`.
        n_restarts: random starts, ascended together as one vmapped batch.
        steps: adam steps per start.
        lr: adam's initial step (cosine-decayed to ``lr/10``), in units of the raw parameters.
        key: ``jax.random.PRNGKey`` for the starts.
        params: physical parameters (default ``SlipParams`` with a 30 deg steering limit).
        noise: ``SensorNoise`` or ``None``.
        n_freq, with_constant, seq_dt: the slip's basis (:func:`pfjax.falsification.space.search_space`).

    Returns:
        :class:`FalsifierResult`; ``n_rollouts = n_gradients = n_restarts * steps``, history per step.

    Raises:
        InputError: ``slip_bound_deg``, ``f_max_hz``, ``objective``, ``n_restarts`` or ``steps`` out of
            a study config's ``[falsifier]`` limits (:func:`check_settings`), named in the message.
    """
    check_settings(n_restarts=n_restarts, steps=steps)
    space, base, config = _setup(
        path,
        gains,
        config,
        slip_bound_deg,
        f_max_hz,
        ic_bounds,
        objective,
        params,
        noise,
        dict(n_freq=n_freq, with_constant=with_constant, seq_dt=seq_dt),
    )
    config = dataclasses.replace(config, record=False)
    raw = init_raw(space, key, int(n_restarts))
    dtype = space.basis.dtype
    best = _Best(
        jnp.asarray(False),
        jnp.asarray(-jnp.inf, dtype),
        jnp.asarray(jnp.nan, dtype),
        jnp.int32(Status.OK),
        unstack(raw, 0),
    )
    opt_state, history, nonfinite = _adam_init(raw), [], []
    which = jnp.int32(OBJECTIVES.index(objective))
    for lr_k in _cosine_lr(float(lr), int(steps)):
        raw, opt_state, best, bad = _ascent_step(
            raw, opt_state, best, jnp.asarray(lr_k, dtype), which, space, base, controller=controller, config=config
        )
        history.append(best.value)
        # one step at a time: a study runs this search in a background thread on one device, where
        # steps dispatched ahead would queue in front of the main thread's multi-device programs,
        # whose other devices then wait for that device at a rendezvous that XLA's CPU runtime ends
        # by aborting the process after 40 s (seen with the default study, compilation cache warm)
        nonfinite.append(jax.block_until_ready(bad))
    n = int(n_restarts) * int(steps)
    seq, ic = _from_raw(space, best.raw)
    hist, hist_n = np.stack(jax.device_get(history)), int(n_restarts) * np.arange(1, int(steps) + 1)
    bad, restarts = int(np.sum(jax.device_get(nonfinite))), jax.vmap(_from_raw, in_axes=(None, 0))(space, raw)
    return _result(space, base, seq, ic, best.value, best.status, hist, hist_n, n, n, bad, restarts)


@jax.jit
def _scenarios(space: SearchSpace, seq: Array, ic: Array, idx: Array, base: Scenario) -> Scenario:
    """The scenarios of draws ``idx`` of ``(seq, ic)``."""
    return jax.vmap(build_scenario, in_axes=(None, 0, 0, None))(space, seq[idx], ic[idx], base)


def random_search(
    controller: Controller,
    gains,
    path,
    *,
    config: SimConfig,
    slip_bound_deg: float,
    f_max_hz: float,
    ic_bounds: dict,
    objective: str = _SEARCH.objective,
    n_samples: int,
    key: Array,
    batch_size: int = 64,
    params: SlipParams | None = None,
    noise=None,
    n_freq: int = 8,
    with_constant: bool = True,
    seq_dt: float = 0.05,
    devices=None,
) -> FalsifierResult:
    """The baseline: ``n_samples`` random draws of the same set (:func:`pfjax.falsification.space.sample`),
    simulated with :func:`~pfjax.sim.simulate_batch` in chunks of ``batch_size`` (the last one
    padded, so one compile), the worst kept. All draws come from ``key`` at once, so the result
    does not depend on ``batch_size``. Arguments as :func:`falsify`; history per sample.

    ``config.record`` is honoured though the trajectories are discarded: with ``record=True`` and
    the same ``batch_size``, :func:`worst_trajectory` reuses this search's compiled program.
    ``devices``: as :func:`~pfjax.sim.simulate_batch` (default: all)."""
    errors.integer("n_samples", n_samples, low=1)
    errors.integer("batch_size", batch_size, low=1)
    space, base, config = _setup(
        path,
        gains,
        config,
        slip_bound_deg,
        f_max_hz,
        ic_bounds,
        objective,
        params,
        noise,
        dict(n_freq=n_freq, with_constant=with_constant, seq_dt=seq_dt),
    )
    n, b = int(n_samples), min(int(batch_size), int(n_samples))
    seq, ic = sample(space, key, n)
    values, statuses = [], []
    for start in range(0, n, b):
        idx = np.minimum(np.arange(start, start + b), n - 1)
        res = simulate_batch(
            _scenarios(space, seq, ic, idx, base), controller=controller, config=config, devices=devices
        )
        keep = min(b, n - start)
        values.append(np.asarray(getattr(res.metrics, objective))[:keep])
        statuses.append(np.asarray(res.status)[:keep])
    all_values, all_statuses = np.concatenate(values), np.concatenate(statuses)
    failed, score = _rank(all_values, all_statuses, np)
    # Running best: index of the first best run of [:k+1] for every k.
    leader = np.zeros(n, dtype=int)
    for k in range(1, n):
        j = leader[k - 1]
        leader[k] = k if _beats(failed[k], score[k], failed[j], score[j]) else j
    i = leader[-1]
    seq_i, ic_i = unstack((seq, ic), i)
    return _result(
        space,
        base,
        seq_i,
        ic_i,
        jnp.asarray(all_values[i]),
        all_statuses[i],
        all_values[leader],
        np.arange(1, n + 1),
        n,
        0,
        0,
    )


def worst_trajectory(
    controller: Controller, result: FalsifierResult, config: SimConfig, batch_size: int = 1, devices=None
) -> SimResult:
    """Re-simulate the worst scenario with ``record=True`` (for plotting): one unbatched ``SimResult``.

    ``batch_size=1`` (default): the one run through :func:`~pfjax.sim.simulate.simulate_one` (the
    unbatched program, on ``devices[0]`` if given, else JAX's default device). Above 1, the scenario
    is repeated to this batch size, so the replay runs a batched program compiled before (a
    :func:`random_search` with ``record=True`` and this ``batch_size``) instead of compiling one.
    ``devices``: as :func:`~pfjax.sim.simulate_batch`."""
    if int(batch_size) < 1:
        raise ValueError(f"batch_size: must be >= 1, got {batch_size}")
    config = dataclasses.replace(config, record=True)
    if int(batch_size) == 1:
        with contextlib.nullcontext() if devices is None else jax.default_device(next(iter(devices))):
            return simulate_one(result.scenario, controller=controller, config=config)
    res = simulate_batch(
        _repeat(result.scenario, int(batch_size)), controller=controller, config=config, devices=devices
    )
    return unstack(res, 0)
