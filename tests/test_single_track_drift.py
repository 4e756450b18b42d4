"""The STD single-track drift model and its magic-formula tyre against CommonRoad's reference
implementation (``commonroad-vehicle-models``): the vector field at random states and inputs (the
kinematic blend, wheel spin and lock, the constraints active and not) to 1e-9 relative, and
trajectories with held inputs against ``scipy.integrate.solve_ivp`` of the reference to 1e-6."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pfjax.models import single_track as st
from pfjax.models import tyres

vm = pytest.importorskip("vehiclemodels")
from vehiclemodels.parameters_vehicle1 import parameters_vehicle1  # noqa: E402
from vehiclemodels.parameters_vehicle2 import parameters_vehicle2  # noqa: E402
from vehiclemodels.parameters_vehicle3 import parameters_vehicle3  # noqa: E402
from vehiclemodels.utils import tire_model  # noqa: E402
from vehiclemodels.vehicle_dynamics_std import vehicle_dynamics_std  # noqa: E402

SETS = [(f"vehicle{i}", f()) for i, f in enumerate((parameters_vehicle1, parameters_vehicle2, parameters_vehicle3), 1)]
_rhs = jax.jit(st.rhs_drift)


def _reference(x, u, cr):
    return np.asarray(vehicle_dynamics_std(list(x), list(u), cr), float)  # it clamps its x's wheel speeds in place


def _random_states(p: st.STDParams, rng, n):
    """States from standstill to 30 m/s (a fifth in the blend below 0.3 m/s), slip angles up to
    about 20 deg, wheels from locked (and spinning backwards) to spinning; inputs inside and beyond
    the constraints."""
    b = p.body
    v = rng.uniform(-1.0, 30.0, n)
    v[: n // 5] = rng.uniform(-0.1, 0.3, n // 5)
    roll = np.abs(v) / p.R_w
    x = np.stack(
        [
            rng.normal(0, 10, n),
            rng.normal(0, 10, n),
            rng.uniform(1.1 * b.delta_min, 1.1 * b.delta_max, n),
            v,
            rng.uniform(-np.pi, np.pi, n),
            rng.normal(0, 0.5, n),
            rng.normal(0, 0.15, n),
            roll * rng.uniform(-0.1, 1.5, n),
            roll * rng.uniform(-0.1, 1.5, n),
        ],
        axis=1,
    )
    u = np.stack([rng.uniform(-2, 2, n) * b.v_delta_max, rng.uniform(-1.5, 1.5, n) * b.a_max], axis=1)
    return x, u


@pytest.mark.parametrize("name,cr", SETS, ids=[s[0] for s in SETS])
def test_drift_vector_field_matches_commonroad(name, cr):
    p = st.drift_params_from_commonroad(cr)
    rng = np.random.default_rng(37)
    xs, us = _random_states(p, rng, 300)
    for x, u in zip(xs, us):
        ref = _reference(x, u, cr)
        got = np.asarray(_rhs(jnp.asarray(x), jnp.asarray(u), p))
        scale = np.abs(ref) + 1e-9 * np.max(np.abs(ref))
        assert np.all(np.abs(got - ref) <= 1e-9 * scale), (name, x, u, got, ref)


def test_magic_formula_matches_commonroad():
    """Each tyre formula at random slips and loads (zero camber, as the drift model calls them)."""
    cr = parameters_vehicle2().tire
    t = tyres.pacejka_from_commonroad(cr)
    rng = np.random.default_rng(3)
    for kappa, alpha, f_z in zip(rng.uniform(-1, 1, 50), rng.uniform(-0.6, 0.6, 50), rng.uniform(100, 8000, 50)):
        f0x = tire_model.formula_longitudinal(kappa, 0, f_z, cr)
        f0y, mu_y = tire_model.formula_lateral(alpha, 0, f_z, cr)
        pairs = [
            (tyres.longitudinal(kappa, f_z, cr.p_dx1, t), f0x),
            (tyres.lateral(alpha, f_z, cr.p_dy1, t), f0y),
            (
                tyres.longitudinal_combined(kappa, alpha, f0x, t),
                tire_model.formula_longitudinal_comb(kappa, alpha, f0x, cr),
            ),
            (
                tyres.lateral_combined(kappa, alpha, f0y, f_z, mu_y, t),
                tire_model.formula_lateral_comb(kappa, alpha, 0, mu_y, f_z, f0y, cr),
            ),
        ]
        for got, ref in pairs:
            assert float(got) == pytest.approx(ref, rel=1e-11, abs=1e-9)


@pytest.mark.parametrize("i", [1, 2, 3])
def test_stored_drift_vehicles_are_the_packages(i):
    f = (parameters_vehicle1, parameters_vehicle2, parameters_vehicle3)[i - 1]
    assert st.drift_parameter_set(f"vehicle{i}") == st.drift_params_from_commonroad(f())
    assert st.drift_params_from_commonroad(f(), mu=0.4).body.mu == 0.4


def test_friction_scales_both_peak_forces():
    """At mu = p_dy1 / 2 the saturated lateral and longitudinal forces halve (the cornering and slip
    stiffnesses stay): the friction coefficient is the tyre's peak."""
    t = tyres.COMMONROAD_TYRE
    for mu in (t.p_dy1, t.p_dy1 / 2):
        peak_y = max(float(tyres.lateral(a, 4000.0, mu, t)) for a in np.linspace(-0.6, 0.0, 601))
        assert abs(peak_y) == pytest.approx(mu * 4000.0, rel=1e-3)
    mu_x = t.p_dx1 * 0.5
    peak_x = max(abs(float(tyres.longitudinal(k, 4000.0, mu_x, t))) for k in np.linspace(-0.5, 0.5, 1001))
    assert peak_x == pytest.approx(mu_x * 4000.0, rel=2e-3)


@pytest.mark.parametrize("name,cr", SETS[1:2], ids=[SETS[1][0]])
def test_drift_held_input_trajectory_matches_solve_ivp_of_the_reference(name, cr):
    """RK4 (1e-4 s: small against the wheel modes' ~1/700 s) of :func:`st.rhs_drift` against
    ``solve_ivp`` (DOP853, rtol 1e-12) of CommonRoad's vector field, inputs held: the steering rate
    beyond its limit (clipped) sweeping the steering from -0.1 to +0.1 rad (a lane change that loads
    the tyres beyond their linear range), driving above ``v_switch`` (the constant-power limit)."""
    from pfjax.sim.integrators import rk4_step

    p = st.drift_params_from_commonroad(cr)
    u = np.array([1.5 * p.body.v_delta_max, 0.3 * p.body.a_max])
    dt, horizon = 1e-4, 0.5
    x0 = np.array([0.0, 0.0, -0.1, 10.0, 0.3, 0.0, 0.0, 10.0 / p.R_w, 10.0 / p.R_w])
    n = int(round(horizon / dt))

    @jax.jit
    def simulate(x0):
        f = lambda t, x: st.rhs_drift(x, jnp.asarray(u), p)
        return jax.lax.scan(lambda x, k: (rk4_step(f, k * dt, x, dt),) * 2, x0, jnp.arange(n))[1]

    got = np.asarray(simulate(jnp.asarray(x0)))
    ts = dt * np.arange(1, n + 1)
    ref = solve_ivp(
        lambda t, x: _reference(x, u, cr), (0, ts[-1]), x0, method="DOP853", t_eval=ts, rtol=1e-12, atol=1e-12
    )
    assert ref.success
    scale = np.max(np.abs(ref.y), axis=1, keepdims=True)
    err = np.max(np.abs(got.T - ref.y) / scale)
    assert err < 1e-6, err
    assert np.max(np.abs(got[:, 6])) > 0.005  # the body slipped (beta beyond 0.3 deg): the tyres were loaded
