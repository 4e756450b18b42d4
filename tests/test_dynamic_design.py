"""The linearised lateral-yaw dynamics of the ST model and the design plant built on them, against
finite-difference Jacobians of the model's vector field; the mixed-criterion output-feedback design."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.models import single_track as st
from pfjax.synthesis import closed_loop, h2_norm, hinf_norm, mixed_h2_hinf, slip_design_plant
from pfjax.synthesis.dynamic_plant import dynamic_design_plant, dynamic_mixed

_rhs = jax.jit(st.rhs)


def _fd_jacobian(f, z0, h=1e-6):
    """Central differences, column by column (truncation O(h^2), rounding O(eps / h): ~1e-10 here)."""
    cols = [(f(z0 + h * e) - f(z0 - h * e)) / (2 * h) for e in np.eye(len(z0))]
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("name,v", [("robot", 1.0), ("robot", 0.5), ("vehicle2", 10.0)])
def test_lateral_yaw_matrices_are_the_jacobian_of_rhs(name, v):
    p = st.parameter_set(name)._replace(mu=0.6)
    x0 = np.array([0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0])

    def f(z):  # (psi_dot, beta, delta) -> (psi_dot', beta')
        x = x0.copy()
        x[[5, 6, 2]] = z
        return np.asarray(_rhs(jnp.asarray(x), jnp.zeros(2), p))[[5, 6]]

    J = _fd_jacobian(f, np.zeros(3))
    a, b = st.lateral_yaw_matrices(p, v)
    np.testing.assert_allclose(J, np.hstack([a, b]), rtol=1e-6, atol=1e-7 * np.max(np.abs(J)))


def test_design_plant_is_the_jacobian_of_the_closed_loop_vector_field():
    """``x = [d, theta_e, psi_dot, beta, delta]`` about straight driving along the x axis (rear axle at
    ``(0, d)``, heading ``theta_e``), the actuator ``v_delta = (delta_c - delta) / tau`` closed: the
    Jacobians in ``x`` and ``delta_c`` of the error dynamics computed from :func:`st.rhs` equal the
    plant's ``A`` and ``Bu`` (the curvature and declared-slip columns ``Bw`` are the kinematic plant's)."""
    p, v, tau = st.robot_params()._replace(mu=0.5), 1.2, 0.05

    def f(z):
        d, th, r, beta, delta, delta_c = z
        x = jnp.asarray([p.l_r * np.cos(th), d + p.l_r * np.sin(th), delta, v, th, r, beta])
        dx = np.asarray(_rhs(x, jnp.asarray([(delta_c - delta) / tau, 0.0]), p))
        d_dot = dx[1] - p.l_r * np.cos(th) * dx[4]  # the rear axle's y velocity
        return np.array([d_dot, dx[4], dx[5], dx[6], dx[2]])

    J = _fd_jacobian(f, np.zeros(6))
    a, b = st.lateral_yaw_matrices(p, v)
    plant = dynamic_design_plant(a, b, v, p.l_r, p.wheelbase, tau)
    np.testing.assert_allclose(J[:, :5], plant.A, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(J[:, 5:], plant.Bu, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(plant.Bw[:2], slip_design_plant(v, p.wheelbase).Bw)


def test_fast_tyres_and_actuator_recover_the_kinematic_plant():
    """As the tyre modes (``mu`` large) and the actuator (``tau`` small) become fast, the kinematic
    design's closed-loop norms on the dynamic plant tend to its norms on the kinematic plant."""
    kin = slip_design_plant(1.0, 0.2)
    K0 = mixed_h2_hinf(kin).K
    A0, B0, Ci0, C20 = closed_loop(kin, K0)
    ref = [hinf_norm(A0, B0, Ci0), h2_norm(A0, B0, C20)]
    p = st.robot_params()
    out = []
    for mu, tau in ((1.0, 0.05), (300.0, 1e-4)):
        a, b = st.lateral_yaw_matrices(p._replace(mu=mu), 1.0)
        plant = dynamic_design_plant(a, b, 1.0, p.l_r, p.wheelbase, tau)
        Kf = np.hstack([K0, np.zeros((1, 3))])
        Acl, Bw, Ci, C2 = closed_loop(plant, Kf)
        out.append([hinf_norm(Acl, Bw, Ci), h2_norm(Acl, Bw, C2)])
    assert np.allclose(out[1], ref, rtol=2e-2)
    assert not np.allclose(out[0], ref, rtol=2e-2)  # at mu = 1 and 50 ms they differ


@pytest.mark.parametrize("integral", [False, True])
def test_dynamic_mixed_lowers_the_criterion_and_stabilises(integral):
    from pfjax.synthesis import integral_mixed

    p = st.robot_params()
    plants = []
    for mu, v in ((0.3, 0.8), (1.0, 1.2)):
        a, b = st.lateral_yaw_matrices(p._replace(mu=mu), v)
        plants.append(dynamic_design_plant(a, b, v, p.l_r, p.wheelbase, 0.05, integral=integral))
    K0 = integral_mixed(1.0, 0.2).K if integral else mixed_h2_hinf(slip_design_plant(1.0, 0.2)).K
    d = dynamic_mixed(plants, K0)
    assert d.K.shape == (1, 3 if integral else 2)
    assert d.max_pole_real < 0
    assert d.criterion < d.criterion0
    assert d.criterion == pytest.approx(10 * d.hinf_norm**2 + d.h2_norm**2, rel=1e-9)
    with pytest.raises(ValueError, match="K0"):
        dynamic_mixed(plants, -np.asarray(K0))  # positive feedback: unstable
