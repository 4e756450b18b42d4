"""The ST single-track model against CommonRoad's reference implementation (``commonroad-vehicle-models``):
the vector field at random states and inputs (both branches, the constraints active and not) to 1e-9
relative, and trajectories with held inputs against ``scipy.integrate.solve_ivp`` of the reference."""

import copy

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pfjax.models import single_track as st

vm = pytest.importorskip("vehiclemodels")
from vehiclemodels.parameters_vehicle1 import parameters_vehicle1  # noqa: E402
from vehiclemodels.parameters_vehicle2 import parameters_vehicle2  # noqa: E402
from vehiclemodels.parameters_vehicle3 import parameters_vehicle3  # noqa: E402
from vehiclemodels.vehicle_dynamics_st import vehicle_dynamics_st  # noqa: E402


def _robot_commonroad(p: st.STParams):
    """A CommonRoad parameter object holding :func:`st.robot_params`, except that CommonRoad has one
    cornering stiffness for both axles: the rear's is set to the front's (``C_Sr := C_Sf``)."""
    c = copy.deepcopy(parameters_vehicle1())
    c.a, c.b, c.h_s, c.m, c.I_z = p.l_f, p.l_r, p.h, p.m, p.I_z
    c.tire.p_dy1, c.tire.p_ky1 = p.mu, -p.C_Sf * p.mu
    c.steering.min, c.steering.max, c.steering.v_min, c.steering.v_max = (
        p.delta_min,
        p.delta_max,
        p.v_delta_min,
        p.v_delta_max,
    )
    lon = c.longitudinal
    lon.v_min, lon.v_max, lon.v_switch, lon.a_max = p.v_min, p.v_max, p.v_switch, p.a_max
    return c


def _sets():
    out = [
        (f"vehicle{i}", f()) for i, f in enumerate((parameters_vehicle1, parameters_vehicle2, parameters_vehicle3), 1)
    ]
    robot = st.robot_params()._replace(C_Sr=st.robot_params().C_Sf)
    return out + [("robot", _robot_commonroad(robot))]


SETS = _sets()
_rhs = jax.jit(st.rhs)


def _random_states(p: st.STParams, rng, n):
    """States over the speed range (slow ones below v_kinematic included), steering at and beyond
    the limits, inputs inside and outside the constraints."""
    v_scale = 3.0 * p.l_f / 0.1 if p.m < 10 else 30.0
    v = rng.uniform(-0.2 * v_scale, v_scale, n)
    v[: n // 5] = rng.uniform(-0.1, 0.1, n // 5)  # the kinematic branch
    x = np.stack(
        [
            rng.normal(0, 10, n),
            rng.normal(0, 10, n),
            rng.uniform(1.1 * p.delta_min, 1.1 * p.delta_max, n),
            v,
            rng.uniform(-np.pi, np.pi, n),
            rng.normal(0, 0.5, n),
            rng.normal(0, 0.1, n),
        ],
        axis=1,
    )
    u = np.stack([rng.uniform(-2, 2, n) * p.v_delta_max, rng.uniform(-1.5, 1.5, n) * p.a_max], axis=1)
    return x, u


@pytest.mark.parametrize("name,cr", SETS, ids=[s[0] for s in SETS])
def test_vector_field_matches_commonroad(name, cr):
    p = st.params_from_commonroad(cr)
    rng = np.random.default_rng(37)
    xs, us = _random_states(p, rng, 400)
    slow = 0
    for x, u in zip(xs, us):
        ref = np.asarray(vehicle_dynamics_st(list(x), list(u), cr), float)
        got = np.asarray(_rhs(jnp.asarray(x), jnp.asarray(u), p))
        scale = np.abs(ref) + 1e-9 * np.max(np.abs(ref))
        assert np.all(np.abs(got - ref) <= 1e-9 * scale), (name, x, u, got, ref)
        slow += abs(x[3]) < 0.1
    assert slow >= 80  # both branches were checked


def test_params_from_commonroad_reads_every_field():
    p = st.params_from_commonroad(parameters_vehicle2())
    cr = parameters_vehicle2()
    assert p.l_f == cr.a and p.l_r == cr.b and p.h == cr.h_s and p.m == cr.m and p.I_z == cr.I_z
    assert p.mu == cr.tire.p_dy1 and p.C_Sf == p.C_Sr == -cr.tire.p_ky1 / cr.tire.p_dy1
    assert (p.delta_min, p.delta_max, p.v_delta_min, p.v_delta_max) == (-1.066, 1.066, -0.4, 0.4)
    assert (p.v_min, p.v_max, p.v_switch, p.a_max) == (-13.9, 50.8, 7.319, 11.5)
    assert st.params_from_commonroad(cr, mu=0.3).mu == 0.3


@pytest.mark.parametrize("i", [1, 2, 3])
def test_stored_commonroad_vehicles_are_the_packages(i):
    f = (parameters_vehicle1, parameters_vehicle2, parameters_vehicle3)[i - 1]
    assert st.parameter_set(f"vehicle{i}") == st.params_from_commonroad(f())


def test_robot_params_scale_the_f1tenth_car_to_the_source_robot():
    p = st.robot_params()
    assert p.wheelbase == pytest.approx(0.2, rel=1e-12)
    assert p.delta_max == pytest.approx(np.pi / 6)
    assert p.m == pytest.approx(3.74 * (0.2 / 0.3302) ** 3)


@pytest.mark.parametrize("name,cr", SETS, ids=[s[0] for s in SETS])
def test_held_input_trajectories_match_solve_ivp_of_the_reference(name, cr):
    """RK4 (a fixed step small against the model's fastest time constant) of :func:`st.rhs` against
    ``solve_ivp`` (DOP853, rtol 1e-12) of CommonRoad's vector field, the inputs held: a steering-rate
    input beyond its limit (clipped) sweeping the steering from -0.4 to +0.4 rad (through the turn's
    reversal; the angle limits' kink is checked by the vector-field test: a fixed step crosses it with
    an O(dt) error), and an acceleration input (above ``v_switch`` for the cars: the constant-power limit)."""
    from pfjax.sim.integrators import rk4_step

    p = st.params_from_commonroad(cr)
    robot = p.m < 10
    v0 = 1.0 if robot else 10.0
    u = np.array([1.5 * p.v_delta_max, 0.3 * p.a_max])
    horizon, dt = (0.8 / p.v_delta_max, 1e-4) if robot else (2.0, 1e-3)
    x0 = np.array([0.0, 0.0, -0.4, v0, 0.3, 0.1, 0.01])
    n = int(round(horizon / dt))

    @jax.jit
    def simulate(x0):
        f = lambda t, x: st.rhs(x, jnp.asarray(u), p)
        return jax.lax.scan(lambda x, k: (rk4_step(f, k * dt, x, dt),) * 2, x0, jnp.arange(n))[1]

    got = np.asarray(simulate(jnp.asarray(x0)))
    ts = dt * np.arange(1, n + 1)
    f_ref = lambda t, x: vehicle_dynamics_st(list(x), list(u), cr)
    ref = solve_ivp(f_ref, (0, ts[-1]), x0, method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-12)
    assert ref.success
    scale = np.max(np.abs(ref.y), axis=1, keepdims=True)
    err = np.max(np.abs(got.T - ref.y) / scale)
    assert err < 1e-6, err


def test_tyre_slip_is_the_kinematic_models_slip_to_third_order():
    """The exact slip angles (the rear axle's and the front wheel's velocity angles) give the
    kinematic slip model (SOURCE convention, speed ``v cos(beta)``) the dynamic state's yaw rate;
    :func:`st.tyre_slip`, the model's linearised tyre slip angles, differ from them by less than
    ``|angle|^3``."""
    from pfjax.models.slip import SlipParams, yaw_rate

    p = st.robot_params()
    rng = np.random.default_rng(5)
    for _ in range(50):
        x = st.STState(
            *jnp.asarray(
                [0.0, 0.0, *rng.uniform(-0.3, 0.3, 1), rng.uniform(0.5, 2), 0.4, *rng.uniform(-1, 1, 2) * [2, 0.1]]
            )
        )
        vx, vy = x.v * jnp.cos(x.beta), x.v * jnp.sin(x.beta)
        exact_r = jnp.arctan2(vy - p.l_r * x.psi_dot, vx)
        exact_f = x.delta - jnp.arctan2(vy + p.l_f * x.psi_dot, vx)
        r = yaw_rate(x.delta, exact_r, exact_f, SlipParams(v=vx, L=p.wheelbase))
        assert float(r) == pytest.approx(float(x.psi_dot), rel=1e-12, abs=1e-14)
        br, bf, b = st.tyre_slip(x, p)
        assert abs(float(br - exact_r)) <= abs(float(exact_r)) ** 3 + abs(float(x.beta)) ** 3 + 1e-15
        assert abs(float(bf - exact_f)) <= abs(float(x.delta - exact_f)) ** 3 + abs(float(x.beta)) ** 3 + 1e-15
        assert float(b) == float(x.beta)
    slow = st.STState(*jnp.asarray([0.0, 0.0, 0.2, 0.05, 0.4, 0.3, 0.02]))
    assert [float(a) for a in st.tyre_slip(slow, p)[:2]] == [0.0, 0.0]  # the kinematic branch: no tyre slip
