"""A genetic algorithm faithful to MATLAB's ``ga`` as the source configured it (docs/reproductions/path-following.md §5, Table 2).

Two entry points share one generation step:

* :func:`ga` — real-valued genomes in a box ``lower <= x <= upper`` (``PopulationType
  'doubleVector'``);
* :func:`ga_bits` — bit strings (``PopulationType 'bitstring'``).

The cost is a *batched* callable: ``cost_batch(X) -> f`` with ``X`` of shape ``(P, D)`` and ``f``
of shape ``(P,)``, minimised. Each generation makes exactly one call (on the new children), so a
jitted, vmapped simulator evaluates a whole generation at once. A non-finite cost (NaN, ±inf: a
failed rollout) ranks worst.

One generation (MATLAB ``stepGA``), population size ``P``, elite count ``E``::

    n_xover  = round(crossover_fraction * (P - E))       # crossover children
    n_mutate = P - E - n_xover                            # mutation children
    n_par    = 2 n_xover + n_mutate                       # parents selected

1. **Fitness scaling** (``fitscalingrank``): sort the costs; the individual of rank ``r``
   (1 = best) gets expectation ``e_r ∝ 1/sqrt(r)``, scaled so that ``sum_r e_r = n_par``. Ties
   are broken by position (a stable sort), as MATLAB's ``sort`` does.
2. **Selection** (``selectionstochunif``): a wheel of cumulative expectations ``W_j / n_par``;
   one uniform offset ``u ~ U[0, 1/n_par)`` and ``n_par`` equally spaced pointers
   ``u + i / n_par``; pointer ``i`` picks the first ``j`` with ``u + i/n_par < W_j / n_par``.
   The parents are then shuffled (``stepGA`` applies ``randperm``).
3. **Elite**: the ``E`` best individuals pass unchanged, with their costs (not re-evaluated).
4. **Crossover** (``crossoverscattered``): child ``k`` takes parents ``2k, 2k+1`` and each gene
   from the first where a fair coin is 1, else from the second.
5. **Mutation** — real: ``mutationgaussian``, child = parent + ``σ_g ⊙ N(0, I)`` with
   ``σ_g = mutation_scale · (1 − mutation_shrink · g / G) · (upper − lower)`` at generation
   ``g = 1..G`` (what ``mutationgaussian.m`` computes: linear in ``g``, reaching 0 at the last
   generation when ``shrink = 1``); bits: ``mutationuniform``, each bit of the parent flipped
   with probability ``mutation_rate``.
6. The children (``P − E`` rows) are evaluated in one ``cost_batch`` call.

The initial population is uniform in the box (``gacreationuniform`` with the initial range
equal to the bounds) or uniform random bits, and is evaluated in one call. The run stops after
``generations`` generations, so ``n_evaluations = P + G (P − E)``.

Where this departs from MATLAB, and why:

* **Bounds with Gaussian mutation.** MATLAB does not combine ``mutationgaussian`` with bounds
  (it switches to ``mutationadaptfeasible``, or warns in recent releases). The source sets
  Gaussian mutation (Table 2), so pfjax keeps it and *clips* each mutated gene to
  ``[lower, upper]`` (Euclidean projection onto the box). Crossover children of feasible parents
  are feasible, so no other repair is needed; every returned point satisfies the bounds.
* **Mutation scale.** MATLAB scales by ``PopInitRange``; here the initial range *is* the box,
  so the scale is ``upper − lower`` per coordinate.
* **Shrink formula.** The documentation writes ``σ_k = σ_{k−1}(1 − shrink·k/G)``; the shipped
  ``mutationgaussian.m`` uses the linear ``σ_k = σ_0 (1 − shrink·k/G)``. pfjax follows the code
  (the linear rule).
* **Stopping.** Only the generation limit. MATLAB also stops on stall (``StallGenLimit`` 50 with
  ``TolFun`` 1e-6), a time limit or a fitness limit; none is implemented, so pfjax may run
  longer than MATLAB would (never shorter).
* **No hybrid function, no constraint handling beyond bounds, no vectorised/serial switch**
  (the cost is always batched).
* **Random numbers** come from a JAX key (``fold_in(key, generation)`` then one split per
  operator), so the same key gives the same result on every machine; the streams differ from
  MATLAB's Mersenne twister, so runs are not bit-identical to MATLAB's (and the draws depend on
  whether JAX runs in float64 (``jax_enable_x64``) or float32).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import numpy as np

from pfjax import errors, resources


class GAOptions(NamedTuple):
    """Settings; defaults are the source's MATLAB ``ga`` settings (docs/reproductions/path-following.md §5, Table 2:
    population, elite count, crossover fraction, mutation scale and shrink) and, where Table 2 gives
    none, assumed: 100 generations, and the bit-flip rate of MATLAB's ``mutationuniform``."""

    population_size: int = 50
    generations: int = 100
    elite_count: int = 1
    crossover_fraction: float = 0.8
    mutation_scale: float = 1.0  # gaussian mutation (real-valued ga), fraction of (upper - lower)
    mutation_shrink: float = 1.0  # sigma_g = scale (1 - shrink g / G) (upper - lower)
    mutation_rate: float = 0.01  # bit-flip probability (ga_bits; MATLAB mutationuniform default)


class GAResult(NamedTuple):
    """The outcome of :func:`ga` / :func:`ga_bits`."""

    x: np.ndarray  # best point found, (D,) float (ga) or (n_bits,) bool (ga_bits)
    f: float  # its cost
    history_best: np.ndarray  # (generations+1,) best cost so far after each generation (0 = initial population)
    history_mean: np.ndarray  # (generations+1,) mean finite cost of each population
    n_evaluations: int  # cost evaluations made (= simulated rollouts when each cost is one rollout)
    population: np.ndarray  # final population, (P, D)
    costs: np.ndarray  # its costs, (P,)


#: Largest population and number of generations the GA accepts (:mod:`pfjax.resources`).
MAX_POPULATION, MAX_GENERATIONS = resources.MAX_POPULATION, resources.MAX_GENERATIONS


def validate_options(options: GAOptions) -> tuple[int, int, int]:
    """``(population, elites, generations)``; :class:`~pfjax.errors.InputError` naming a bad option."""
    from pfjax import errors

    P = errors.integer("population_size", options.population_size, low=2, high=MAX_POPULATION)
    E = errors.integer("elite_count", options.elite_count, low=0, high=P - 1)
    G = errors.integer("generations", options.generations, low=0, high=MAX_GENERATIONS)
    errors.number("crossover_fraction", options.crossover_fraction, low=0.0, high=1.0)
    errors.number("mutation_rate", options.mutation_rate, low=0.0, high=1.0)
    errors.number("mutation_scale", options.mutation_scale, nonnegative=True)
    errors.number("mutation_shrink", options.mutation_shrink, low=0.0, high=1.0)
    return P, E, G


def _evaluate(cost_batch, X: np.ndarray) -> np.ndarray:
    f = np.asarray(cost_batch(X), dtype=np.float64).reshape(-1)
    if f.shape[0] != X.shape[0]:
        raise ValueError(f"cost_batch returned {f.shape[0]} costs for {X.shape[0]} points")
    return np.where(np.isfinite(f), f, np.inf)  # non-finite ranks worst


def rank_expectation(costs: np.ndarray, n_parents: int) -> np.ndarray:
    """MATLAB ``fitscalingrank``: expectation ``∝ 1/sqrt(rank)``, summing to ``n_parents``."""
    order = np.argsort(costs, kind="stable")
    e = np.empty(len(costs))
    e[order] = 1.0 / np.sqrt(np.arange(1, len(costs) + 1))
    return n_parents * e / e.sum()


def stochastic_uniform(expectation: np.ndarray, n_parents: int, u: float) -> np.ndarray:
    """MATLAB ``selectionstochunif`` with offset ``u ∈ [0, 1)`` (in units of one step).

    Returns the indices of ``n_parents`` parents (each individual appears about
    ``expectation_j`` times).
    """
    wheel = np.cumsum(expectation) / n_parents
    pointers = (u + np.arange(n_parents)) / n_parents
    return np.minimum(np.searchsorted(wheel, pointers, side="right"), len(expectation) - 1)


def _uniform(key, shape) -> np.ndarray:
    return np.asarray(jax.random.uniform(key, shape), dtype=np.float64)


def _generation(pop, costs, g, G, key, options, cost_batch, mutate):
    """One MATLAB ``stepGA`` generation; returns the new population and its costs."""
    P, E = pop.shape[0], int(options.elite_count)
    n_x = int(round(options.crossover_fraction * (P - E)))
    n_m = P - E - n_x
    n_par = 2 * n_x + n_m
    k_sel, k_perm, k_x, k_m = jax.random.split(key, 4)

    expectation = rank_expectation(costs, n_par)
    parents = stochastic_uniform(expectation, n_par, float(_uniform(k_sel, ())))
    parents = parents[np.asarray(jax.random.permutation(k_perm, n_par))]

    elite = np.argsort(costs, kind="stable")[:E]
    p1, p2 = pop[parents[0 : 2 * n_x : 2]], pop[parents[1 : 2 * n_x : 2]]
    coin = _uniform(k_x, p1.shape) < 0.5
    xover = np.where(coin, p1, p2)
    mutants = mutate(pop[parents[2 * n_x :]], g, G, k_m)

    kids = np.concatenate([xover, mutants], axis=0)
    kid_costs = _evaluate(cost_batch, kids) if len(kids) else np.zeros(0)
    return np.concatenate([pop[elite], kids], axis=0), np.concatenate([costs[elite], kid_costs])


def _run(cost_batch, pop0, mutate, key, options, progress, desc) -> GAResult:
    P, E, G = validate_options(options)
    costs = _evaluate(cost_batch, pop0)
    pop = pop0
    n_eval = P
    best_i = int(np.argmin(costs))
    best_x, best_f = pop[best_i].copy(), float(costs[best_i])
    hist_best, hist_mean = [best_f], [_finite_mean(costs)]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=G, desc=desc, leave=False)
    for g in range(1, G + 1):
        pop, costs = _generation(pop, costs, g, G, jax.random.fold_in(key, g), options, cost_batch, mutate)
        n_eval += P - E
        i = int(np.argmin(costs))
        if costs[i] < best_f:
            best_x, best_f = pop[i].copy(), float(costs[i])
        hist_best.append(best_f)
        hist_mean.append(_finite_mean(costs))
        if bar is not None:
            bar.update(1)
            bar.set_postfix(best=f"{best_f:.5g}")
    if bar is not None:
        bar.close()
    return GAResult(best_x, best_f, np.asarray(hist_best), np.asarray(hist_mean), n_eval, pop, costs)


def _finite_mean(costs: np.ndarray) -> float:
    ok = np.isfinite(costs)
    return float(costs[ok].mean()) if ok.any() else float("nan")


def ga(
    cost_batch: Callable[[np.ndarray], np.ndarray],
    lower,
    upper,
    *,
    key,
    options: GAOptions = GAOptions(),
    progress: bool = False,
) -> GAResult:
    """Minimise ``cost_batch`` over the box ``[lower, upper]`` with MATLAB-style ``ga``.

    Args:
        cost_batch: ``(P, D) float64 -> (P,)`` costs, minimised; non-finite ranks worst.
        lower: ``(D,)`` finite lower bounds, ``lower < upper``.
        upper: ``(D,)`` finite upper bounds.
        key: JAX PRNG key (same key, same result).
        options: :class:`GAOptions` (defaults: the source's Table 2).
        progress: show a tqdm bar over the generations.

    Returns:
        :class:`GAResult`; ``x`` is the best point ever evaluated (the elite keeps it in the
        population), inside the bounds.
    """
    lo, hi = errors.box(lower, upper)
    if key is None:
        raise errors.InputError(
            "key: required, a JAX PRNG key (the first population, selection, crossover, mutation)", "key"
        )
    P, _, _ = validate_options(options)
    span = hi - lo
    k0, kr = jax.random.split(key)
    pop0 = lo + span * _uniform(k0, (P, lo.size))

    def mutate(parents, g, G, k):
        sigma = options.mutation_scale * (1.0 - options.mutation_shrink * g / max(G, 1)) * span
        z = np.asarray(jax.random.normal(k, parents.shape), dtype=np.float64)
        return np.clip(parents + sigma * z, lo, hi)

    return _run(cost_batch, pop0, mutate, kr, options, progress, "ga")


def ga_bits(
    cost_batch: Callable[[np.ndarray], np.ndarray],
    n_bits: int,
    *,
    key,
    options: GAOptions = GAOptions(),
    progress: bool = False,
) -> GAResult:
    """Minimise ``cost_batch`` over bit strings of length ``n_bits`` (MATLAB ``'bitstring'``).

    Same selection, elitism and scattered crossover as :func:`ga`; mutation flips each bit with
    probability ``options.mutation_rate`` (``mutationuniform``). ``cost_batch`` receives a
    ``(P, n_bits)`` bool array.
    """
    n_bits = int(n_bits)
    if n_bits < 1:
        raise ValueError(f"n_bits: value {n_bits}, expected >= 1")
    P, _, _ = validate_options(options)
    k0, kr = jax.random.split(key)
    pop0 = _uniform(k0, (P, n_bits)) < 0.5

    def mutate(parents, g, G, k):
        return np.logical_xor(parents, _uniform(k, parents.shape) < options.mutation_rate)

    return _run(cost_batch, pop0, mutate, kr, options, progress, "ga_bits")
