"""Worst-case search through the dynamic vehicle (:mod:`pfjax.sim.dynamic`): the friction and the
start errors that maximise a path-following cost, by multi-start gradient ascent.

The kinematic falsifier (:mod:`pfjax.falsification.search`) searches declared slip sequences; on the
dynamic vehicle the slip is not an input, so the search is over what is: the friction coefficient
``mu``, the start's lateral offset ``e_d`` (m, left of the start pose) and heading error ``e_theta``
(rad), each in a box. A box ``[lo, hi]`` is reached through ``x = lo + (hi - lo) sigmoid(r)`` of an
unconstrained ``r``, so that every ascent step stays inside. From ``n_starts`` uniformly drawn
``r``, ``steps`` steps of Adam ascent (learning rate ``lr``, on ``r``) on the run's objective::

    J(r) = metric(simulate(sc(mu, e_d, e_theta)))    (``iae`` m s, ``ise`` m^2 s or ``itae`` m s^2)

with the gradient by reverse mode through the whole run (the loop's checkpointing). A run that
fails (status not ``ok``) counts as found: its objective is reported with its status.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from jax import Array

from pfjax.controllers.base import Controller
from pfjax.models import single_track as st
from pfjax.models.slip import Pose
from pfjax.numerics import elementary as E
from pfjax.numerics.random import seed_key
from pfjax.sim import dynamic
from pfjax.sim.dynamic import DynamicScenario
from pfjax.sim.simulate import SimConfig


class DynamicBox(NamedTuple):
    """The search box: ``(low, high)`` of each searched input."""

    mu: tuple[float, float] = (0.3, 1.0)  # friction coefficient
    offset: tuple[float, float] = (-0.5, 0.5)  # m, start's lateral offset
    heading: tuple[float, float] = (-0.5236, 0.5236)  # rad, start's heading error


class DynamicFalsification(NamedTuple):
    """Result of :func:`falsify_dynamic` (host arrays)."""

    mu: np.ndarray  # (n_starts,) the final friction of each start
    offset: np.ndarray  # (n_starts,) m
    heading: np.ndarray  # (n_starts,) rad
    objective: np.ndarray  # (n_starts,) the final objective
    objective0: np.ndarray  # (n_starts,) the objective at each start's draw
    status: np.ndarray  # (n_starts,) int32 status of the final run
    history: np.ndarray  # (steps + 1, n_starts) objective along the ascent


def inputs(r: Array, box: DynamicBox) -> tuple[Array, Array, Array]:
    """``(mu, offset, heading)`` of the unconstrained ``r`` (shape ``(3,)``)."""
    lo = jnp.asarray([box.mu[0], box.offset[0], box.heading[0]], r.dtype)
    hi = jnp.asarray([box.mu[1], box.offset[1], box.heading[1]], r.dtype)
    x = lo + (hi - lo) * jax.nn.sigmoid(r)
    return x[0], x[1], x[2]


def scenario(r: Array, base: DynamicScenario, box: DynamicBox) -> DynamicScenario:
    """``base`` (one run) with the friction and the start errors of ``r``."""
    mu, off, head = inputs(r, box)
    p0 = Pose(*base.pose0)
    s, c = E.sincos(p0.theta)
    pose0 = Pose(p0.x - off * s, p0.y + off * c, p0.theta + head)
    return base._replace(pose0=pose0, vehicle=st.with_mu(base.vehicle, mu))


def objective(r: Array, controller: Controller, base: DynamicScenario, config: SimConfig, box: DynamicBox, metric: str):
    """The run's ``metric`` and status at ``r`` (pure; differentiate it with respect to ``r``)."""
    res = dynamic.simulate(controller, scenario(r, base, box), config)
    return getattr(res.metrics, metric), res.status


@partial(jax.jit, static_argnames=("controller", "config", "box", "metric", "lr"))
def _ascend(r, opt_state, controller, base, config, box, metric, lr):
    f = lambda r: objective(r, controller, base, config, box, metric)
    (value, status), g = jax.vmap(jax.value_and_grad(f, has_aux=True))(r)
    updates, opt_state = optax.adam(lr).update(jax.tree_util.tree_map(jnp.negative, g), opt_state, r)
    return optax.apply_updates(r, updates), opt_state, value, status


def falsify_dynamic(
    controller: Controller,
    base: DynamicScenario,
    config: SimConfig,
    *,
    box: DynamicBox = DynamicBox(),
    metric: str = "iae",
    n_starts: int = 4,
    steps: int = 20,
    lr: float = 0.3,
    key: Array | int = 0,
) -> DynamicFalsification:
    """Multi-start gradient ascent of ``metric`` over ``box`` (module docstring) from ``base`` (one
    run of the dynamic vehicle, its ``gains`` set; ``config.record`` is ignored)."""
    import dataclasses

    config = dataclasses.replace(config, record=False)
    key = seed_key(key) if isinstance(key, int) else key
    dtype = jnp.asarray(base.v_ref, float).dtype
    u = jax.random.uniform(key, (n_starts, 3), dtype, 0.02, 0.98)
    r = jnp.log(u) - jnp.log1p(-u)  # logit: uniform draws in the box
    opt_state = optax.adam(lr).init(r)
    history, status = [], None
    for _ in range(steps + 1):
        r_next, opt_next, value, status = _ascend(r, opt_state, controller, base, config, box, metric, lr)
        history.append(np.asarray(value))
        if len(history) <= steps:
            r, opt_state = r_next, opt_next
    mu, off, head = jax.vmap(lambda x: inputs(x, box))(r)
    hist = np.stack(history)
    return DynamicFalsification(
        np.asarray(mu), np.asarray(off), np.asarray(head), hist[-1], hist[0], np.asarray(status), hist
    )
