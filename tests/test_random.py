"""pfjax.numerics.random.step_normals: standard normal in distribution (Kolmogorov-Smirnov against
scipy.stats.norm), independent between components, steps and keys, deterministic, in float32 and
float64. The draws are a fixed function of the key, so the p-values are fixed numbers, not flaky."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.special
from scipy import stats

from pfjax.numerics.random import step_normals

N = 40_000


def _draws(dtype, n=4, key=jax.random.PRNGKey(7)):
    return np.asarray(jax.jit(jax.vmap(lambda k: step_normals(key, k, n, dtype)))(jnp.arange(N)))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_draws_are_standard_normal_and_independent(dtype):
    z = _draws(dtype)
    assert z.dtype == dtype and z.shape == (N, 4) and np.all(np.isfinite(z))
    # each component and all together: N(0, 1) by KS (p > 1e-3; a scale 3 % off fails at this N)
    for col in [*z.T, z.ravel()]:
        assert stats.kstest(col, "norm").pvalue > 1e-3
    # components, and consecutive steps, uncorrelated (|r| < 4 / sqrt(N) = 0.02)
    r = np.corrcoef(np.concatenate([z[:-1], z[1:]], axis=1).T)
    assert np.max(np.abs(r - np.eye(8))) < 4 / np.sqrt(N)
    # tails reach where they should: P(|z| > 3) = 0.0027
    assert 0.002 < np.mean(np.abs(z) > 3) < 0.0034
    assert stats.kstest(z.ravel() * 1.03, "norm").pvalue < 1e-3  # the test can fail


def test_deterministic_per_key_and_step_and_independent_across_keys():
    a, b = _draws(np.float32), _draws(np.float32)
    np.testing.assert_array_equal(a, b)
    c = _draws(np.float32, key=jax.random.PRNGKey(8))
    assert abs(np.corrcoef(a.ravel(), c.ravel())[0, 1]) < 4 / np.sqrt(a.size)
    # a typed key gives the draws of its raw key data
    np.testing.assert_array_equal(np.asarray(step_normals(jax.random.key(7), 5, 4)), a[5])
    with pytest.raises(ValueError, match="^dtype: "):
        step_normals(jax.random.PRNGKey(0), 0, 2, np.float16)


def test_unrolled_threefry_is_jax_fold_in_bit_for_bit():
    """pfjax's unrolled Threefry-2x32 gives exactly ``jax.random.fold_in``'s bits (the hash JAX
    itself runs as a rolled loop on CPU), for raw and typed keys, any counter, under vmap and jit;
    and the draws are the inverse normal distribution of those bits."""
    from pfjax.numerics.random import _uniform_open, fold_in

    keys = jax.random.split(jax.random.PRNGKey(3), 257)
    data = np.random.default_rng(0).integers(0, 2**32, 257, dtype=np.uint64).astype(np.uint32)
    data[:4] = [0, 1, 2**31, 2**32 - 1]
    want = np.asarray(jax.vmap(jax.random.fold_in)(keys, data))
    np.testing.assert_array_equal(np.asarray(jax.jit(jax.vmap(fold_in))(keys, data)), want)
    np.testing.assert_array_equal(
        np.asarray(fold_in(jax.random.key(11), 5)),
        np.asarray(jax.random.key_data(jax.random.fold_in(jax.random.key(11), 5))),
    )
    # step k's words are fold_in(key, m k + j): four float32 draws take m = 2 hashes
    key, k = jax.random.PRNGKey(7), 9
    w = [np.asarray(jax.random.fold_in(key, 2 * k + j)) for j in range(2)]
    u = np.asarray([_uniform_open([jnp.uint32(x)], np.float32) for x in (w[0][0], w[0][1], w[1][0], w[1][1])])
    z = np.sqrt(2.0) * scipy.special.erfinv(2.0 * u.astype(np.float64) - 1.0)
    np.testing.assert_allclose(np.asarray(step_normals(key, k, 4)), z, rtol=1e-5, atol=1e-5)  # float32 erf_inv


def test_seed_key_is_the_64_bit_prng_key_in_any_precision():
    """``seed_key(s)`` is ``PRNGKey(s)`` as built with 64-bit integers, whatever ``jax_enable_x64``:
    below 2**32 the keys of both modes; above, distinct keys for ``s`` and ``s + 2**32`` (a
    float32 study's seeds 1 and 2**32 + 1 drew the same runs)."""
    from pfjax.numerics.random import seed_key

    seeds = [0, 1, 2**31, 2**32 - 1, 2**32 + 1, 12345678901234, 2**63 - 1]
    with jax.enable_x64(False):
        for s in seeds[:4]:
            assert np.asarray(seed_key(s)).tolist() == np.asarray(jax.random.PRNGKey(s)).tolist()
        assert np.asarray(seed_key(1)).tolist() != np.asarray(seed_key(2**32 + 1)).tolist()
        low = [np.asarray(seed_key(s)).tolist() for s in seeds]
    with jax.enable_x64(True):
        for s, k in zip(seeds, low):
            assert k == np.asarray(jax.random.PRNGKey(s)).tolist(), s


def test_a_float32_study_draws_other_runs_for_a_seed_2_to_the_32_apart():
    from pfjax.montecarlo.chunk_runs import precision, sample_aligned
    from pfjax.montecarlo.config import load_study

    drawn = []
    for seed in (1, 2**32 + 1):
        study = Path(__file__).resolve().parents[1] / "studies" / "robustness_default.toml"
        spec, _ = load_study(study, [f"seed={seed}", "n_runs=8"])
        with precision(spec):
            drawn.append(np.asarray(sample_aligned(spec, 0, np.arange(8)).columns["beta_r_deg"]))
    assert not np.array_equal(*drawn)
