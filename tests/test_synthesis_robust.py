"""Designs beyond the source (integral, polytopic, bounded steering) and synthesis error reporting."""

import math
import warnings

import numpy as np
import pytest
from scipy.linalg import expm

from pfjax.synthesis import (
    SynthesisError,
    integral_mixed,
    mixed_h2_hinf,
    operating_point_plant,
    polytopic_mixed,
    robust_mixed,
    slip_design_plant,
)
from pfjax.synthesis.lmi import bound_warnings
from pfjax.synthesis.norms import closed_loop, h2_norm, hinf_norm, is_hurwitz


def test_integral_design_bounds_and_default_gain():
    d = integral_mixed()
    assert d.warnings == () and d.solver_status in ("optimal", "optimal_inaccurate")
    assert d.hinf_norm <= d.gamma_inf * (1 + 1e-6) and d.h2_norm <= d.gamma_2 * (1 + 1e-6)
    assert np.all(np.real(d.vertex_poles) < 0)
    from pfjax.controllers.integral import DEFAULT_K

    np.testing.assert_allclose(d.K.ravel(), DEFAULT_K, atol=1e-3)  # the registry default is this design


def test_integral_design_removes_constant_slip_offset():
    # the design's purpose: steady |d| below 0.1 mm under constant slip (line: constant curvature)
    import jax

    from pfjax import controllers as C
    from pfjax.sim import SimConfig, simulate_batch, stack
    from pfjax.sim.scenario import paper_scenario

    with jax.enable_x64(True):
        g = C.integral_params(integral_mixed().K.ravel())
        sc = stack([paper_scenario("line", g, beta_r_deg=br, beta_f_deg=bf) for br, bf in ((5, 5), (-8, 4), (10, -10))])
        r = simulate_batch(sc, controller=C.integral, config=SimConfig(dt=0.01, horizon=30.0, record=False))
    assert np.all(np.asarray(r.status) == 0)
    assert np.all(np.asarray(r.metrics.steady_abs_d) < 1e-4)


def test_polytopic_design_certifies_every_operating_point():
    d = polytopic_mixed(v_range=(0.7, 1.3), beta_r_max_deg=10.0)
    assert d.warnings == ()
    # independent check on a grid of true operating points inside the polytope
    for v in np.linspace(0.7, 1.3, 4):
        for b in np.radians(np.linspace(-10, 10, 5)):
            p = operating_point_plant(v, 0.2, b)
            Acl, Bw, Ci, C2 = closed_loop(p, d.K)
            assert is_hurwitz(Acl)
            assert hinf_norm(Acl, Bw, Ci) <= d.gamma_inf * (1 + 1e-6)
            assert h2_norm(Acl, Bw, C2) <= d.gamma_2 * (1 + 1e-6)
    # robustness costs nominal performance: bounds above the nominal design's
    assert d.gamma_inf >= mixed_h2_hinf(slip_design_plant()).gamma_inf


def test_steering_bound_holds_for_undisturbed_linear_loop():
    x0s = np.array([[0.3, math.radians(15)], [-0.3, math.radians(15)]])
    dmax = math.radians(30)
    d = robust_mixed([slip_design_plant()], x0s=x0s, delta_max=dmax)
    assert d.steer_bound <= dmax * (1 + 1e-6)
    p = slip_design_plant()
    Acl = p.A + p.Bu @ d.K
    for x0 in x0s:  # exact solution x(t) = expm(Acl t) x0, on a fine grid
        u = [(d.K @ expm(Acl * t) @ x0).item() for t in np.linspace(0, 60, 601)]
        assert max(abs(np.array(u))) <= dmax * (1 + 1e-6)


def test_steering_bound_scales_with_the_initial_errors():
    """The ellipsoid's scale is free: a small initial error leaves the steering limit inactive (the
    design equals the unconstrained one, and the guaranteed peak |K x| scales with the start), and
    larger initial errors ask for smaller gains, each design steering exactly up to the limit from
    its worst start (checked on the exact linear trajectories)."""
    p = slip_design_plant()
    dmax = math.radians(30)
    free = robust_mixed([p])
    small = robust_mixed([p], x0s=[[0.01, 0.0]], delta_max=dmax)
    tiny = robust_mixed([p], x0s=[[0.001, 0.0]], delta_max=dmax)
    np.testing.assert_allclose(small.K, free.K, rtol=1e-3)
    assert small.steer_bound < dmax and small.steer_bound / tiny.steer_bound == pytest.approx(10.0, rel=1e-3)
    t = np.linspace(0, 60, 241)
    gains = []
    for a in (0.01, 0.1, 0.3, 0.5):
        x0s = np.array([[a, math.radians(30 * a)], [-a, math.radians(30 * a)]])
        d = robust_mixed([p], x0s=x0s, delta_max=dmax)
        w, V = np.linalg.eig(p.A + p.Bu @ d.K)  # x(t) = V diag(exp(w t)) V^-1 x0
        peak = max(
            np.max(np.abs((d.K @ V @ (np.exp(np.outer(w, t)) * np.linalg.solve(V, x0)[:, None])).real)) for x0 in x0s
        )
        assert peak <= d.steer_bound * (1 + 1e-6) and d.steer_bound <= dmax * (1 + 1e-6)
        if a >= 0.1:
            assert d.steer_bound == pytest.approx(dmax, rel=1e-4)
        gains.append(float(np.linalg.norm(d.K)))
    assert gains[0] > gains[1] > gains[2] > gains[3] > 0.1 * float(np.linalg.norm(free.K))


def test_synthesis_error_carries_status():
    bad = slip_design_plant()._replace(A=np.array([[1.0, 0.0], [0.0, -1.0]]), Bu=np.array([[0.0], [1.0]]))
    with pytest.raises(SynthesisError) as info:
        mixed_h2_hinf(bad)
    assert info.value.status == "infeasible" and "infeasible" in str(info.value)
    with pytest.raises(SynthesisError) as info:
        robust_mixed([slip_design_plant()], x0s=[[50.0, 1.0]], delta_max=1e-6)
    assert info.value.status not in (None, "optimal", "optimal_inaccurate")  # Clarabel: infeasible or user_limit


def test_bound_disagreement_is_reported():
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        msgs = bound_warnings(1.0, 4.0, 1.2, 3.9, cond_X=1e11)
    assert len(msgs) == 2 and "H-inf" in msgs[0] and "cond" in msgs[1]
    assert len(w) == 2
    assert bound_warnings(1.1, 4.07, 1.08, 3.6) == ()
    assert mixed_h2_hinf(slip_design_plant()).warnings == ()
