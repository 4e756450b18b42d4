"""Tuning and worst-case search through the dynamic vehicle: the tuning cost's gradient over a batch of
ST and STD runs and the falsifier's objective gradient against central differences (float64), and the
search's ascent."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax import paths
from pfjax.falsification.dynamic import DynamicBox, falsify_dynamic, objective
from pfjax.models import single_track as st
from pfjax.sim import SimConfig, stack
from pfjax.sim.dynamic import DynamicScenario
from pfjax.sim.scenario import make_dynamic_scenario
from pfjax.tuning.cost import CostSpec, Tunable, batch_cost

SHORT = SimConfig(dt=0.01, horizon=2.0, record=False)


def _stanley():
    e, _ = C.resolve("stanley", "--controller")
    return e.controller, C.params_from_flat(e, C.flat_gains(e))


def _fd(f, z, h=1e-6):
    return np.array([(float(f(z.at[i].add(h))) - float(f(z.at[i].add(-h)))) / (2 * h) for i in range(z.size)])


def test_tuning_cost_gradient_through_the_st_model_matches_central_differences():
    """d (CVaR of IAE + effort) / d (k, k_soft) over 3 ST runs on the sine (frictions 0.3, 0.6, 1.0):
    float64, h = 1e-6, so 1e-5 relative is tight (truncation and rounding both below 1e-8)."""
    ctrl, gains = _stanley()
    e = paths.entry("sine")
    assert e.build is not None and e.start_pose is not None
    runs = [make_dynamic_scenario(e.build(), e.start_pose, gains, mu=mu) for mu in (0.3, 0.6, 1.0)]
    spec = CostSpec("iae", effort=0.1, aggregate="cvar", level=0.5)
    f = jax.jit(batch_cost(ctrl, Tunable(gains, ("k", "k_soft")), stack(runs), SHORT, spec))
    th = jnp.asarray([float(gains.k), float(gains.k_soft)])
    g = np.asarray(jax.grad(f)(th))
    assert np.all(np.abs(g) > 1e-8)
    np.testing.assert_allclose(g, _fd(f, th), rtol=1e-5, atol=1e-9)


@pytest.mark.slow
def test_tuning_cost_gradient_through_the_drift_model_matches_central_differences():
    """The same through the STD model (vehicle 2, 10 m/s, a 120 m circle, 2 ms steps for its wheel modes),
    in forward mode as the tuner takes a few gains' gradient (pfjax.numerics.autodiff). The derivative
    is small (about 2.8e-8 against a cost of 0.45), so the step is h = 1e-3: rounding (1e-16 x 0.45 / h)
    and truncation (measured 6e-6 relative at h = 1e-3, 2e-5 at 1e-4) stay below the 1e-4 relative
    tolerance, with no absolute slack (at h = 1e-6 rounding alone is 4e-3 relative)."""
    ctrl, gains = _stanley()
    path = paths.shapes.circle(radius=120.0, cy=120.0)
    sc = make_dynamic_scenario(path, (0.0, 1.0, 0.05), gains, params="vehicle2", mu=0.5, v=10.0, model="std")
    config = SimConfig(dt=0.002, horizon=0.4, record=False)
    cost = batch_cost(ctrl, Tunable(gains, ("k",)), stack([sc]), config, CostSpec("ise"))
    # one program: value and derivative
    jvp = jax.jit(lambda th: jax.jvp(cost, (th,), (jnp.ones_like(th),)))
    f = lambda th: jvp(th)[0]
    th = jnp.asarray([float(gains.k)])
    g = np.asarray([jvp(th)[1]])
    assert abs(g[0]) > 1e-8
    np.testing.assert_allclose(g, _fd(f, th, h=1e-3), rtol=1e-4, atol=0)


def _base() -> tuple:
    ctrl, gains = _stanley()
    e = paths.entry("sine")
    assert e.build is not None and e.start_pose is not None
    base = DynamicScenario(pose0=e.start_pose, vehicle=st.robot_params(), v_ref=1.0, path=e.build(), gains=gains)
    return ctrl, jax.tree_util.tree_map(lambda a: jnp.asarray(a, float), base)


def test_falsifier_objective_gradient_matches_central_differences():
    ctrl, base = _base()
    box = DynamicBox()
    f = jax.jit(lambda r: objective(r, ctrl, base, SHORT, box, "iae")[0])
    r = jnp.asarray([0.3, -0.4, 0.8])
    g = np.asarray(jax.grad(f)(r))
    assert np.all(np.abs(g) > 1e-8)
    np.testing.assert_allclose(g, _fd(f, r), rtol=1e-5, atol=1e-10)


@pytest.mark.slow
def test_falsifier_ascends_to_a_worse_run_in_the_box():
    """Six ascent steps from three starts: the worst objective found exceeds the worst start's, and
    every input stays in its box."""
    ctrl, base = _base()
    box = DynamicBox(mu=(0.3, 1.0), offset=(-0.3, 0.3), heading=(-0.4, 0.4))
    res = falsify_dynamic(ctrl, base, SHORT, box=box, n_starts=3, steps=6, lr=0.5, key=1)
    assert res.history.shape == (7, 3)
    assert np.max(res.objective) > np.max(res.objective0)
    for x, (lo, hi) in ((res.mu, box.mu), (res.offset, box.offset), (res.heading, box.heading)):
        assert np.all((x >= lo) & (x <= hi))
