"""Tuning costs: a controller's parameters -> one number over a batch of scenarios.

Per run ``i`` (metrics from :mod:`pfjax.metrics.running`, ``SimConfig(record=False)``)::

    J_i = M_i + w_u * int delta^2 dt + P * [run i failed]

with ``M`` one of IAE ``int |d| dt`` (m s, the source's eq. 15 as assumed in docs/reproductions/path-following.md §5), ISE
``int d^2 dt`` (m^2 s) or ITAE ``int t |d| dt`` (m s^2), ``w_u`` the control-effort weight
(``effort``, per rad^2 s) and ``P`` the failure penalty (``fail_penalty``, in the metric's
units; a failed run's metrics stop accumulating at the failure, so without it a run that
diverges early would look cheap). Over the batch ``J_1..J_n``:

* ``mean``: ``(1/n) sum J_i``;
* ``quantile``: the ``level`` quantile (linear interpolation between order statistics);
* ``cvar``: the mean of the ``k = ceil((1 - level) n)`` largest ``J_i`` (conditional value at
  risk, the expected cost of the worst ``1 - level`` fraction).

All three are piecewise smooth in ``J`` (through ``sort``), so ``jax.grad`` gives the gradient
of the active order statistics. The same function serves the GA (batched, forward only) and
gradient tuning, so both optimise exactly the same number.

Parameters are tuned as a flat vector ``theta`` inside a box; :class:`Tunable` maps it to the
controller's gains pytree (the other gain fields stay at their base values).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pfjax.controllers.base import Controller
from pfjax.sim import dynamic
from pfjax.sim.dynamic import DynamicScenario
from pfjax.sim.simulate import Scenario, SimConfig, simulate
from pfjax.sim.status import Status

METRICS = ("iae", "ise", "itae")
AGGREGATES = ("mean", "quantile", "cvar")
#: The quantile / CVaR level when :class:`CostSpec` is given none.
LEVEL = 0.9


class CostSpec(NamedTuple):
    """What is minimised (see the module docstring)."""

    metric: str = "iae"  # iae | ise | itae
    effort: float = 0.0  # weight on int delta^2 dt (metric units per rad^2 s)
    aggregate: str = "mean"  # mean | quantile | cvar
    level: float | None = None  # quantile / CVaR level (None: LEVEL); not with the mean
    fail_penalty: float = 100.0  # added to a failed run's cost (metric units)

    @property
    def quantile_level(self) -> float:
        """The quantile / CVaR level: ``level``, or :data:`LEVEL` when it is not given."""
        return LEVEL if self.level is None else self.level

    def check(self) -> CostSpec:
        """``self`` if every field is valid, with the quantile's or CVaR's ``level`` filled in
        (:data:`LEVEL` when not given, so that a record of the spec says what ran);
        :class:`~pfjax.errors.InputError` naming the field (a ``level`` with the mean, which reads
        none, too)."""
        from pfjax import errors

        if self.metric not in METRICS:
            raise errors.InputError(f"metric: value {self.metric!r}, expected one of {', '.join(METRICS)}")
        if self.aggregate not in AGGREGATES:
            raise errors.InputError(f"aggregate: value {self.aggregate!r}, expected one of {', '.join(AGGREGATES)}")
        if self.level is not None:
            if self.aggregate == "mean":
                raise errors.InputError("level: not with aggregate mean (only with quantile, cvar)", "level")
            if not 0.0 < errors.number("level", self.level) < 1.0:
                raise errors.InputError(f"level: value {self.level:g}, expected in (0, 1)")
        errors.number("effort", self.effort, nonnegative=True)
        errors.number("fail_penalty", self.fail_penalty, nonnegative=True)
        return self if self.level is not None or self.aggregate == "mean" else self._replace(level=LEVEL)


class Tunable(NamedTuple):
    """A flat parameter vector ``theta`` <-> gain fields of a controller's parameter pytree."""

    base: Any  # the gains pytree (a NamedTuple); untuned fields keep these values
    fields: tuple  # names of the tuned fields, in order (each a scalar or a vector)

    @property
    def sizes(self) -> tuple:
        return tuple(int(np.size(getattr(self.base, f))) for f in self.fields)

    def flatten(self, gains=None) -> np.ndarray:
        g = self.base if gains is None else gains
        return np.concatenate([np.ravel(np.asarray(getattr(g, f), dtype=np.float64)) for f in self.fields])

    def gains(self, theta) -> Any:
        """The gains pytree with ``theta`` written into the tuned fields (traceable)."""
        out, i = {}, 0
        for f, n in zip(self.fields, self.sizes):
            shape = jnp.shape(getattr(self.base, f))
            out[f] = jnp.reshape(theta[i : i + n], shape)
            i += n
        return self.base._replace(**out)


def run_costs(metrics, status, spec: CostSpec):
    """``J_i`` of each run (module docstring); ``metrics`` / ``status`` batched along axis 0."""
    m = getattr(metrics, spec.metric)
    failed = status != Status.OK
    return m + spec.effort * metrics.steer_energy + spec.fail_penalty * failed.astype(m.dtype)


def aggregate(J, spec: CostSpec):
    """Mean / quantile / CVaR of the per-run costs ``J`` (shape ``(n,)``)."""
    if spec.aggregate == "mean":
        return jnp.mean(J)
    if spec.aggregate == "quantile":
        return jnp.quantile(J, spec.quantile_level)
    return jnp.mean(jnp.sort(J)[-tail_count(spec.quantile_level, J.shape[0]) :])


def tail_count(level: float, n: int) -> int:
    """The CVaR's ``k = ceil((1 - level) n)``, at least 1, with ``x = (1 - level) n`` lowered by a
    relative 1e-9 first: ``(1 - 0.7) * 10`` is ``3.0000000000000004`` in floating point (and
    ``(1 - 0.18) * 10^7`` one spacing above 8,200,000), whose ceiling would keep one run too many."""
    x = (1.0 - level) * n
    return max(1, math.ceil(x - 1e-9 * max(1.0, x)))


def batch_cost(controller: Controller, tunable: Tunable, scenarios, config: SimConfig, spec: CostSpec):
    """``cost(theta) -> scalar`` over ``scenarios`` (their ``gains`` are ignored).

    ``scenarios`` is one batched :class:`Scenario` or a list of them (one per path shape: a batch
    holds one path type), or the same of the dynamic vehicle's
    :class:`~pfjax.sim.dynamic.DynamicScenario` (tuning through the ST or STD model); the runs of
    all are pooled before aggregation. Pure and traceable
    (``jax.grad``/``jax.vmap`` it); one call simulates :func:`n_scenarios` rollouts.
    """
    spec = spec.check()
    config = config if not config.record else _no_record(config)
    batches = _batches(scenarios)

    def cost(theta):
        g = tunable.gains(theta)
        J = [run_costs(*_sim(controller, b, g, config), spec) for b in batches]
        return aggregate(jnp.concatenate(J), spec)

    return cost


def population_cost(
    controller: Controller, tunable: Tunable, scenarios: Scenario | list[Scenario], config: SimConfig, spec: CostSpec
):
    """Jitted ``(P, D) -> (P,)`` costs for the GA (``P x n`` rollouts per call)."""
    return PopulationCost(batch_cost(controller, tunable, scenarios, config, spec))


class PopulationCost:
    """``X (P, D) -> (P,)`` float64 costs of a scalar cost, vmapped and jitted; :meth:`compile`
    compiles a batch size ahead of time (so a tuner can keep compilation out of its wall time)."""

    def __init__(self, cost):
        self._f = jax.jit(jax.vmap(cost))
        self._compiled: dict = {}
        self._dtype = jnp.result_type(float)

    def compile(self, n: int, dim: int) -> None:
        """Compile the program for ``(n, dim)`` batches (once per shape)."""
        shape = (int(n), int(dim))
        if shape not in self._compiled:
            self._compiled[shape] = self._f.lower(jnp.zeros(shape, self._dtype)).compile()

    def __call__(self, X) -> np.ndarray:
        X = jnp.asarray(X, self._dtype)
        f = self._compiled.get(tuple(X.shape), self._f)
        return np.asarray(f(X), dtype=np.float64)


def _batches(scenarios) -> list:
    return [scenarios] if isinstance(scenarios, (Scenario, DynamicScenario)) else list(scenarios)


def _sim(controller, batch, gains, config):
    run = dynamic.simulate if isinstance(batch, DynamicScenario) else simulate
    res = jax.vmap(lambda sc: run(controller, sc._replace(gains=gains), config))(batch)
    return res.metrics, res.status


def n_scenarios(scenarios) -> int:
    """Rollouts per cost evaluation (runs in one batch or a list of batches)."""
    batches = _batches(scenarios)
    return sum(int(jax.tree_util.tree_leaves(b.pose0)[0].shape[0]) for b in batches)


def _no_record(config: SimConfig) -> SimConfig:
    import dataclasses

    return dataclasses.replace(config, record=False)
