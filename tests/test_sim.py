"""The simulator's run status, freezing after a failure, batching, record modes, slip profiles,
no-recompilation and float32.

One batch of eight line scenarios (one compile) mixes healthy runs, each kind of failure the
line allows and the three time-varying slip profiles; the circle (SINGULAR) and float32 runs
compile once more each.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.paths import circle, line, spline_through
from pfjax.sim import SimConfig, Status, simulate_batch, slip_profile, stack, unstack
from pfjax.sim.scenario import make_scenario

DEG = math.pi / 180
CFG = SimConfig(dt=0.01, horizon=6.0, d_fail=3.0)
NSEQ = 12  # every slip profile in the batch carries a sampled sequence of this length (one shape)
SEQ_DT = 0.5035  # no sample time t_k = k dt falls on a hold boundary j * SEQ_DT within the horizon
SEQ = np.random.default_rng(7).uniform(-5, 5, size=(NSEQ, 2)) * DEG
LINE_POSE = (1.0, 0.0, math.pi / 2)  # the source's line test start


def slip(**kw):
    """Every term present (zeros where unused), so runs of different kinds batch together."""
    kw.setdefault("seq", np.zeros((NSEQ, 2)))
    kw.setdefault("seq_dt", SEQ_DT)
    kw.setdefault("step_size", 0.0)
    kw.setdefault("sin_amp", 0.0)
    return slip_profile(**kw)


PAPER_SLIP = slip(constant=5 * DEG)
STEP = dict(constant=(0.0, 0.0), step_time=2.0, step_size=(5 * DEG, 3 * DEG))
SINE = dict(constant=(2 * DEG, -1 * DEG), sin_amp=(3 * DEG, 2 * DEG), sin_freq=(0.5, 1.3), sin_phase=(0.3, -1.0))


def sf(K=C.PAPER_K):
    return C.state_feedback_params(K=K)


def healthy():
    return make_scenario(line(), LINE_POSE, sf(), slip=PAPER_SLIP)


#: name -> scenario. Failures: positive gains with a 3 deg steering limit (turning radius 3.8 m,
#: so |d| passes d_fail = 3 m; with 30 deg the robot turns round and follows the line backwards,
#: bounded), a linearly unstable K = (1, -2) (closed loop det < 0), v = NaN, a line ending at 3 m.
ROWS = {
    "healthy": healthy(),
    "diverged_positive_K": make_scenario(line(), LINE_POSE, sf((2.7, 2.0)), slip=slip(), delta_max_deg=3.0),
    # v = NaN: no builder accepts it (make_scenario checks its inputs), but the simulator must turn
    # whatever it is given into a status
    "nonfinite": healthy()._replace(params=healthy().params._replace(v=jax.numpy.asarray(float("nan")))),
    "path_end": make_scenario(line(u_max=3.0), LINE_POSE, sf(), slip=PAPER_SLIP),
    "step_slip": make_scenario(line(), LINE_POSE, sf(), slip=slip(**STEP)),
    "sinusoid_slip": make_scenario(line(), LINE_POSE, sf(), slip=slip(**SINE)),
    "sampled_slip": make_scenario(line(), LINE_POSE, sf(), slip=slip(seq=SEQ)),
    "diverged_unstable_K": make_scenario(line(), LINE_POSE, sf((1.0, -2.0)), slip=slip()),
}
NAMES = list(ROWS)
FAILING = {
    "diverged_positive_K": Status.DIVERGED,
    "nonfinite": Status.NONFINITE,
    "path_end": Status.PATH_END,
    "diverged_unstable_K": Status.DIVERGED,
}


def run(rows, config=CFG):
    return jax.device_get(simulate_batch(stack(rows), controller=C.state_feedback, config=config))


def row(res, name):
    return jax.tree_util.tree_map(lambda a: a[NAMES.index(name)], res)


@pytest.fixture(scope="module")
def mixed():
    return run(list(ROWS.values()))


def test_statuses_of_the_mixed_batch(mixed):
    """Every run comes back (nothing dropped), each with its own status; healthy runs have no
    fail_time."""
    assert mixed.status.shape == (len(NAMES),)
    for name in NAMES:
        r = row(mixed, name)
        assert int(r.status) == FAILING.get(name, Status.OK), (name, int(r.status))
        assert np.isnan(r.fail_time) == (name not in FAILING)


def test_failure_times_are_the_first_failing_samples(mixed):
    """fail_time is the first sample at which the failure is visible in the recorded trajectory."""
    for name in ("diverged_positive_K", "diverged_unstable_K"):
        r = row(mixed, name)
        k = int(np.argmax(np.abs(r.trajectory.d) > CFG.d_fail))
        assert k > 0 and np.all(np.abs(r.trajectory.d[:k]) <= CFG.d_fail)
        assert r.fail_time == r.trajectory.t[k]
    r = row(mixed, "nonfinite")  # v = NaN: the pose is NaN after the first step
    assert r.fail_time == r.trajectory.t[1] and np.isfinite(r.trajectory.x[0]) and np.isnan(r.trajectory.x[1])
    r = row(mixed, "path_end")  # the closest point reaches u_max = 3 m of the line (s = u)
    k = int(round(r.fail_time / CFG.dt))
    assert r.trajectory.s[k] == pytest.approx(3.0, abs=1e-12) and r.trajectory.s[k - 1] < 3.0 - 1e-3


def test_failed_runs_are_frozen_and_their_metrics_finite(mixed):
    """From the failing sample on, the pose (and d, s) stays at its value there, and Final is that
    state; the metrics describe the run up to the failure: finite, except the steady-state errors
    and settling time, which are NaN by definition for a failed run.

    Final's pose is the frozen pose, bit for bit. Its d and s come from projecting that pose again
    after the loop (warm-started from the last closest point, in another compiled program than the
    loop's projection), so they equal the trajectory's to rounding: bit for bit with jax 0.10.2,
    an ulp apart with jax 0.10.0 (s = 3 against 3 + 4.4e-16 m)."""
    for name in FAILING:
        r = row(mixed, name)
        k = int(round(r.fail_time / CFG.dt))
        tr = r.trajectory
        for field in ("x", "y", "theta", "d", "s"):
            a = getattr(tr, field)
            np.testing.assert_array_equal(a[k:], np.full_like(a[k:], a[k]), err_msg=f"{name}.{field}")
            if field in ("x", "y", "theta"):
                np.testing.assert_array_equal(getattr(r.final, field), a[k], err_msg=f"{name}.{field}")
            else:  # float64, positions of a few metres: 1e-12 m is a few thousand ulps
                np.testing.assert_allclose(getattr(r.final, field), a[k], rtol=0, atol=1e-12, err_msg=f"{name}.{field}")
        m = r.metrics
        for field in ("iae", "ise", "itae", "max_abs_d", "overshoot", "steer_energy", "steer_tv", "sat_fraction"):
            assert np.isfinite(getattr(m, field)), (name, field, getattr(m, field))
        assert np.isnan(m.steady_abs_d) and np.isnan(m.steady_abs_theta_e_rad) and np.isnan(m.settling_time)
        assert m.max_abs_d <= CFG.d_fail


def test_healthy_runs_do_not_depend_on_their_batch_neighbours(mixed):
    """The same healthy scenarios in a batch without failing runs (same shapes, no recompile) give
    bit-identical results: a failure in one run never leaks into another."""
    alone = run([ROWS[n] if n not in FAILING else healthy() for n in NAMES])
    for name in NAMES:
        if name in FAILING:
            continue
        a, b = row(mixed, name), row(alone, name)
        for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
            np.testing.assert_array_equal(x, y, err_msg=name)


def test_line_parabola_and_sine_share_one_program():
    """The source's three paths are one shape (:class:`pfjax.paths.Graph`): one batch may mix them,
    every run's result is bit-identical to the same run in a batch of its own path (same program,
    lanes independent), and the three compile one program, not three."""
    from pfjax.paths import Graph, parabola, sine
    from pfjax.sim.simulate import _simulate_vmapped

    cfg = SimConfig(dt=0.01, horizon=3.0, d_fail=CFG.d_fail, record=False)
    rows = [
        make_scenario(line(), LINE_POSE, sf(), slip=PAPER_SLIP),
        make_scenario(parabola(), (-1.0, 1.3, -1.0), sf(), slip=PAPER_SLIP),
        make_scenario(sine(), (0.0, 0.3, math.pi / 4), sf(), slip=PAPER_SLIP),
    ]
    assert all(isinstance(r.path, Graph) for r in rows)
    before = _simulate_vmapped._cache_size()
    together = run(rows, cfg)
    alone = [run([r] * 3, cfg) for r in rows]
    assert _simulate_vmapped._cache_size() == before + 1
    assert np.all(np.asarray(together.status) == Status.OK)
    for i, res in enumerate(alone):
        for x, y in zip(jax.tree_util.tree_leaves(together), jax.tree_util.tree_leaves(res)):
            np.testing.assert_array_equal(np.asarray(x)[i], np.asarray(y)[0], err_msg=str(i))


def test_line_must_travel_towards_increasing_x():
    with pytest.raises(ValueError, match="heading"):
        line(heading=math.pi)
    with pytest.raises(ValueError, match="heading"):
        line(heading=-math.pi / 2)


def test_record_false_gives_the_same_metrics(mixed):
    """record=False (no trajectory, memory independent of the horizon) gives the same statuses and
    the same metrics, failure times and final states to rounding: the two are different compiled
    programs, and XLA may fuse (and contract multiply-adds) differently in each, so a metric may
    differ in its last bit (seen: 1 ulp in 2 of 8 runs' steady-state error)."""
    lean = run(list(ROWS.values()), SimConfig(dt=CFG.dt, horizon=CFG.horizon, d_fail=CFG.d_fail, record=False))
    assert lean.trajectory is None
    np.testing.assert_array_equal(mixed.status, lean.status)
    for part in ("metrics", "fail_time", "final"):
        for x, y in zip(
            jax.tree_util.tree_leaves(getattr(mixed, part)), jax.tree_util.tree_leaves(getattr(lean, part))
        ):
            np.testing.assert_allclose(x, y, rtol=1e-14, atol=1e-15, err_msg=part)


def test_time_varying_slip_profiles_in_the_trajectory(mixed):
    """The recorded beta_r, beta_f equal the profiles' formulas at the sample times (step at 2 s,
    sinusoid mean + amp sin(2 pi f t + phase), zero-order hold of the sampled sequence)."""
    t = row(mixed, "healthy").trajectory.t
    np.testing.assert_allclose(t, np.arange(t.size) * CFG.dt, atol=1e-12)
    expect = {
        "healthy": np.full((t.size, 2), 5 * DEG),
        "step_slip": np.where((t >= 2.0)[:, None], [5 * DEG, 3 * DEG], 0.0),
        "sinusoid_slip": np.asarray(SINE["constant"])
        + np.asarray(SINE["sin_amp"])
        * np.sin(2 * np.pi * np.outer(t, SINE["sin_freq"]) + np.asarray(SINE["sin_phase"])),
        "sampled_slip": SEQ[np.minimum((t / SEQ_DT).astype(int), NSEQ - 1)],
    }
    for name, e in expect.items():
        tr = row(mixed, name).trajectory
        np.testing.assert_allclose(np.c_[tr.beta_r, tr.beta_f], e, atol=1e-15, err_msg=name)
        assert int(row(mixed, name).status) == Status.OK
    # The step is really taken at 2 s: 0 before, the new value from the sample at 2 s on.
    tr = row(mixed, "step_slip").trajectory
    k = int(round(2.0 / CFG.dt))
    assert tr.beta_r[k - 1] == 0.0 and tr.beta_r[k] == pytest.approx(5 * DEG, abs=1e-15)


def test_no_recompilation_for_new_values(mixed):
    """New values with the same shapes (gains, poses, speeds, slip, path parameters) reuse the
    compiled simulate_batch: its jit cache does not grow."""
    rows = [
        make_scenario(
            line(x0=0.3, heading=0.7),
            (0.5, -0.2, 0.1 * i),
            sf((-1.0 - i, -1.5)),
            slip=slip(constant=i * DEG, sin_amp=1 * DEG, sin_freq=0.2, seq=SEQ),
            v=0.5 + 0.1 * i,
        )
        for i in range(len(NAMES))
    ]
    run(list(ROWS.values()))  # the fixture's compile is in the cache
    from pfjax.sim.simulate import _simulate_vmapped  # the jitted core: its compilation count

    before = _simulate_vmapped._cache_size()
    r = run(rows)
    run([ROWS[n] for n in reversed(NAMES)])
    assert _simulate_vmapped._cache_size() == before
    assert np.all(r.status == Status.OK)  # the values really changed the runs
    assert not np.allclose(r.final.x, row(mixed, "healthy").final.x)


def test_absent_slip_terms_cost_nothing_and_change_nothing():
    """``constant_slip`` carries only the constant term (the others are None, not zeros), and gives
    exactly the runs of the same profile with every term present at zero; profiles with different
    terms present refuse to stack, with a message that says what to do."""
    from pfjax.sim import constant_slip, slip_at

    lean = constant_slip(5 * DEG, -3 * DEG)
    assert all(getattr(lean, f) is None for f in lean._fields if f != "constant")
    full = slip_profile(
        constant=(5 * DEG, -3 * DEG), step_size=0.0, sin_amp=0.0, seq=np.zeros((NSEQ, 2)), seq_dt=SEQ_DT
    )
    for t in (0.0, 1.3, 7.0):
        assert [float(b) for b in slip_at(lean, t)] == [float(b) for b in slip_at(full, t)]
    cfg = SimConfig(dt=CFG.dt, horizon=2.0, record=False)
    a, b = (run([make_scenario(line(), LINE_POSE, sf(), slip=p)], cfg) for p in (lean, full))
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_array_equal(x, y)
    with pytest.raises(ValueError, match="same terms"):
        stack([make_scenario(line(), LINE_POSE, sf(), slip=p) for p in (lean, full)])


def test_singular_at_the_centre_of_a_circle():
    """SINGULAR (1 - kappa d <= 1e-6) at the exact centre of a circle.

    With the true closest point, 1 - kappa d = r / R >= 0 on a circle (and >= 0 at any local
    minimum of the distance to any path), so the Frenet singularity is only reached on a centre of
    curvature itself: here a robot driven straight (K = 0, no slip) from (0, -0.5) through the
    centre of the unit circle reaches it at t = 0.5 s.

    A robot passing 5 cm from the centre stays OK, but while it is within R/4 of the centre
    (t in 0.26..0.74 s) the warm-started projection lags the fast-moving closest point: the
    Newton safeguard falls back to Gauss-Newton where g' < |p'|^2 / 4 (i.e. 1 - kappa d < 1/4),
    which converges only linearly there. d is then measured against a point that is not the
    closest, d = R - r cos(dphi) >= R - r (an over-estimate, < 2 cm here); outside that zone d is
    exact (R - r, inside the CCW circle is left, positive)."""
    path = circle(radius=1.0, cx=0.0, cy=0.0)
    g = sf((0.0, 0.0))
    rows = [make_scenario(path, (0.0, -0.5, math.pi / 2), g), make_scenario(path, (0.05, -0.5, math.pi / 2), g)]
    r = jax.device_get(simulate_batch(stack(rows), controller=C.state_feedback, config=SimConfig(dt=0.01, horizon=2.0)))
    np.testing.assert_array_equal(r.status, [Status.SINGULAR, Status.OK])
    assert r.fail_time[0] == pytest.approx(0.5, abs=1e-12)
    tr = jax.tree_util.tree_map(lambda a: a[1], r.trajectory)
    rad = np.hypot(tr.x, tr.y)
    assert rad.min() == pytest.approx(0.05, abs=1e-9)
    outside = rad > 0.25 + 1e-3
    np.testing.assert_allclose(tr.d[outside], 1.0 - rad[outside], atol=1e-9)
    err = tr.d - (1.0 - rad)
    assert np.all(err > -1e-12) and err.max() < 0.02
    # The closest point moved to the far side: theta_e against the tangent at the robot's polar
    # angle, +84 deg before the pass, -88 deg after it.
    te_ref = np.angle(np.exp(1j * (tr.theta - np.arctan2(tr.y, tr.x) - math.pi / 2)))
    np.testing.assert_allclose(tr.theta_e[outside], te_ref[outside], atol=1e-9)
    assert tr.theta_e[0] > 1.4 and tr.theta_e[-1] < -1.5


def test_short_spline_ends_with_path_end():
    """A robot following a 4.4 m spline reaches its end: PATH_END, at about the time the arc
    length runs out (v = 1 m/s, tracking from on the path), frozen there."""
    wp = np.array([[0.0, 0.0], [1.0, 0.3], [2.0, 0.1], [3.0, -0.2], [4.3, 0.0]])
    path = spline_through(wp)
    rows = [make_scenario(path, (0.5, 0.0, 0.3), C.state_feedback_params(), slip=slip_profile(constant=0.0))]
    r = jax.device_get(simulate_batch(stack(rows), controller=C.state_feedback, config=SimConfig(dt=0.01, horizon=8.0)))
    assert int(r.status[0]) == Status.PATH_END
    s = r.trajectory.s[0]
    k = int(round(r.fail_time[0] / 0.01))
    total = float(path.u_max)  # chord length, <= arc length
    assert s[k] > total and 3.5 < r.fail_time[0] < 5.5
    np.testing.assert_array_equal(r.trajectory.x[0, k:], r.trajectory.x[0, k])


@pytest.mark.filterwarnings("ignore:Explicitly requested dtype")
def test_float32_agrees_with_float64():
    """With x64 disabled the whole run is float32 and the final lateral error on the line test
    (paper gains and slip, 6 s) agrees with float64 to 1e-4 m: float32 rounding of the ~5 m
    positions is ~5e-7 m per step and the stable loop damps it rather than accumulating it."""
    d64 = float(row(run(list(ROWS.values())), "healthy").final.d)
    with jax.enable_x64(False):
        sc = make_scenario(line(), LINE_POSE, sf(), slip=slip(constant=5 * DEG))
        r = jax.device_get(simulate_batch(stack([sc]), controller=C.state_feedback, config=CFG))
    assert r.trajectory.x.dtype == np.float32 and r.final.d.dtype == np.float32
    assert int(r.status[0]) == Status.OK
    assert abs(float(r.final.d[0]) - d64) < 1e-4, (float(r.final.d[0]), d64)
    assert abs(d64) > 1e-3  # the steady slip offset, not a trivially zero error


def test_stack_builds_numpy_leaves_and_compiles_nothing():
    """``stack`` is host-side NumPy (one array per leaf, each item's values in order), so building a
    batch compiles no program (``jnp.stack`` compiled one per leaf shape and item count)."""
    items = [make_scenario(line(), LINE_POSE, sf(), slip=slip(constant=b * DEG)) for b in (1.0, 2.0, 3.0)]
    events = []
    listener = lambda name, secs, **kw: (
        events.append(name) if name == "/jax/core/compile/backend_compile_duration" else None
    )
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        batch = stack(items)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert events == []
    for leaf, *per_item in zip(jax.tree_util.tree_leaves(batch), *(jax.tree_util.tree_leaves(i) for i in items)):
        assert isinstance(leaf, np.ndarray) and leaf.shape[0] == 3
        for k, x in enumerate(per_item):
            np.testing.assert_array_equal(leaf[k], np.asarray(x))
    with pytest.raises(ValueError, match="item 1 has a different structure"):
        stack([items[0], make_scenario(line(), LINE_POSE, sf(), slip=slip_profile(constant=DEG))])


def test_unstack_is_one_gather_and_checks_the_index(mixed):
    """unstack gives what indexing every leaf gives (device arrays: one jitted gather; NumPy leaves
    stay NumPy), negative indices count from the end, and an index past the batch is an error
    (a traced gather would clamp it silently)."""
    on_device = jax.device_put(mixed)
    for i in (0, 3, -1):
        got, want = unstack(on_device, i), row(mixed, NAMES[i])
        assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(want)
        for x, y in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(want)):
            assert isinstance(x, jax.Array)
            np.testing.assert_array_equal(np.asarray(x), y)
    host = unstack(mixed, 2)
    assert not any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(host))
    for bad in (len(NAMES), np.int64(-len(NAMES) - 1)):
        with pytest.raises(IndexError, match="out of range"):
            unstack(on_device, bad)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_switching_instants_do_not_depend_on_rounding(dtype):
    """A time a few ulps before a sample boundary or the step time (a rounded RK4 stage time at the
    instant) gets the new value; a time well inside the previous interval keeps the old one."""
    from pfjax.sim import slip_at

    seq = np.arange(8.0)[:, None] * np.array([[1.0, -1.0]])
    prof = jax.tree_util.tree_map(
        lambda a: np.asarray(a, dtype), slip_profile(seq=seq, seq_dt=0.05, step_size=(10.0, 10.0), step_time=0.15)
    )
    for j in range(1, 8):
        edge = dtype(j) * dtype(0.05)
        for t in (edge, np.nextafter(edge, dtype(0)), np.nextafter(np.nextafter(edge, dtype(0)), dtype(0))):
            step = 10.0 * (j >= 3)
            assert float(slip_at(prof, t)[0]) == j + step, (j, t)
        inside = edge - dtype(0.001)
        assert float(slip_at(prof, inside)[0]) == j - 1 + 10.0 * (j - 1 >= 3), (j, inside)


@pytest.mark.parametrize("control_every", [1, 3, None])
def test_metrics_and_final_state_agree_with_the_trajectory(control_every):
    """Samples 0 and N are iterations of the simulator's one loop (no separate first and last
    sample): with sensor noise and a steering-rate limit, the metrics recomputed in NumPy from the
    recorded samples (trapezoid rule, total variation of the applied steering from sample 0,
    overshoot against the sign of d(0)) and the final state (the last sample) agree to rounding."""
    from pfjax.sim import SensorNoise

    sc = make_scenario(line(), (1.0, 0.3, math.pi / 2 + 0.4), sf(), slip=PAPER_SLIP)
    sc = sc._replace(
        params=sc.params._replace(delta_rate_max=jax.numpy.asarray(0.8)),
        noise=SensorNoise(jax.numpy.asarray(0.01), jax.numpy.asarray(0.5 * DEG), jax.random.PRNGKey(3)),
    )
    cfg = SimConfig(dt=0.01, horizon=4.0, d_fail=3.0, control_every=control_every)
    res = run([sc, sc], cfg)
    m, tr, fin = (
        jax.tree_util.tree_map(lambda a: np.asarray(a)[0], x) for x in (res.metrics, res.trajectory, res.final)
    )
    assert int(res.status[0]) == Status.OK and tr.t.shape == (cfg.n_steps + 1,)
    w = np.full(tr.t.shape, cfg.dt)
    w[[0, -1]] *= 0.5
    np.testing.assert_allclose(m.iae, np.sum(w * np.abs(tr.d)), rtol=1e-12)
    np.testing.assert_allclose(m.itae, np.sum(w * tr.t * np.abs(tr.d)), rtol=1e-12)
    np.testing.assert_allclose(m.steer_energy, np.sum(w * tr.delta**2), rtol=1e-12)
    np.testing.assert_allclose(m.steer_tv, np.sum(np.abs(np.diff(tr.delta))), rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(m.overshoot, max(0.0, np.max(-np.sign(tr.d[0]) * tr.d)), rtol=1e-12, atol=1e-15)
    assert tr.t[-1] == cfg.horizon
    if control_every is not None:  # rate-limited from 0 at sample 0; the last sample holds step N-1's command
        assert np.abs(tr.delta[0]) <= 0.8 * cfg.dt and np.all(np.abs(np.diff(tr.delta)) <= 0.8 * cfg.dt * (1 + 1e-9))
        assert tr.delta[-1] == tr.delta[-2] and tr.delta_cmd[-1] == tr.delta_cmd[-2]
    for field in ("x", "y", "theta", "delta"):  # the state itself: the same numbers
        assert getattr(fin, field) == getattr(tr, field)[-1], field
    # The final measurement is evaluated again after the loop, from the same pose and parameter but
    # in its own fused kernels (XLA may contract multiply-adds differently there): equal to rounding.
    for field in ("d", "theta_e", "s"):
        np.testing.assert_allclose(getattr(fin, field), getattr(tr, field)[-1], rtol=1e-14, atol=1e-15, err_msg=field)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_first_failure_keeps_the_first_failure_and_its_time(dtype):
    """The status helper of both car-like simulators: over a sequence of per-sample statuses the
    first failure wins and keeps its time; the float status code is exact."""
    import jax.numpy as jnp

    from pfjax.sim.status import first_failure

    now = np.array([[0, 0, 2, 1, 0], [0, 0, 0, 0, 0], [4, 3, 0, 0, 0], [0, 0, 0, 0, 1]], np.int32)
    t = np.arange(5, dtype=dtype) * dtype(0.1)

    def scan(now_row):
        def body(c, x):
            return first_failure(*c, x[0], x[1]), None

        return jax.lax.scan(body, (jnp.zeros((), dtype), jnp.asarray(np.nan, dtype)), (now_row, t))[0]

    status, fail_time = jax.jit(jax.vmap(scan))(now)
    assert status.dtype == dtype and fail_time.dtype == dtype
    np.testing.assert_array_equal(np.asarray(status), [2, 0, 4, 1])
    np.testing.assert_array_equal(np.asarray(fail_time), [t[2], np.nan, t[0], t[4]])


@pytest.mark.parametrize("model", ["slip", "tracking"])
def test_status_checks_are_compiled_once(model):
    """XLA's CPU backend recomputes a cheap value in every kernel that reads it; the run's status
    (read by everything a step freezes or accumulates) is computed once
    (:func:`pfjax.sim.status.first_failure`), so the status checks, marked here by a distinctive
    failure threshold, appear in one fused kernel of the compiled program (before: 2 in the slip
    simulator, whose failure time repeated them, and 14 in the tracking simulator)."""
    import re

    if jax.default_backend() != "cpu":
        pytest.skip("a CPU code-generation check")
    if model == "slip":
        from pfjax.sim.simulate import _simulate_vmapped

        cfg = SimConfig(dt=0.01, horizon=0.5, d_fail=7.8125, record=False)
        lowered = _simulate_vmapped.lower(stack([healthy()] * 8), controller=C.state_feedback, config=cfg)
    else:
        from pfjax import tracking as T
        from pfjax.tracking import leader as L
        from pfjax.tracking.simulate import _simulate_vmapped

        params = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
        sc = T.scenario(params, L.sine(), init=T.initial_state(L.sine(), params))
        cfg = T.TrackConfig(dt=0.02, horizon=0.5, window=0.1, z_fail=7.8125)
        lowered = _simulate_vmapped.lower(stack([sc] * 8), config=cfg)
    fused = [c for c in re.split(r"\n(?=\S)", lowered.compile().as_text()) if c.lstrip("%").startswith("fused")]
    marked = [c.split()[0] for c in fused if re.search(r"constant\(7\.8125\)", c)]
    assert len(marked) == 1, marked


def test_batched_programs_are_named_after_their_simulators():
    """pfjax.sim.batch builds each simulator's batched program: it is registered (for the compiler
    audit) and compiled under its simulator module's name, not the builder's."""
    from importlib import import_module

    from pfjax.numerics import compiler

    mods = [import_module(f"pfjax.{m}") for m in ("sim.simulate", "sim.dynamic", "tracking.simulate")]
    assert {f"{m.__name__}._simulate_vmapped" for m in mods} <= compiler.PROGRAMS
    assert not any(p.startswith("pfjax.sim.batch.") for p in compiler.PROGRAMS)
    cfg = SimConfig(dt=0.01, horizon=0.05, record=False)
    text = mods[0]._simulate_vmapped.lower(stack([healthy()] * 2), controller=C.state_feedback, config=cfg).as_text()
    assert "jit__simulate_vmapped" in text


def test_a_start_beyond_the_paths_end_is_path_end_not_a_divergence():
    """The closest point held at the domain's end: ``d`` is the distance to that end point, not a
    lateral error, so the run ends as path_end at t = 0 (it read as diverged, d = 72 m)."""
    import pfjax

    sc = pfjax.scenarios("sine", n=2, start_along_m=np.array([3.0, 200.0]))
    r = pfjax.simulate(sc, "paper_k", config={"horizon": 1.0})
    assert r.table["status"].tolist() == ["ok", "path_end"]
    assert r.table["fail_time"].iloc[1] == 0.0
