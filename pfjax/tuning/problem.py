"""Tuning problems: controller + scenario set + cost -> one call to the GA or to gradient descent.

A :class:`Problem` bundles what both optimisers need; :func:`tune` runs either on it and returns
a :class:`~pfjax.tuning.gradient.TuneResult` (same fields for both, so they compare directly).

Scenario sets (``scenario`` argument):

* ``"paper-line"``, ``"paper-parabola"``, ``"paper-sine"``: the source's test (docs/reproductions/path-following.md §6, constant
  slip 5°, one rollout per cost evaluation);
* ``"paper-all"``: the three tests pooled (3 rollouts per evaluation);
* a study TOML path (``CONFIG``): ``n_runs`` runs per path sampled by
  :func:`pfjax.montecarlo.sampling.sample_runs` with the study's seed (a training set; held-out
  sets use other run indices), the study's simulation settings.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np

from pfjax import controllers as C
from pfjax.sim.simulate import SimConfig
from pfjax.tuning.cost import CostSpec, Tunable, batch_cost, n_scenarios, population_cost
from pfjax.tuning.ga import GAOptions
from pfjax.tuning.gradient import TuneResult, ga_tune, gradient_tune


def scenario_sets() -> dict[str, tuple[str, ...]]:
    """Named scenario sets (one run per path, from its start pose with the source's 5 deg slip):
    ``paper-<test>`` and ``paper-all`` for the source's tests, and every fixed path
    (:func:`pfjax.paths.fixed_paths`) by its own name."""
    from pfjax import paths

    tests = paths.source_tests()
    return {**{f"paper-{t}": (t,) for t in tests}, "paper-all": tests, **{n: (n,) for n in paths.fixed_paths()}}


class Problem(NamedTuple):
    controller: Any  # pfjax Controller
    tunable: Tunable
    scenarios: list  # batched Scenarios, one per path shape
    config: SimConfig
    cost: CostSpec
    lower: np.ndarray
    upper: np.ndarray

    @property
    def n_per_eval(self) -> int:
        return n_scenarios(self.scenarios)


def make_problem(
    controller: str,
    scenario: str,
    *,
    cost: CostSpec = CostSpec(),
    config: SimConfig | None = None,
    n_runs: int = 16,
    run_offset: int = 0,
    base_gains=None,
    box=None,
) -> Problem:
    """Build a problem (``controller``: a :data:`pfjax.controllers.REGISTRY` name).

    Args:
        controller: registry name with a tuning box (``pi``, ``state_feedback``, ``integral``, ``stanley``, ...).
        scenario: a paper set name or a study TOML path (module docstring).
        cost: what is minimised.
        config: simulation settings (``record`` is forced off); default ``SimConfig()`` for paper
            sets, the study's for a TOML.
        n_runs: runs per path sampled from a study TOML; ``run_offset``: first run index.
        base_gains: gains pytree for the untuned fields (default: the registry's defaults).
        box: ``(fields, lower, upper)`` overriding the registry entry's ``box``.
    """
    from pfjax import errors
    from pfjax.sim.simulate import stack

    tunable = [n for n, e in C.REGISTRY.items() if e.box is not None]
    if controller not in tunable:
        raise errors.InputError(f"controller: value {controller!r}, expected one of {', '.join(tunable)}")
    sets = scenario_sets()
    if scenario not in sets and not (Path(scenario).suffix == ".toml" and Path(scenario).is_file()):
        raise errors.InputError(
            f"scenario: value {scenario!r}, expected one of {', '.join(sets)} or an existing study .toml"
        )
    errors.integer("n_runs", n_runs, low=1, high=1_000_000)
    errors.integer("run_offset", run_offset, low=0, high=errors.MAX_SEED - n_runs)
    ctrl, factory = C.REGISTRY[controller][:2]
    box = box or C.REGISTRY[controller].box
    if box is None:
        raise errors.InputError(
            f"controller: {controller!r} has no tuning box; give box=(fields, lower, upper)", "controller"
        )
    fields, lo, hi = box
    base = factory() if base_gains is None else base_gains
    tun = Tunable(base, tuple(fields))
    if scenario in sets:
        from pfjax.sim.scenario import paper_scenario

        batches = [stack([paper_scenario(t, base)]) for t in sets[scenario]]
        cfg = config or SimConfig(record=False)
    else:
        from pfjax.montecarlo.config import load_study
        from pfjax.montecarlo.runner import sim_config
        from pfjax.montecarlo.sampling import sample_runs

        try:
            spec, _ = load_study(Path(scenario))
        except errors.InputError as e:
            raise errors.InputError(f"scenario: {e}", "scenario") from None
        runs = np.arange(run_offset, run_offset + n_runs)
        batches = []
        for i in range(len(spec.paths)):
            sc = sample_runs(spec, i, runs).scenarios
            batches.append(
                sc._replace(gains=jax.tree_util.tree_map(lambda g: np.broadcast_to(g, (n_runs,) + np.shape(g)), base))
            )
        cfg = config or sim_config(spec)
    import dataclasses

    cfg = dataclasses.replace(cfg, record=False)
    return Problem(ctrl, tun, batches, cfg, cost.check(), np.asarray(lo, float), np.asarray(hi, float))


def evaluate(problem: Problem, theta) -> float:
    """The problem's cost at ``theta`` (one evaluation, ``n_per_eval`` rollouts)."""
    import jax.numpy as jnp

    cost_functions(problem)
    return float(_COSTS[id(problem)][3](jnp.asarray(theta, jnp.result_type(float))))


_COSTS: dict = {}


def cost_functions(problem: Problem):
    """(scalar cost, population cost) of a problem, built once per Problem object so repeated
    tuning runs (seeds) reuse the compiled functions."""
    entry = _COSTS.get(id(problem))
    if entry is None or entry[0] is not problem:
        args = (problem.controller, problem.tunable, problem.scenarios, problem.config, problem.cost)
        f = batch_cost(*args)
        entry = (problem, f, population_cost(*args), jax.jit(f))
        _COSTS[id(problem)] = entry
    return entry[1], entry[2]


def tune(
    problem: Problem,
    method: str,
    *,
    key,
    ga_options: GAOptions = GAOptions(),
    steps: int = 100,
    n_starts: int = 1,
    learning_rate: float = 0.05,
    theta0=None,
    progress: bool = False,
) -> TuneResult:
    """Run ``method`` (``"ga"`` or ``"gradient"``) on ``problem``; the gradient starts at ``theta0``
    or uniformly in the box from ``key``. Refused before any work (:class:`~pfjax.errors.InputError`
    naming the argument) for an unknown method or settings, or batches beyond the memory budget
    (:mod:`pfjax.resources`: the GA simulates a whole population at once, the gradient every start
    with one tangent per tuned gain)."""
    from pfjax import errors, resources
    from pfjax.tuning.ga import _validate

    if method not in ("ga", "gradient"):
        raise errors.InputError(f"method: value {method!r}, expected ga or gradient")
    _validate(ga_options)  # every setting is checked, whichever method uses it
    errors.integer("steps", steps, low=1, high=1_000_000)
    errors.integer("n_starts", n_starts, low=1, high=1_000_000)
    errors.number("learning_rate", learning_rate, positive=True)
    per_run = resources.run_bytes(problem.config.n_steps)
    if method == "ga":
        population = _validate(ga_options)[0]
        resources.check_memory(
            "population_size",
            2 * population * problem.n_per_eval * per_run,
            f"a GA population of {population} x {problem.n_per_eval} runs",
        )
    else:
        n = errors.integer("n_starts", n_starts, low=1, high=1_000_000)
        resources.check_memory(
            "n_starts",
            2 * n * problem.n_per_eval * per_run * (1 + problem.lower.size),
            f"{n} starts x {problem.n_per_eval} runs with {problem.lower.size} tangents",
        )
    f_scalar, f_pop = cost_functions(problem)
    if method == "ga":
        f = f_pop
        return ga_tune(
            f,
            problem.lower,
            problem.upper,
            key=key,
            options=ga_options,
            n_per_eval=problem.n_per_eval,
            progress=progress,
        )
    if method == "gradient":
        return gradient_tune(
            f_scalar,
            problem.lower,
            problem.upper,
            theta0=theta0,
            key=key,
            steps=steps,
            n_starts=n_starts,
            n_per_eval=problem.n_per_eval,
            learning_rate=learning_rate,
            progress=progress,
        )
    raise AssertionError(method)
