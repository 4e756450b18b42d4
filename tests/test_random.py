"""pfjax.numerics.random.step_normals: standard normal in distribution (Kolmogorov-Smirnov against
scipy.stats.norm), independent between components, steps and keys, deterministic, in float32 and
float64. The draws are a fixed function of the key, so the p-values are fixed numbers, not flaky."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
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
