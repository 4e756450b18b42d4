"""Measurement noise, the steering rate limit and the success criterion in the simulator."""

import math

import jax
import jax.numpy as jnp
import numpy as np

from pfjax import controllers as C
from pfjax.sim import SensorNoise, SimConfig, simulate_batch, stack
from pfjax.sim.scenario import paper_scenario

K = np.array(C.PAPER_K)
CFG = SimConfig(horizon=20.0)


def _noise(sd, st, seed):
    return SensorNoise(jnp.asarray(sd, float), jnp.asarray(st, float), jax.random.PRNGKey(seed))


def _run(scs, cfg=CFG):
    return jax.device_get(simulate_batch(stack(scs), controller=C.state_feedback, config=cfg))


def test_noise_enters_the_controller_with_the_stated_statistics():
    """With noise, the command minus K x_true is K n: its sample std over 4000 steps is
    sqrt(K1^2 sd^2 + K2^2 st^2) within 5 % (the estimate's relative std is ~1/sqrt(2*4000) = 1.1 %)
    and its mean ~0. Zero sigma equals no noise bit for bit; same key, same run; other key, other run."""
    g = C.state_feedback_params()
    sd, st = 0.01, math.radians(1.0)
    base = paper_scenario("line", g)
    scs = [
        base,
        base._replace(noise=_noise(0.0, 0.0, 1)),
        base._replace(noise=_noise(sd, st, 1)),
        base._replace(noise=_noise(sd, st, 1)),
        base._replace(noise=_noise(sd, st, 2)),
    ]
    # None and a noise pytree are different structures: run them as two batches.
    r0 = _run(scs[:1])
    r = _run(scs[1:])
    np.testing.assert_array_equal(r.trajectory.x[0], r0.trajectory.x[0])
    np.testing.assert_array_equal(r.trajectory.x[1], r.trajectory.x[2])
    assert np.abs(r.trajectory.x[1] - r.trajectory.x[3]).max() > 1e-6
    tr = jax.tree_util.tree_map(lambda a: a[1], r.trajectory)
    resid = (tr.delta_cmd - (K[0] * tr.d + K[1] * tr.theta_e))[:-1]
    expected = math.sqrt((K[0] * sd) ** 2 + (K[1] * st) ** 2)
    assert abs(resid.std() / expected - 1) < 0.05
    assert abs(resid.mean()) < 4 * expected / math.sqrt(resid.size)


def test_rate_limit_bounds_every_step_and_infinity_is_a_no_op():
    """|delta_k - delta_{k-1}| <= rate * dt at every step, starting from a straight wheel; the
    command saturates at the start of the line test, so the steering ramps at exactly the limit."""
    g = C.state_feedback_params()
    base = paper_scenario("line", g)
    rate = math.radians(60.0)
    limited = base._replace(params=base.params._replace(delta_rate_max=jnp.asarray(rate)))
    r = _run([base, limited])
    delta = r.trajectory.delta[1][:-1]
    steps = np.abs(np.diff(np.concatenate([[0.0], delta])))
    assert steps.max() <= rate * CFG.dt * (1 + 1e-12)
    np.testing.assert_allclose(steps[:5], rate * CFG.dt, rtol=1e-12)
    # inf: identical to the unlimited command path (the default SlipParams)
    unlimited = base._replace(params=base.params._replace(delta_rate_max=jnp.asarray(np.inf)))
    r2 = _run([unlimited, limited])
    np.testing.assert_array_equal(r2.trajectory.x[0], r.trajectory.x[0])
    assert int(r.status[1]) == 0 and float(r.metrics.late_max_abs_d[1]) < 0.01


def test_success_flag():
    """success = no failure and |d| <= success_band from success_from on, recomputed from the trajectory."""
    g_ok, g_bad = C.state_feedback_params(), C.state_feedback_params((-0.05, -0.05))
    cfg = SimConfig(horizon=10.0, success_from=6.0, success_band=0.02)
    r = _run([paper_scenario("line", g_ok), paper_scenario("line", g_bad)], cfg)
    for i in range(2):
        t, d = r.trajectory.t[i], r.trajectory.d[i]
        late = np.abs(d[t >= 6.0 - 1e-9]).max()
        np.testing.assert_allclose(r.metrics.late_max_abs_d[i], late, rtol=1e-12)
        assert bool(r.metrics.success[i]) == (int(r.status[i]) == 0 and late <= 0.02)
    assert bool(r.metrics.success[0]) and not bool(r.metrics.success[1])
