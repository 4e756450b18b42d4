"""The MATLAB-style GA: operators against literal transcriptions, known optima, determinism, bounds."""

import re

import jax
import numpy as np
import pytest

from pfjax.tuning.ga import GAOptions, ga, ga_bits, rank_expectation, stochastic_uniform


def sphere(X):
    return (X**2).sum(axis=1)


def rastrigin(X):
    return 10.0 * X.shape[1] + (X**2 - 10.0 * np.cos(2 * np.pi * X)).sum(axis=1)


def _stochunif_loop(expectation, n_parents, u):
    """Literal transcription of MATLAB's selectionstochunif.m loop (offset u in step units)."""
    wheel = np.cumsum(expectation) / n_parents
    parents = np.zeros(n_parents, dtype=int)
    step = 1.0 / n_parents
    position = u * step
    lowest = 0
    for i in range(n_parents):
        for j in range(lowest, len(wheel)):
            if position < wheel[j]:
                parents[i] = j
                lowest = j
                break
        position += step
    return parents


def test_rank_scaling_matches_fitscalingrank():
    costs = np.array([3.0, np.inf, 1.0, 2.0, 1.0])
    e = rank_expectation(costs, 9)
    assert e.sum() == pytest.approx(9.0, rel=1e-14)
    # ranks (stable sort): idx2 -> 1, idx4 -> 2, idx3 -> 3, idx0 -> 4, idx1 (inf) -> 5
    ranks = np.array([4, 5, 1, 3, 2])
    ref = 1 / np.sqrt(ranks)
    np.testing.assert_allclose(e, 9 * ref / ref.sum(), rtol=1e-14)


@pytest.mark.parametrize("u", [0.0, 0.137, 0.5, 0.999])
def test_stochastic_uniform_matches_matlab_loop(u):
    rng = np.random.default_rng(0)
    costs = rng.normal(size=50)
    e = rank_expectation(costs, 89)
    np.testing.assert_array_equal(stochastic_uniform(e, 89, u), _stochunif_loop(e, 89, u))
    # each individual is picked floor or ceil of its expectation times
    counts = np.bincount(stochastic_uniform(e, 89, u), minlength=50)
    assert np.all(np.abs(counts - e) < 1.0 + 1e-9)


def test_sphere_3d_reaches_optimum():
    # Defaults = source's settings (P = 50, G = 100, E = 1, Pc = 0.8, Gaussian scale = shrink = 1).
    for seed in range(3):
        r = ga(sphere, [-5.0] * 3, [5.0] * 3, key=jax.random.PRNGKey(seed))
        assert np.max(np.abs(r.x)) < 0.05, r.x  # 1 % of the box half-width
        assert r.f == pytest.approx(sphere(r.x[None])[0])
        assert r.n_evaluations == 50 + 100 * 49


def test_rastrigin_2d_reaches_global_basin():
    # Rastrigin has local minima at every integer point; the global one at 0 has f = 0 and the
    # next best f ~ 1. Tolerance: inside the global basin (|x_i| < 0.1) with f < 0.5.
    for seed in range(5):
        r = ga(rastrigin, [-5.12] * 2, [5.12] * 2, key=jax.random.PRNGKey(seed))
        assert np.max(np.abs(r.x)) < 0.1 and r.f < 0.5, (seed, r.x, r.f)


def test_history_and_call_count():
    calls = []

    def cost(X):
        calls.append(X.shape)
        return sphere(X)

    opts = GAOptions(population_size=20, generations=15, elite_count=2)
    r = ga(cost, [-1, -1], [1, 1], key=jax.random.PRNGKey(3), options=opts)
    assert calls == [(20, 2)] + [(18, 2)] * 15  # one batched call per generation, elites not re-evaluated
    assert r.n_evaluations == 20 + 15 * 18
    assert r.history_best.shape == r.history_mean.shape == (16,)
    assert np.all(np.diff(r.history_best) <= 0)
    assert r.history_best[-1] == r.f == r.costs.min()
    assert r.population.shape == (20, 2) and r.costs.shape == (20,)


def test_determinism_by_key():
    a = ga(rastrigin, [-2, -2], [2, 2], key=jax.random.PRNGKey(7), options=GAOptions(generations=20))
    b = ga(rastrigin, [-2, -2], [2, 2], key=jax.random.PRNGKey(7), options=GAOptions(generations=20))
    c = ga(rastrigin, [-2, -2], [2, 2], key=jax.random.PRNGKey(8), options=GAOptions(generations=20))
    np.testing.assert_array_equal(a.population, b.population)
    np.testing.assert_array_equal(a.history_best, b.history_best)
    assert not np.array_equal(a.population, c.population)


def test_bounds_respected_and_active_bound_found():
    # Unconstrained optimum at (3, -3) lies outside the box: the solution is the corner (1, -0.5).
    lo, hi = np.array([-1.0, -0.5]), np.array([1.0, 0.5])
    seen = []

    def cost(X):
        seen.append(X.copy())
        return ((X - np.array([3.0, -3.0])) ** 2).sum(axis=1)

    r = ga(cost, lo, hi, key=jax.random.PRNGKey(0), options=GAOptions(generations=40))
    allx = np.concatenate(seen)
    assert np.all(allx >= lo) and np.all(allx <= hi)
    np.testing.assert_allclose(r.x, [1.0, -0.5], atol=1e-3)


def test_non_finite_costs_rank_worst():
    # NaN for x0 < 0 (a "failed rollout"); optimum of the finite part at x = (0.5, 0).
    def cost(X):
        f = (X[:, 0] - 0.5) ** 2 + X[:, 1] ** 2
        return np.where(X[:, 0] < 0, np.nan, f)

    r = ga(cost, [-1, -1], [1, 1], key=jax.random.PRNGKey(1), options=GAOptions(generations=40))
    assert np.isfinite(r.f) and r.x[0] >= 0
    np.testing.assert_allclose(r.x, [0.5, 0.0], atol=0.05)
    assert np.all(np.isfinite(r.history_mean))


def test_ga_bits_onemax_and_decoded_integer():
    r = ga_bits(lambda B: -B.sum(axis=1), 30, key=jax.random.PRNGKey(0), options=GAOptions(generations=60))
    assert r.f == -30 and r.x.dtype == bool and r.x.all()

    # Two 8-bit Gray-coded unsigned integers; minimise (a - 77)^2 + (b - 200)^2 (unique optimum,
    # cost 0). Gray code avoids the Hamming cliffs of plain binary, which trap a bit-flip GA.
    w = 2 ** np.arange(7, -1, -1)

    def gray(B):  # b_i = g_0 xor ... xor g_i
        return (np.cumsum(B, axis=1) % 2) @ w

    def decoded(B):
        return (gray(B[:, :8]) - 77.0) ** 2 + (gray(B[:, 8:]) - 200.0) ** 2

    for seed in range(3):
        assert ga_bits(decoded, 16, key=jax.random.PRNGKey(seed)).f == 0.0


def test_bad_options_raise():
    with pytest.raises(ValueError, match="elite_count"):
        ga(sphere, [0], [1], key=jax.random.PRNGKey(0), options=GAOptions(elite_count=50))
    with pytest.raises(ValueError, match="^lower: expected corners of one size with lower < upper"):
        ga(sphere, [1], [0], key=jax.random.PRNGKey(0))


def test_every_tuner_checks_its_box_and_key_alike():
    """The GA, the gradient tuner, the multi-start tuner and the check refuse the same boxes with the
    same one line (:func:`pfjax.errors.box`), and the random tuners a missing key."""
    import jax.numpy as jnp

    from pfjax.errors import InputError
    from pfjax.tuning.check import check_point
    from pfjax.tuning.gradient import gradient_tune
    from pfjax.tuning.multistart import MultistartOptions, multistart_tune

    f = lambda th: jnp.sum(th**2)
    k = jax.random.PRNGKey(0)
    tuners = {
        "ga": lambda lo, hi, key=k: ga(lambda X: np.sum(X**2, axis=1), lo, hi, key=key),
        "gradient": lambda lo, hi, key=k: gradient_tune(f, lo, hi, key=key, steps=1),
        "multistart": lambda lo, hi, key=k: multistart_tune(f, lo, hi, key=key),
        "check": lambda lo, hi, key=k: check_point(f, [0.5], lo, hi),
    }
    for name, tune in tuners.items():
        for lo, hi, msg in (
            ([1.0], [0.0], "lower: expected corners of one size with lower < upper"),
            ([0.0, 0.0], [1.0], "lower: expected corners of one size"),
            ([0.0], [0.0], "lower: expected corners of one size with lower < upper"),
            ([0.0], [np.inf], "upper: expected finite numbers, got [inf]"),
            ([], [], "lower: expected finite numbers"),
            ([0.0], "x", "upper: expected an array of numbers, got a str"),
        ):
            with pytest.raises(InputError, match=f"^{re.escape(msg)}"):
                tune(lo, hi)
        if name != "check":
            with pytest.raises(InputError, match="^key: required"):
                tune([0.0], [1.0], key=None)
    with pytest.raises(InputError, match="^options: expected a MultistartOptions, got dict"):
        multistart_tune(f, [0.0], [1.0], key=k, options={"n_starts": 2})
    assert isinstance(MultistartOptions(), MultistartOptions)


def test_ga_tune_evaluates_the_children_on_the_population_program_when_cheap():
    """With ``rollout_steps`` small, each generation's ``P - E`` children are padded to the
    population's ``P`` points (copies of the first child, costs dropped), so one program is
    compiled instead of two, to the same result; beyond the padding budget, two programs again."""
    import jax.numpy as jnp

    from pfjax.tuning.cost import PopulationCost
    from pfjax.tuning.gradient import PAD_FORWARD_PASSES, ga_tune

    cost = lambda th: jnp.sum((th - 0.3) ** 2) + 0.1 * jnp.sin(5.0 * th[0])
    o = GAOptions(population_size=12, elite_count=2, generations=5)
    f_own = PopulationCost(cost)
    own = ga_tune(f_own, [0.0, 0.0], [1.0, 1.0], key=jax.random.PRNGKey(3), options=o)
    assert sorted(f_own._compiled) == [(10, 2), (12, 2)]
    f_shared = PopulationCost(cost)
    shared = ga_tune(f_shared, [0.0, 0.0], [1.0, 1.0], key=jax.random.PRNGKey(3), options=o, rollout_steps=1)
    assert sorted(f_shared._compiled) == [(12, 2)] and f_shared._f._cache_size() == 0  # nothing compiled on call
    np.testing.assert_array_equal(shared.theta, own.theta)
    np.testing.assert_array_equal(shared.history, own.history)
    assert shared.n_rollouts == own.n_rollouts == 12 + 5 * 10  # the padded evaluations are not counted
    # E = 2 padded evaluations per generation, 5 generations: over the budget by one rollout-step
    f_over = PopulationCost(cost)
    ga_tune(
        f_over, [0.0, 0.0], [1.0, 1.0], key=jax.random.PRNGKey(3), options=o, rollout_steps=PAD_FORWARD_PASSES // 10 + 1
    )
    assert sorted(f_over._compiled) == [(10, 2), (12, 2)]
    # a cost function that is not a PopulationCost compiles nothing ahead: it gets the children as they are
    sizes = []
    plain = ga_tune(
        lambda X: (sizes.append(len(X)), np.asarray(f_own(X)))[1],
        [0.0, 0.0],
        [1.0, 1.0],
        key=jax.random.PRNGKey(3),
        options=o,
        rollout_steps=1,
    )
    assert sizes == [12] + [10] * 5
    np.testing.assert_array_equal(plain.theta, own.theta)
