"""LMI state-feedback designs (source eq. 8-13): guarantees, pole regions, infeasibility, and the
reproduction of the source's mixed H2/H-infinity design (docs/reproductions/path-following.md §4)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.linalg as sla

from pfjax.synthesis import (
    Design,
    PoleRegion,
    SynthesisError,
    closed_loop,
    h2_norm,
    h2_state_feedback,
    hinf_norm,
    hinf_state_feedback,
    is_hurwitz,
    mixed_bounds_for_gain,
    mixed_h2_hinf,
    region_contains,
    slip_design_plant,
    synthesize,
)

BOUND_RTOL = 1e-6  # true norm <= LMI bound * (1 + BOUND_RTOL)
SOURCE_K = np.array([[-2.7381, -2.0772]])  # source eq. 13 result (docs/reproductions/path-following.md §4)
SOURCE_GAMMA_INF = 1.1
SOURCE_GAMMA_2 = 4.07


@pytest.fixture(scope="module")
def plant():
    return slip_design_plant(v=1.0, L=0.2)


@pytest.fixture(scope="module")
def mixed(plant):
    return mixed_h2_hinf(plant, alpha=10.0, beta=1.0)


def assert_guarantees(d: Design, plant):
    Acl, Bw, Cinf, C2 = closed_loop(plant, d.K)
    assert d.K.shape == (plant.Bu.shape[1], plant.A.shape[0])
    assert is_hurwitz(Acl)
    assert np.all(d.closed_loop_poles.real < 0)
    np.testing.assert_allclose(np.sort_complex(d.closed_loop_poles), np.sort_complex(np.linalg.eigvals(Acl)), rtol=1e-9)
    assert d.hinf_norm == pytest.approx(hinf_norm(Acl, Bw, Cinf), rel=1e-9)
    assert d.h2_norm == pytest.approx(h2_norm(Acl, Bw, C2), rel=1e-9)
    if d.gamma_inf is not None:
        assert d.hinf_norm <= d.gamma_inf * (1 + BOUND_RTOL)
    if d.gamma_2 is not None:
        assert d.h2_norm <= d.gamma_2 * (1 + BOUND_RTOL)
    assert d.solver == "CLARABEL"
    assert d.solver_status in ("optimal", "optimal_inaccurate")


def test_slip_design_plant_matches_spec():
    P = slip_design_plant(v=2.0, L=0.4)
    np.testing.assert_array_equal(P.A, [[0, 2], [0, 0]])
    np.testing.assert_array_equal(P.Bu, [[0], [5]])
    np.testing.assert_array_equal(P.Bw, [[2, 0, 0], [-5, -5, -2]])
    np.testing.assert_array_equal(P.Cinf, np.eye(2))
    np.testing.assert_array_equal(P.Dinf_u, np.zeros((2, 1)))
    np.testing.assert_array_equal(P.C2, [[1, 0], [0, 1], [0, 0]])
    np.testing.assert_array_equal(P.D2u, [[0], [0], [1]])
    assert all(m.dtype == np.float64 for m in P)


# --- designs: stability and guaranteed bounds --------------------------------------------------


def test_mixed_design_guarantees(plant, mixed):
    assert mixed.method == "mixed" and mixed.alpha == 10.0 and mixed.beta == 1.0
    assert_guarantees(mixed, plant)


def test_h2_design_is_lqr_and_bound_is_tight(plant):
    d = h2_state_feedback(plant)
    assert d.method == "h2" and d.gamma_inf is None and d.gamma_2 is not None
    assert_guarantees(d, plant)
    # H2-optimal state feedback = LQR with Q = C2'C2, R = D2u'D2u (C2'D2u = 0 here).
    Q = plant.C2.T @ plant.C2
    R = plant.D2u.T @ plant.D2u
    S = sla.solve_continuous_are(plant.A, plant.Bu, Q, R)
    K_lqr = -np.linalg.solve(R, plant.Bu.T @ S)
    # The cost is quadratic (flat) around the optimum: a relative objective error e moves K by
    # ~sqrt(e), so K is checked to 1e-3 and the optimal value to 1e-6.
    np.testing.assert_allclose(d.K, K_lqr, rtol=1e-3)
    Acl, Bw, _, C2 = closed_loop(plant, K_lqr)
    h2_opt = h2_norm(Acl, Bw, C2)
    assert h2_opt <= d.h2_norm <= h2_opt * (1 + 1e-6)
    # the optimal LMI bound equals the optimal H2 norm up to solver tolerance and eps
    assert d.gamma_2 == pytest.approx(h2_opt, rel=1e-6)


def test_hinf_design_guarantees(plant):
    d = hinf_state_feedback(plant)
    assert d.method == "hinf" and d.gamma_2 is None and d.gamma_inf is not None
    assert_guarantees(d, plant)
    # z_inf = x has no control penalty (singular problem): the optimum beats every other design
    # and is approached with large gains, so only the ordering is asserted.
    assert d.gamma_inf <= mixed_h2_hinf(plant).gamma_inf


def test_mixed_bound_constraints_are_respected(plant, mixed):
    d = mixed_h2_hinf(plant, gamma_inf_max=1.05)
    assert_guarantees(d, plant)
    assert d.gamma_inf <= 1.05 * (1 + 1e-7)
    assert d.gamma_2 >= mixed.gamma_2  # tighter H-inf bound costs H2 performance
    d2 = mixed_h2_hinf(plant, gamma_2_max=3.8)
    assert_guarantees(d2, plant)
    assert d2.gamma_2 <= 3.8 * (1 + 1e-7)


REGIONS = [
    PoleRegion(max_real=-2.0),
    PoleRegion(disk_center=0.0, disk_radius=6.0),
    PoleRegion(sector_angle=np.pi / 6),
    PoleRegion(max_real=-1.0, disk_center=-3.0, disk_radius=3.0, sector_angle=np.pi / 4),
]


@pytest.mark.parametrize("region", REGIONS, ids=["halfplane", "disk", "sector", "all"])
@pytest.mark.parametrize("method", ["hinf", "h2", "mixed"])
def test_pole_region_respected(plant, region, method):
    design = {"hinf": hinf_state_feedback, "h2": h2_state_feedback, "mixed": mixed_h2_hinf}[method]
    d = design(plant, region=region)
    assert_guarantees(d, plant)
    assert region_contains(region, d.closed_loop_poles)


def test_region_contains_geometry():
    r = PoleRegion(max_real=-1.0, disk_center=-3.0, disk_radius=3.0, sector_angle=np.pi / 4)
    assert region_contains(r, [-2.0 + 0.5j, -2.0 - 0.5j])
    assert not region_contains(r, [-0.5])  # right of the half-plane
    assert not region_contains(r, [-6.5])  # outside the disk
    assert not region_contains(r, [-2.0 + 2.5j])  # outside the 45 deg sector
    with pytest.raises(ValueError):
        PoleRegion(disk_center=-1.0)


# --- reproduction of the source (docs/reproductions/path-following.md §4) ----------------------------------------------


def test_mixed_reproduces_source_within_2_percent(mixed):
    # Ours (Clarabel, eps=1e-7): K = [-2.7826, -2.0819], gamma_inf = 1.1008, gamma_2 = 4.0670.
    # Bounds agree to < 0.1 %; K to 1.6 % (k1) and 0.2 % (k2): see the next test for why K is the
    # loosest of the three.
    np.testing.assert_allclose(mixed.K, SOURCE_K, rtol=0.02)
    assert mixed.gamma_inf == pytest.approx(SOURCE_GAMMA_INF, rel=0.02)
    assert mixed.gamma_2 == pytest.approx(SOURCE_GAMMA_2, rel=0.02)
    assert mixed.gamma_inf == pytest.approx(SOURCE_GAMMA_INF, rel=0.002)
    assert mixed.gamma_2 == pytest.approx(SOURCE_GAMMA_2, rel=0.002)


def test_source_gain_is_near_optimal_and_its_bounds_hold(plant, mixed):
    # The objective alpha g_inf^2 + beta g_2^2 is very flat along k1: the source K is certified
    # (common X, Y = K X) with an objective only ~3e-5 (relative) above our optimum, and gains
    # with k1 anywhere in about [-2.88, -2.69] reach 1e-4 of it. msfsyn stops at a relative
    # accuracy `tol` on this criterion, so the 1.6 % difference in k1 is optimiser stopping, not
    # a different convention.
    g_inf, g_2 = mixed_bounds_for_gain(plant, SOURCE_K)
    opt = 10.0 * mixed.gamma_inf**2 + mixed.gamma_2**2
    src = 10.0 * g_inf**2 + g_2**2
    assert opt <= src <= opt * (1 + 1e-4)
    assert g_inf == pytest.approx(SOURCE_GAMMA_INF, rel=0.005)
    assert g_2 == pytest.approx(SOURCE_GAMMA_2, rel=0.005)
    # True closed-loop norms of the source K are below its reported bounds.
    Acl, Bw, Cinf, C2 = closed_loop(plant, SOURCE_K)
    assert hinf_norm(Acl, Bw, Cinf) < SOURCE_GAMMA_INF  # 1.0842
    assert h2_norm(Acl, Bw, C2) < SOURCE_GAMMA_2  # 3.5940


# --- failures ------------------------------------------------------------------------------------


def test_unstable_uncontrollable_mode_is_infeasible(plant):
    bad = plant._replace(A=np.array([[1.0, 0.0], [0.0, -1.0]]), Bu=np.array([[0.0], [1.0]]))
    for design in (hinf_state_feedback, h2_state_feedback, mixed_h2_hinf):
        with pytest.raises(SynthesisError, match="infeasible") as info:
            design(bad)
        assert "\n" not in str(info.value)


def test_too_small_bounds_are_infeasible(plant):
    with pytest.raises(SynthesisError, match=r"mixed .*status 'infeasible'"):
        mixed_h2_hinf(plant, gamma_inf_max=0.9)  # below the H-inf infimum (1 for this plant)
    with pytest.raises(SynthesisError, match="infeasible"):
        mixed_h2_hinf(plant, gamma_2_max=3.0)  # below the LQR optimum 3.354
    with pytest.raises(SynthesisError, match="infeasible"):
        mixed_bounds_for_gain(plant, [[1.0, 1.0]])  # destabilising gain
    assert issubclass(SynthesisError, ValueError)


# --- dispatcher and serialisation -----------------------------------------------------------------


def test_synthesize_dispatch_and_to_dict(mixed):
    d = synthesize("mixed", v=1.0, L=0.2, alpha=10.0, beta=1.0)
    np.testing.assert_allclose(d.K, mixed.K, rtol=1e-6)
    out = json.loads(json.dumps(d.to_dict()))
    assert out["method"] == "mixed"
    np.testing.assert_allclose(out["K"], d.K)
    assert len(out["closed_loop_poles"]) == 2 and all(len(p) == 2 for p in out["closed_loop_poles"])
    assert out["gamma_inf"] == d.gamma_inf and out["h2_norm"] == d.h2_norm
    assert synthesize("h2").to_dict()["gamma_inf"] is None
    with pytest.raises(ValueError, match="bogus"):
        synthesize("bogus")
