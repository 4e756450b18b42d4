"""Focus-point vehicle tracking (pfjax.tracking) against independent references.

References: hand-computed focus point and connection; central finite differences of the output map
for M(theta, gamma) and numpy's det for the closed form; scipy solve_ivp (RK45, rtol 1e-11) of the
docs/reproductions/vehicle-tracking.md §1 model written here in NumPy for the simulator; exp(-k t) for the linearised error; the
linearised zero dynamics' eigenvalues against simulated convergence.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pfjax import tracking as T
from pfjax.sim.slip_profiles import constant_slip
from pfjax.tracking import leader as L
from pfjax.tracking.geometry import tracking_error_from_connection
from pfjax.tracking.lemma import sample_geometry, zero_dynamics_matrix, zero_dynamics_stable

G30 = math.radians(30)


def _state(x, y, th, g):
    return T.Follower(*(jnp.asarray(v, float) for v in (x, y, th, g)))


def test_focus_point_by_hand():
    s = _state(1.0, 2.0, math.pi / 2, 0.2)
    fw = T.FollowerParams(a=2.0, f=1.0, l=1.5, p=2.0)
    z = np.asarray(T.focus_point(s, fw))
    np.testing.assert_allclose(z, [1.0 - 1.5 * math.sin(0.4), 4.0 + 1.5 * math.cos(0.4)], atol=1e-14)  # P_f = (1, 4)
    bw = fw._replace(f=-1.0, l=-1.5)
    z = np.asarray(T.focus_point(s, bw))
    np.testing.assert_allclose(z, [1.0 + 1.5 * math.sin(0.4), 2.0 - 1.5 * math.cos(0.4)], atol=1e-14)  # from P_b


def test_connection_by_hand_and_eq_8_7():
    s = _state(0.0, 0.0, 0.0, 0.1)
    fw = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
    c = T.connection(s, jnp.array([1.0 + 2.0, 2.0]), fw)  # P_f = (1, 0): w = (2, 2)
    assert float(c.phi) == pytest.approx(math.pi / 4, abs=1e-14) and float(c.d) == pytest.approx(
        2 * math.sqrt(2), abs=1e-14
    )
    c = T.connection(s, jnp.array([1.0 - 2.0, -2.0]), fw)  # w = (-2, -2): same line, behind -> d < 0
    assert float(c.phi) == pytest.approx(math.pi / 4, abs=1e-14) and float(c.d) == pytest.approx(
        -2 * math.sqrt(2), abs=1e-14
    )
    bw = fw._replace(f=-1.0, l=-1.0)
    c = T.connection(s, jnp.array([-3.0, 1.0]), bw)  # behind P_b = (0, 0): d > 0 for backward tracking
    assert float(c.phi) == pytest.approx(math.atan2(-1.0, 3.0), abs=1e-14) and float(c.d) == pytest.approx(
        math.sqrt(10), abs=1e-14
    )
    rng = np.random.default_rng(0)
    for f in (1.0, -1.0):
        p = T.FollowerParams(a=0.8, f=f, l=1.3 * f, p=1.7)
        for _ in range(20):
            s = _state(*rng.uniform(-3, 3, 2), rng.uniform(-math.pi, math.pi), rng.uniform(-G30, G30))
            zd = jnp.asarray(rng.uniform(-5, 5, 2))
            np.testing.assert_allclose(
                tracking_error_from_connection(s, T.connection(s, zd, p), p), T.tracking_error(s, zd, p), atol=1e-12
            )


@pytest.mark.parametrize("f", [1.0, -1.0])
def test_input_matrix_vs_finite_differences(f):
    rng = np.random.default_rng(1)
    p = T.FollowerParams(a=1.2, f=f, l=0.9 * f, p=-1.4)
    zero = jnp.zeros(())
    for _ in range(10):
        s = _state(*rng.uniform(-3, 3, 2), rng.uniform(-math.pi, math.pi), rng.uniform(-G30, G30))
        M = np.asarray(T.input_matrix(s.theta, s.gamma, p))
        for j, (v, w) in enumerate([(1.0, 0.0), (0.0, 1.0)]):
            r = T.follower_rhs(s, jnp.asarray(v), jnp.asarray(w), zero, zero, p)
            h = 1e-5
            zp = T.focus_point(T.Follower(*(a + h * b for a, b in zip(s, r))), p)
            zm = T.focus_point(T.Follower(*(a - h * b for a, b in zip(s, r))), p)
            np.testing.assert_allclose(M[:, j], (np.asarray(zp) - np.asarray(zm)) / (2 * h), atol=1e-8)
        assert float(T.input_det(s.gamma, p)) == pytest.approx(np.linalg.det(M), abs=1e-12)


def test_invertibility_bounds():
    g = jnp.linspace(-G30, G30, 201)
    for f, (lo, hi) in ((-1, T.p_bound(G30, -1)), (1, T.p_bound(G30, 1))):
        assert (lo, hi) == pytest.approx((-3.0, 3.0) if f < 0 else (-2.0, 4.0))
        for p in (lo + 1e-3, hi - 1e-3):
            assert float(jnp.min(jnp.abs(T.invertibility_factor(g, T.FollowerParams(f=float(f), p=p))))) > 0
        for p in (lo - 0.2, hi + 0.2):
            fac = T.invertibility_factor(g, T.FollowerParams(f=float(f), p=p))
            assert float(jnp.min(fac)) < 0 < float(jnp.max(fac))  # changes sign: singular inside the range


def test_leader_velocity_and_shapes():
    pv, pos = jax.jit(L.position_velocity), jax.jit(L.position)
    for ld in (
        L.line(heading=0.3),
        L.circle(radius=-4.0),
        L.sine(),
        L.lane_change(),
        L.line(depth=1.0),
        L.random_smooth(jax.random.PRNGKey(3)),
    ):
        for t in (0.3, 4.0, 7.7):
            z, zd = pv(ld, t)
            h = 1e-6
            fd = (np.asarray(pos(ld, t + h)) - np.asarray(pos(ld, t - h))) / (2 * h)
            np.testing.assert_allclose(zd, fd, atol=1e-7)
    c = L.circle(radius=4.0, speed=2.0)
    pts = np.asarray(jax.vmap(lambda t: L.position(c, t))(jnp.linspace(0, 12, 13)))
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1] - 4.0), 4.0, atol=1e-12)  # centre (0, R)
    _, v = pv(L.line(depth=1.0, period=10.0), 5.0)
    assert float(jnp.hypot(*v)) < 1e-12  # stop-and-go stops at T/2


def _numpy_rhs(
    s, v, w, a, br, bf
):  # docs/reproductions/vehicle-tracking.md §1 with slip (source convention), written independently
    x, y, th, g = s
    return [
        v * (math.cos(th) - math.tan(br) * math.sin(th)),
        v * (math.sin(th) + math.tan(br) * math.cos(th)),
        v / a * (math.tan(g - bf) - math.tan(br)),
        w,
    ]


def test_simulation_matches_solve_ivp():
    params = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
    ld = L.sine(amplitude=1.0, wavenumber=0.4)
    br, bf = math.radians(3), math.radians(-2)
    init = T.initial_state(ld, params, offset=(-0.5, 0.7), heading_error=0.3)
    batched = T.initial_states(
        T.stack([ld, ld]), T.stack([params, params]), np.array([[-0.5, 0.7], [0.0, 0.0]]), np.array([0.3, 0.0])
    )
    for k in ("x", "y", "theta", "gamma"):  # the batched placement is the single-run one
        assert float(getattr(batched, k)[0]) == pytest.approx(float(getattr(init, k)), abs=1e-14)
    on = T.unstack(batched, 1)  # no offset, no heading error: the focus point sits on z_d(0)
    np.testing.assert_allclose(T.tracking_error(on, L.position(ld, 0.0), params), 0.0, atol=1e-14)
    sc = T.scenario(params, ld, init=init, slip=constant_slip(br, bf))
    cfg = T.TrackConfig(dt=0.02, horizon=6.0, window=1.0, record=True)
    r = T.unstack(T.simulate_batch(T.stack([sc]), config=cfg), 0)
    tr = r.trajectory
    v, w = np.asarray(tr.v), np.asarray(tr.omega)
    s = np.array([float(getattr(init, k)) for k in ("x", "y", "theta", "gamma")])
    got = np.stack([np.asarray(getattr(tr.state, k)) for k in ("x", "y", "theta", "gamma")], axis=1)
    for k in range(cfg.n_steps):  # replay the held commands
        sol = solve_ivp(lambda t, y: _numpy_rhs(y, v[k], w[k], 1.0, br, bf), (0.0, cfg.dt), s, rtol=1e-11, atol=1e-12)
        s = sol.y[:, -1]
        np.testing.assert_allclose(got[k], s, atol=1e-8)  # RK4 local error O(dt^5) ~ 1e-9 here
    assert int(r.status) == 0


LINE = L.line(speed=1.0, heading=0.4)
ZD_CASES = [(f, l, p) for f in (1.0, -1.0) for l in (1.0, -1.0) for p in (-1.5, 1.5) if not (f > 0 and l < 0)]
# forward with l = -a is marginal (trace 0), left out


@pytest.fixture(scope="module")
def line_batch():
    """One jitted batch for every straight-line test (one compilation): per mode a small offset (no limit
    active), a large one, then the zero-dynamics cases, a singular case and a diverged one."""
    runs, names = [], []  # (params, offset, heading error)
    for f in (1.0, -1.0):
        prm = T.FollowerParams(a=1.0, f=f, l=1.0 * f, p=1.0 * f)
        runs += [(prm, (0.0, 0.05), 0.0), (prm, (-0.8, 1.0), 0.4)]
        names += [("small", f), ("big", f)]
    for f, l, p in ZD_CASES:
        runs.append((T.FollowerParams(f=f, l=0.5 * l if f > 0 else l, p=p), (0.0, 0.05), 0.0))
        names.append(("zd", (f, l, p)))
    runs.append(
        (T.FollowerParams(f=-1.0, l=-1.0, p=3.0), (-0.2, 0.3), 0.1)
    )  # gamma reaches pi/(2p) = gamma_max: det M = 0
    runs.append((T.FollowerParams(f=-1.0, l=-1.0, p=-1.0), (0.0, 60.0), 0.0))  # |z~0| > z_fail = 50 m
    names += [("singular", None), ("far", None)]
    inits = T.initial_states(
        T.stack([LINE] * len(runs)),
        T.stack([r[0] for r in runs]),
        np.array([r[1] for r in runs]),
        np.array([r[2] for r in runs]),
    )
    scs = [T.scenario(r[0], LINE, init=T.unstack(inits, i)) for i, r in enumerate(runs)]
    cfg = T.TrackConfig(dt=0.01, horizon=30.0, record=True)
    return names, scs, cfg, T.simulate_batch(T.stack(scs), config=cfg)


@pytest.mark.parametrize("f", [1.0, -1.0])
def test_straight_line_convergence_forward_backward(line_batch, f):
    names, _, _, r = line_batch
    for which in ("small", "big"):
        i = names.index((which, f))
        assert int(r.status[i]) == 0
        assert bool(r.metrics.converged[i]) and bool(r.metrics.phi_converged[i])
        assert float(r.metrics.final_error_norm[i]) < 1e-6
    i = names.index(("small", f))
    e = np.hypot(*np.moveaxis(np.asarray(r.trajectory.z_err[i]), -1, 0))
    t = np.asarray(r.trajectory.t[i])
    k = np.searchsorted(t, 2.0)
    assert e[k] / 0.05 == pytest.approx(math.exp(-t[k]), rel=2e-2)  # |z~| = |z~0| exp(-k t), k = 1/s
    v = np.asarray(r.trajectory.v[names.index(("big", f))])[-100:]
    np.testing.assert_allclose(v, f * 1.0, atol=1e-4)  # forward drives, backward reverses at the leader's speed


def test_zero_dynamics_prediction_matches_simulation(line_batch):
    names, scs, _, r = line_batch
    idx = [names.index(("zd", c)) for c in ZD_CASES]
    pred = [zero_dynamics_stable(1.0, f, scs[i].params) for i, (f, _, _) in zip(idx, ZD_CASES)]  # sigma = f
    conv = np.asarray(r.metrics.converged)[idx] & (np.asarray(r.metrics.max_abs_gamma)[idx] < 0.2)
    assert list(conv) == pred and any(pred) and not all(pred)
    A = zero_dynamics_matrix(2.0, -1.0, T.FollowerParams(a=1.0, f=-1.0, l=-2.0, p=-0.5))
    # trace = -sigma V (l + c_f a)/(a l p), det = V^2/(a l p)
    assert np.trace(A) == pytest.approx(2.0 * -2.0 / (-2.0 * -0.5)) and np.linalg.det(A) == pytest.approx(4.0)


def test_statuses_are_data_and_no_recompilation(line_batch):
    names, scs, cfg, r = line_batch
    st = np.asarray(r.status)
    assert st[names.index(("singular", None))] == T.TrackStatus.SINGULAR
    assert st[names.index(("far", None))] == T.TrackStatus.DIVERGED
    bad = [names.index(("singular", None)), names.index(("far", None))]
    assert np.isinf(np.asarray(r.metrics.iae)[bad]).all() and np.isfinite(np.asarray(r.fail_time)[bad]).all()
    from pfjax.tracking.simulate import _simulate_vmapped  # the jitted core: its compilation count

    n = _simulate_vmapped._cache_size()
    T.simulate_batch(T.stack(scs[::-1]), config=cfg)
    assert _simulate_vmapped._cache_size() == n


def test_lemma_geometry():
    df = sample_geometry(jax.random.PRNGKey(0), 500, G30, p=4.0)  # |p| > pi/(2 gamma_max) = 3
    on = df[df.kind == "on_focus"]
    inside = on.p_gamma.abs() < math.pi / 2
    assert inside.any() and (~inside).any()
    assert on.z_err.max() < 1e-12
    assert on[inside].phi_minus_pgamma.abs().max() < 1e-12
    np.testing.assert_allclose(on[~inside].phi_minus_pgamma.abs(), math.pi, atol=1e-12)  # counterexamples
    wd = df[df.kind == "wrong_distance"]
    assert wd[wd.p_gamma.abs() < math.pi / 2].phi_minus_pgamma.abs().max() < 1e-12 and wd.z_err.min() > 0.19
