"""The dynamic vehicle (:mod:`pfjax.sim.dynamic`): every registered controller runs on it; steady
cornering on a circle against geometry (the rear axle's slip is minus the heading error, the yaw rate
is the rear axle's speed over its radius); at high friction it follows the kinematic model without
slip; the speed loop holds the reference; failures are statuses; gradients match finite differences."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax import paths
from pfjax.errors import InputError
from pfjax.models import single_track as st
from pfjax.sim import SimConfig, Status, simulate_batch, stack
from pfjax.sim import dynamic as dyn
from pfjax.sim.scenario import make_scenario


def _gains(name: str):
    e, d = C.resolve(name, "--controller")
    flat = C.flat_gains(e)
    if d is not None:
        flat.update(d.make(1.0, 0.2))
    return e.controller, C.params_from_flat(e, flat)


def _scenario(path="sine", controller="stanley", pose0=None, **kw):
    ctrl, gains = _gains(controller)
    e = paths.entry(path)
    sc = dyn.DynamicScenario(
        pose0=e.start_pose if pose0 is None else pose0,
        vehicle=st.robot_params(),
        v_ref=1.0,
        path=e.build(),
        gains=gains,
    )
    return ctrl, sc._replace(**kw)


@pytest.mark.slow  # one compilation per controller: about 35 s on 2 cores
def test_every_registered_controller_runs_unchanged_and_its_slip_is_recorded():
    config = SimConfig(horizon=1.0, dt=0.01, record=False)
    for name in C.cli_names():
        ctrl, sc = _scenario(controller=name)
        r = dyn.simulate_batch(
            stack([sc, sc._replace(vehicle=sc.vehicle._replace(mu=0.3))]), controller=ctrl, config=config
        )
        assert np.all(np.asarray(r.status) == Status.OK), name
        assert np.all(np.isfinite(np.asarray(r.metrics.iae))), name
        slip = np.asarray(r.slip.max_abs_beta_f_deg)
        assert np.all(slip > 0) and slip[1] > slip[0], name  # less friction, more slip


def test_steady_cornering_on_a_circle_matches_the_geometry():
    """On the 2 m circle at the end of 12 s (steady): the rear axle moves on a circle concentric with
    the path, so its velocity is the path's tangent (``beta_r = -theta_e``) and the yaw rate is its
    speed over its radius ``R - d``; the slip angles are those of the tyre forces that turn it."""
    ctrl, sc = _scenario("circle", "stanley")
    r = dyn.simulate_batch(stack([sc]), controller=ctrl, config=SimConfig(horizon=12.0, record=True))
    tr = jax.tree_util.tree_map(lambda a: np.asarray(a[0]), r.trajectory)
    assert int(r.status[0]) == Status.OK
    assert abs(tr.d[-1] - tr.d[-200]) < 1e-6  # steady
    v, beta, r_ = tr.v[-1], tr.beta[-1], tr.psi_dot[-1]
    exact_r = math.atan2(v * math.sin(beta) - sc.vehicle.l_r * r_, v * math.cos(beta))  # the rear axle's velocity angle
    assert exact_r == pytest.approx(-tr.theta_e[-1], abs=1e-6)
    v_rear = v * math.cos(beta) / math.cos(exact_r)
    assert r_ == pytest.approx(v_rear / (2.0 - tr.d[-1]), rel=1e-6)
    # the measured (linearised tyre) slip: third-order terms in beta and l_r psi_dot / v (0.05 rad) away
    assert tr.beta_r[-1] == pytest.approx(exact_r, abs=1e-4)
    # the lateral acceleration v^2 / R = 0.5 m/s^2 needs slip at both axles, the front more (understeer: C_Sf < C_Sr)
    assert 0 < -tr.beta_r[-1] < tr.beta_f[-1] < math.radians(5)


def test_at_high_friction_it_follows_the_kinematic_model_without_slip():
    """The slip falls as ``1 / mu``: with a fast actuator (2 ms, no rate limit) the lateral error
    approaches the kinematic model's (no slip, same controller and start) as ``mu`` grows, to about a
    millimetre at ``mu = 20``."""
    ctrl, sc = _scenario("sine", "stanley", tau_delta=0.002)
    fast = sc.vehicle._replace(v_delta_max=1e3, v_delta_min=-1e3)
    runs = [sc._replace(vehicle=fast._replace(mu=mu)) for mu in (5.0, 20.0)]
    config = SimConfig(horizon=4.0, dt=0.0005, record=True)
    d_dyn = np.asarray(dyn.simulate_batch(stack(runs), controller=ctrl, config=config).trajectory.d)
    kin = make_scenario(sc.path, sc.pose0, sc.gains, v=1.0, L=0.2, delta_max_deg=30.0)
    d_kin = np.asarray(simulate_batch(stack([kin]), controller=ctrl, config=config).trajectory.d[0])
    err = np.max(np.abs(d_dyn - d_kin), axis=1)
    assert err[1] < 1.5e-3 and err[1] < 0.5 * err[0], err
    assert np.max(np.abs(d_kin)) > 0.1  # the start is off the path: there is a transient to follow


def test_the_speed_loop_holds_the_reference_speed():
    ctrl, sc = _scenario("sine", "pure-pursuit", v_ref=1.5)
    x0 = dyn.start_state(sc.pose0, 1.5, sc.vehicle)
    assert float(x0.v) == 1.5
    r = dyn.simulate_batch(stack([sc]), controller=ctrl, config=SimConfig(horizon=3.0, record=True))
    v = np.asarray(r.trajectory.v[0])
    assert np.max(np.abs(v - 1.5)) < 0.02 and abs(v[-1] - 1.5) < 2e-3


def test_failures_are_statuses():
    ctrl, sc = _scenario("line", "stanley")
    sc = sc._replace(u0=0.0)
    far = sc._replace(pose0=(0.0, 3.0, 0.0))
    nan = sc._replace(pose0=(0.0, float("nan"), 0.0))
    config = SimConfig(horizon=1.0, dt=0.01, record=False, d_fail=1.0)
    r = dyn.simulate_batch(stack([sc, far, nan]), controller=ctrl, config=config)
    assert [int(s) for s in r.status] == [Status.OK, Status.DIVERGED, Status.NONFINITE]
    assert np.isnan(float(r.fail_time[0])) and float(r.fail_time[1]) == 0.0
    # the runs that failed at t = 0 have no samples: no slip (NaN, not 0 deg), as no max |d|
    for name in dyn.SLIP_METRIC_NAMES:
        values = np.asarray(getattr(r.slip, name))
        assert np.isfinite(values[0]) and np.all(np.isnan(values[1:])), name
    assert np.all(np.isnan(np.asarray(r.metrics.max_abs_d)[1:]))
    with pytest.raises(InputError, match="^control_every: "):
        dyn.simulate_batch(stack([sc]), controller=ctrl, config=SimConfig(horizon=1.0, control_every=None))


def test_gradient_through_the_dynamic_vehicle_matches_finite_differences():
    """d IAE / d (mu, k, tau_delta) through a 2 s run (reverse mode through the loop) against
    central differences, float64."""
    ctrl, sc = _scenario("sine", "stanley")
    config = SimConfig(horizon=2.0, dt=0.01, record=False)

    def iae(z):
        mu, k, tau = z[0], z[1], z[2]
        s = sc._replace(vehicle=sc.vehicle._replace(mu=mu), gains=sc.gains._replace(k=k), tau_delta=tau)
        return dyn.simulate(ctrl, s, config).metrics.iae

    z = jnp.array([0.6, float(sc.gains.k), 0.05])
    g = np.asarray(jax.jit(jax.grad(iae))(z))
    f = jax.jit(iae)
    h = 1e-6
    fd = np.array([(float(f(z.at[i].add(h))) - float(f(z.at[i].add(-h)))) / (2 * h) for i in range(3)])
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)
    assert np.all(np.abs(g) > 1e-6)


def test_max_stable_step_separates_stable_from_unstable_integration():
    """At ``mu = 10`` and 1 m/s the tyre modes are fast (about -1100 and -500 1/s): a step below
    :func:`st.max_stable_step` runs, one 30 % above it blows up (the run fails, as data; the entry
    points refuse that step, so the pure single-run function is jitted here)."""
    from functools import partial

    ctrl, sc = _scenario("line", "stanley")
    sc = sc._replace(vehicle=sc.vehicle._replace(mu=10.0))
    dt_max = st.max_stable_step(sc.vehicle, 1.0, sc.tau_delta, sc.k_v)
    assert 0.002 < dt_max < 0.0025
    ev = st.lateral_eigenvalues(sc.vehicle, 1.0)
    assert np.all(ev.real < 0)
    for dt, ok in ((0.002, True), (1.3 * dt_max, False)):
        config = SimConfig(horizon=round(1.0 / dt) * dt, dt=dt, record=False)
        r = jax.jit(partial(dyn.simulate, ctrl, config=config))(sc)
        assert (int(r.status) == Status.OK) == ok, dt
        if not ok:
            with pytest.raises(InputError, match=r"^config\.dt: the ST model at mu = 10 "):
                dyn.simulate_batch(stack([sc]), controller=ctrl, config=config)


def test_the_entry_points_check_the_step_against_the_batchs_worst_case():
    """CommonRoad's vehicle 2 on the drift model at 1 m/s needs dt <= 0.27 ms: 5 ms is refused by
    simulate_one and simulate_batch as by pfjax.simulate (it ran 'ok' with 101 deg of front slip)."""
    from pfjax.sim.scenario import make_dynamic_scenario

    ctrl, gains = _gains("stanley")
    e = paths.entry("sine")
    sc = make_dynamic_scenario(e.build(), e.start_pose, gains, params="vehicle2", model="std", v=1.0)
    config = SimConfig(horizon=0.1, dt=0.005, record=False)
    with pytest.raises(InputError, match=r"^config\.dt: the STD model at mu = 1\.0489 and speed 1 m/s"):
        dyn.simulate_one(sc, controller=ctrl, config=config)
    with pytest.raises(InputError, match=r"^config\.dt: "):
        dyn.simulate_batch(stack([sc, sc]), controller=ctrl, config=config)


def test_a_batch_a_callers_jit_captures_is_checked_on_the_host_and_still_runs():
    """Inside a caller's jit only the gains are traced: the step is checked on the batch's concrete
    numbers (host copies), and the value and its gradient come back."""
    ctrl, sc = _scenario("line", "stanley")
    batch = stack([sc, sc])
    config = SimConfig(horizon=0.2, dt=0.01, record=False)

    def loss(k):
        gains = jax.tree_util.tree_map(lambda g: k * g, batch.gains)
        return dyn.simulate_batch(batch._replace(gains=gains), controller=ctrl, config=config).metrics.iae.sum()

    value, grad = jax.jit(loss)(1.0), jax.jit(jax.grad(loss))(1.0)
    assert np.isfinite(value) and np.isfinite(grad)
