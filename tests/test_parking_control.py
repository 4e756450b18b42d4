"""pfjax.parking controller and simulation: Lyapunov decrease under random switching, closed forms,
solve_ivp replay of a switched run, statuses, schedules, calibration, batching.

References: V = k₁ y² + tan²θ must be non-increasing (docs/reproductions/parking.md §2 Theorem) — checked along RK4 runs
with random direction/α switching every 0.1 s (tolerance 1e-10 relative: RK4's local error at
h = 0.02 s) and along the simulated cases; case A's first leg against the closed-form solution of
z₁'' + 8 z₁' + 32 z₁ = 0 (1e-7 m); a switched run (case D) replayed by scipy solve_ivp between the
logged switch times (rtol 1e-11), final pose to 1e-6.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from pfjax.parking.calibrate import A_F, calibrate_front, case_a_pose
from pfjax.parking.geometry import half_corners, quad_hits_map, robot_shape
from pfjax.parking.maps import PARALLEL, to_obstacle_map
from pfjax.parking.model import control_params, lyapunov, vector_field
from pfjax.parking.schedules import CASES, alpha_at, decode_bits, pad_schedule, parse_schedule, three_phase
from pfjax.parking.simulate import (
    ParkingConfig,
    Status,
    n_periods_for,
    run_batch,
    run_jit,
    run_params,
    run_recorded_jit,
    simulated_first_switch,
    stack_params,
)
from pfjax.sim.integrators import rk4_step

PMAP = to_obstacle_map(list(PARALLEL.values()))
FAR_MAP = to_obstacle_map([[(50.0, 50.0), (51.0, 50.0), (51.0, 51.0)]])


def test_lyapunov_nonincreasing_under_random_switching():
    p = control_params()
    h, n_sub, n_per = 0.02, 5, 400

    def leg(state, dir_alpha):
        d, a = dir_alpha

        def sub(s, _):
            s2 = rk4_step(lambda t, z: vector_field(z, d * p.speed, a, p), 0.0, s, h)
            return s2, lyapunov(s2[1], s2[2], p.k1)

        return jax.lax.scan(sub, state, None, length=n_sub)

    sim = jax.jit(lambda s0, dirs, alphas: jax.lax.scan(leg, s0, (dirs, alphas))[1].reshape(-1))
    rng = np.random.default_rng(0)
    for trial in range(6):
        s0 = jnp.array([rng.uniform(-1, 1), rng.uniform(-0.6, 0.6), rng.uniform(-1.2, 1.2), 0.0])
        dirs = jnp.asarray(rng.choice([-1.0, 1.0], n_per))
        alphas = jnp.asarray(np.exp(rng.uniform(np.log(0.05), np.log(10.0), n_per)))
        V = np.concatenate([[float(lyapunov(s0[1], s0[2], p.k1))], np.asarray(sim(s0, dirs, alphas))])
        dv = np.diff(V)
        assert np.all(dv <= 1e-10 * (1 + V[:-1])), (trial, dv.max())
        assert V[-1] < 0.9 * V[0]  # and it really decreases (random switching: little net travel)


def test_lyapunov_rate_matches_theory():
    """dV/dt = −2 α k₂ tan²θ |v₁| cos θ (dV/dτ = −2αk₂z₂² in the distance scale), by central differences."""
    p = control_params()
    s = jnp.array([0.1, 0.2, 0.4, 0.0])
    for d, a in [(1.0, 1.0), (-1.0, 0.5), (1.0, 8.0)]:
        rate = jax.jit(
            lambda s, d, a: jax.grad(lambda z: lyapunov(z[1], z[2], p.k1))(s) @ vector_field(s, d * p.speed, a, p)
        )
        expect = -2 * a * 8.0 * math.tan(0.4) ** 2 * 0.05 * math.cos(0.4)
        assert float(rate(s, d, a)) == pytest.approx(expect, rel=1e-12)


@pytest.mark.parametrize("case", ["A", "B", "C", "D"])
def test_lyapunov_along_simulated_cases(case):
    c = CASES[case]
    p = run_params(c["x0"], c["direction"], c["schedule"])
    cfg = ParkingConfig()
    r, tr = run_recorded_jit(p, PMAP, cfg, n_periods_for(cfg, 0.1))
    st = np.asarray(tr.state)[np.asarray(tr.running)]
    V = np.asarray(lyapunov(st[:, 1], st[:, 2], 32.0))
    assert np.all(np.diff(V) <= 1e-9)
    assert int(r.n_switches) >= 1


def test_case_a_first_leg_closed_form():
    cfg = ParkingConfig()
    r, tr = run_recorded_jit(run_params((-0.4, 0.5, 0.0), 1, (1.0,)), PMAP, cfg, n_periods_for(cfg, 0.1))
    t_sw = float(r.log_t[0])
    t, st = np.asarray(tr.t), np.asarray(tr.state)
    keep = t < t_sw
    for x, y, th in st[keep][::10, :3]:
        yc, thc = case_a_pose(x)
        assert abs(y - yc) < 2e-7 and abs(th - thc) < 2e-6


def test_switched_run_against_solve_ivp():
    c = CASES["D"]
    p = run_params(c["x0"], c["direction"], c["schedule"])
    r = run_jit(p, PMAP, ParkingConfig())
    assert Status(int(r.status)) == Status.CONVERGED
    times = [0.0] + [float(v) for v in np.asarray(r.log_t)[: int(r.n_switches)]] + [float(r.time)]
    s = np.array([*c["x0"][:2], 0.0])
    d = float(c["direction"])
    for k in range(len(times) - 1):
        a = float(pad_schedule(c["schedule"])[min(k, 7)])

        def f(_t, z, d=d, a=a):
            x, y, th = z
            v1 = 0.05 * d
            v2 = -v1 * math.cos(th) ** 3 * (32 * y + d * a * 8 * math.tan(th))
            return [v1 * math.cos(th), v1 * math.sin(th), v2]

        s = solve_ivp(f, (times[k], times[k + 1]), s, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
        d = -d
    np.testing.assert_allclose(np.asarray(r.final), s, atol=1e-6)


def test_substeps_converge():
    c = CASES["D"]
    p = run_params(c["x0"], c["direction"], c["schedule"])
    a, b = run_jit(p, PMAP, ParkingConfig(n_sub=2)), run_jit(p, PMAP, ParkingConfig(n_sub=10))
    assert int(a.n_switches) == int(b.n_switches)
    assert abs(float(a.time) - float(b.time)) <= 0.1
    np.testing.assert_allclose(
        np.asarray(a.log_pose)[: int(a.n_switches)], np.asarray(b.log_pose)[: int(b.n_switches)], atol=1e-4
    )


def test_statuses():
    # a corridor around (10, 0) 2 cm longer than the robot (body x_b in [a_f - 0.54, a_f], a_f = 0.1746):
    # it touches one end, reverses, touches the other after about 2 cm, ... reversing in place
    box = lambda x0, y0, x1, y1: [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    front, rear = 10.0 + A_F + 0.01, 10.0 + A_F - 0.54 - 0.01
    omap = to_obstacle_map([box(front, -1.0, 11.0, 1.0), box(9.0, -1.0, rear, 1.0), box(50.0, 50.0, 51.0, 51.0)])
    runs = [
        run_params((0.0, 0.3, 90.0), 1, (1.0,)),  # heading limit: the controller is undefined at θ = π/2
        run_params((-1.0, 0.3, 0.0), 1, (1.0,), control=control_params(speed=float("nan"))),  # non-finite
        run_params((-12.0, 0.3, 0.0), 1, (1.0,)),  # 200 s at 0.05 m/s is 10 m: cannot arrive -> timeout
        run_params((10.0, 0.0, 0.0), 1, (1.0,)),  # in the corridor: stuck
        run_params((10.0, 0.0, 0.0), 1, (1.0,), length=0.6),  # a longer robot starts touching both ends
    ]
    r = run_batch(stack_params(runs), omap, ParkingConfig())
    assert [Status(int(s)) for s in r.status] == [
        Status.HEADING_LIMIT,
        Status.NONFINITE,
        Status.TIMEOUT,
        Status.STUCK,
        Status.START_OVERLAP,
    ]
    assert float(r.time[2]) == pytest.approx(200.0, abs=1e-6)
    # stuck at the 4th reversal (legs of 1, 2, 2, 2 cm: less than 0.1 m in all), long before any cut-off
    legs = np.diff(np.concatenate([[0.0], np.asarray(r.log_t[3])[: int(r.n_switches[3])]])) * 0.05
    assert int(r.n_switches[3]) == 4 and legs.sum() < 0.1 and np.all(legs > 0.005), legs
    assert float(r.time[4]) == 0.0 and int(r.n_switches[4]) == 0
    # the search's cut-off: the same trap fails at the 11th switch instead (no progress test there)
    r = run_batch(stack_params(runs[3:4]), omap, ParkingConfig(max_switches=10, stuck_switches=None))
    assert Status(int(r.status[0])) == Status.TOO_MANY_SWITCHES and int(r.n_switches[0]) == 11


def test_schedules_drive_alpha():
    assert pad_schedule([1, 0.5]).tolist() == [1, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5]
    assert parse_schedule("1,0.5,8,1")[:5].tolist() == [1, 0.5, 8, 1, 1]
    for bad in ("1,-1", "a", "1,nan", "", ",".join(["1"] * 9)):
        with pytest.raises(ValueError):
            parse_schedule(bad)
    s = jnp.asarray(pad_schedule([1, 0.5, 8, 1]))
    assert [float(alpha_at(s, n)) for n in range(12)] == [1, 0.5, 8, 1] + [1] * 8
    np.testing.assert_allclose(np.asarray(three_phase(jnp.array([2.0]), jnp.array([3.0])))[0], [1, 2] + [3] * 6)
    c = CASES["D"]
    cfg = ParkingConfig()
    r, tr = run_recorded_jit(run_params(c["x0"], c["direction"], c["schedule"]), PMAP, cfg, n_periods_for(cfg, 0.1))
    t, alpha, run = np.asarray(tr.t), np.asarray(tr.alpha), np.asarray(tr.running)
    sw = np.asarray(r.log_t)[: int(r.n_switches)]
    n_before = np.searchsorted(sw, t, side="right")  # switches decided at or before the period's start
    expect = np.asarray(pad_schedule(c["schedule"]))[np.minimum(n_before, 7)]
    np.testing.assert_array_equal(alpha[run], expect[run])


def test_decode_bits():
    bits = np.zeros((3, 24), bool)
    bits[1] = True
    bits[2, :8] = [1, 0, 0, 0, 0, 0, 0, 0]  # ξ₁ = 128
    bits[2, 8:16] = [0, 0, 0, 0, 0, 0, 1, 1]  # ξ₂ = 3
    xs, a1, a2 = (np.asarray(v) for v in decode_bits(jnp.asarray(bits)))
    np.testing.assert_allclose(xs, [-1.2, -0.6, -1.2 + 0.6 * 128 / 255])
    np.testing.assert_allclose(a1, [10 / 256, 10.0, 10 * 4 / 256])
    np.testing.assert_allclose(a2, [10 / 256, 10.0, 10 / 256])


def test_calibration_of_front_reach():
    c = calibrate_front()
    assert c["obstacle"] == "kerb"
    # closed form of the leg against solve_ivp of the linear system in the x time scale
    sol = solve_ivp(lambda x, z: [z[1], -32 * z[0] - 8 * z[1]], (-0.4, 0.074), [0.5, 0.0], rtol=1e-12, atol=1e-14)
    y, th = case_a_pose(0.074)
    assert y == pytest.approx(sol.y[0, -1], abs=1e-9) and math.tan(th) == pytest.approx(sol.y[1, -1], abs=1e-9)
    assert abs(y - 0.047) < 5e-4  # the model reproduces the source's y at the switch
    # brute force: the smallest reach whose front half touches the map at that pose
    pose = jnp.array([0.074, y, th])
    hits = jax.jit(lambda f: quad_hits_map(half_corners(pose, robot_shape(f), 1.0), PMAP))
    grid = np.linspace(0.05, 0.4, 3501)
    first = grid[np.argmax([bool(hits(f)) for f in grid[::50]]) * 50 - 50 :][:101]
    touch = first[np.argmax([bool(hits(f)) for f in first])]
    assert touch == pytest.approx(A_F, abs=1.01e-4)
    sw = simulated_first_switch(A_F)
    assert math.hypot(sw["x"] - 0.074, sw["y"] - 0.047) < 0.0055  # one scanner period of travel (5 mm)


def test_batch_matches_single_and_does_not_recompile():
    items = [run_params(CASES[k]["x0"], CASES[k]["direction"], CASES[k]["schedule"]) for k in "ABCD"]
    batch = stack_params(items)
    rb = run_batch(batch, PMAP, ParkingConfig())
    for i, it in enumerate(items):
        r1 = run_jit(it, PMAP, ParkingConfig())
        assert int(rb.status[i]) == int(r1.status) and int(rb.n_switches[i]) == int(r1.n_switches)
        assert float(rb.time[i]) == pytest.approx(float(r1.time), abs=1e-9)
    size = run_batch._cache_size()
    run_batch(jax.tree_util.tree_map(lambda a: a * 1.0, batch), PMAP, ParkingConfig())
    assert run_batch._cache_size() == size


def test_a_pause_at_each_reversal_shifts_the_run_in_time():
    """Standing still ``pause`` s at each reversal (the source's experiments: 1 s) changes nothing but
    the clock: the same switch poses, every switch and the end later by pause times the switches before."""
    c = CASES["D"]
    a = run_jit(run_params(c["x0"], c["direction"], c["schedule"]), PMAP, ParkingConfig())
    b = run_jit(run_params(c["x0"], c["direction"], c["schedule"], pause=1.0), PMAP, ParkingConfig())
    n = int(a.n_switches)
    assert int(b.n_switches) == n and Status(int(b.status)) == Status.CONVERGED
    np.testing.assert_allclose(np.asarray(b.log_pose)[:n], np.asarray(a.log_pose)[:n], atol=1e-9)
    np.testing.assert_allclose(np.asarray(b.log_t)[:n], np.asarray(a.log_t)[:n] + np.arange(n), atol=1e-6)
    assert float(b.time) == pytest.approx(float(a.time) + n, abs=1e-6)
    assert float(b.distance) == pytest.approx(float(a.distance), abs=1e-9)


def test_decision_delay_and_detection_zone():
    """A scanner deciding on the pose one period old switches one period later; a detection zone of
    the whole rectangle reverses on contact behind the robot too."""
    c = CASES["A"]
    a = run_jit(run_params(c["x0"], c["direction"], c["schedule"]), PMAP, ParkingConfig())
    b = run_jit(run_params(c["x0"], c["direction"], c["schedule"], decision_delay=True), PMAP, ParkingConfig())
    assert float(b.log_t[0]) == pytest.approx(float(a.log_t[0]) + 0.1, abs=1e-9)
    from pfjax.parking.geometry import obstacle_ahead

    box = lambda x0, y0, x1, y1: [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    behind = to_obstacle_map([box(-1.0, -1.0, A_F - 0.54 + 0.01, 1.0)])  # 1 cm into the rear end
    pose = jnp.zeros(3)
    seen = {zone: bool(obstacle_ahead(pose, robot_shape(A_F, zone=zone), 1.0, behind)) for zone in (0.0, 0.54)}
    assert seen == {0.0: False, 0.54: True}  # travelling forward: only the whole rectangle sees it
    assert bool(obstacle_ahead(pose, robot_shape(A_F), -1.0, behind))  # backing: the rear half sees it
    axle = robot_shape(A_F, split=0.0)  # split at the axle: the rear zone is everything behind it
    near_axle = to_obstacle_map([box(-0.05, -1.0, -0.01, 1.0)])
    assert not bool(obstacle_ahead(pose, axle, 1.0, near_axle)) and bool(obstacle_ahead(pose, axle, -1.0, near_axle))


def test_case_sweep_counts_the_source_outcomes():
    from pfjax.parking.assumptions import case_sweep, sweep_summary

    grid = {
        "front": [A_F],
        "zone": ["middle", "whole"],
        "scan_period": [0.1],
        "decision_delay": [False],
        "lag": [False],
        "pause": [0.0],
    }
    df = case_sweep(PMAP, grid)
    assert len(df) == 2 * 4 and set(df.case) == {"A", "B", "C", "D"}
    mid = df[df.zone == "middle"].set_index("case")
    assert mid.loc["C", "status"] == "converged" and int(mid.loc["C", "switches"]) == 19
    s = sweep_summary(df)
    assert s["n_combinations"] == 2 and s["status_counts"]["A"]["converged"] >= 1
    assert all(c["zone"] == "whole" for c in s["all_four_reproduced"])
