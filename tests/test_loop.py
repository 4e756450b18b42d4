"""The simulation loop (:mod:`pfjax.sim.loop`): a third, tiny system (a 1-D linear ODE with a failure
threshold, one Euler step per sample) run through the loop against a hand-written NumPy loop; the
slip vehicle and the tracker run through the same loop; its status table is the enumerations'."""

from __future__ import annotations

import importlib
import math
import re
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax.sim import loop
from pfjax.sim.status import Status

DT, N, X_FAIL = 0.1, 30, 2.0


class Params(NamedTuple):
    x0: float  # initial state
    a: float  # 1/s, x' = a x + b
    b: float  # 1/s


class Out(NamedTuple):
    t: jax.Array  # s
    x: jax.Array  # the sample's state


def integrator(keep_last: bool) -> loop.System:
    """``x' = a x + b``, Euler steps of ``DT``; each sample checks its own state (check, then step):
    NONFINITE if not finite, DIVERGED if ``|x| > X_FAIL``. Metrics: ``sum x dt`` over the live samples
    and the number of samples the run entered live. ``aux``: the proposed next state (never frozen)."""

    def init(p):
        zero = jnp.zeros((), jnp.result_type(float))
        return loop.Start(state=p.x0 + zero, metrics=(zero, zero), zero=zero, aux=zero)

    def step(p, carry, k):
        x, t = carry.state, k * DT
        proposed = x + DT * (p.a * x + p.b)
        health = jnp.where(
            ~jnp.isfinite(x), int(Status.NONFINITE), jnp.where(jnp.abs(x) > X_FAIL, int(Status.DIVERGED), 0)
        )
        return loop.Sample(
            proposed, health.astype(jnp.int32), t, Out(t, x), aux=proposed, keep=(k == N - 1) if keep_last else None
        )

    def update(p, m, s, live, was_live):
        integral, entered = m
        return integral + jnp.where(live, s.out.x * DT, 0.0), entered + was_live

    return loop.System(
        init, step, update, record=lambda p, s, state: (s.out.t, state), finish=lambda p, r: r, no_failure=math.nan
    )


def numpy_loop(p: Params, keep_last: bool):
    """The same run written out by hand."""
    x, status, fail_time, integral, entered, aux = p.x0, 0, math.nan, 0.0, 0.0, 0.0
    ts, xs = [], []
    for k in range(N):
        t = k * DT
        proposed = x + DT * (p.a * x + p.b)
        health = 1 if not np.isfinite(x) else 2 if abs(x) > X_FAIL else 0
        entered += status == 0
        if status == 0 and health != 0:
            status, fail_time = health, t
        if status == 0:
            integral += x * DT
            if not (keep_last and k == N - 1):
                x = proposed
        aux = proposed
        ts.append(t)
        xs.append(x)
    return status, fail_time, x, aux, integral, entered, np.array(ts), np.array(xs)


CASES = [
    Params(1.0, -1.0, 0.0),  # decays: OK
    Params(1.0, 1.0, 0.0),  # grows past X_FAIL at sample 8: DIVERGED, frozen
    Params(0.5, 0.0, 1.0),  # ramp, reaches X_FAIL later
    Params(1.0, math.inf, 0.0),  # inf after one step: NONFINITE at sample 1
    Params(math.nan, 0.0, 0.0),  # NaN from the start: NONFINITE at sample 0
    Params(5.0, 0.0, 0.0),
]  # beyond the threshold at sample 0


@pytest.mark.parametrize("keep_last", [False, True])
def test_dummy_system_matches_a_numpy_loop(keep_last):
    ps = Params(*(np.array(v, float) for v in zip(*CASES)))
    run = jax.jit(jax.vmap(lambda p: loop.run(integrator(keep_last), p, N, record=True)))
    r = run(ps)
    assert isinstance(r, loop.Run) and r.status.dtype == jnp.int32
    for i, p in enumerate(CASES):
        status, fail_time, x, aux, integral, entered, ts, xs = numpy_loop(p, keep_last)
        assert int(r.status[i]) == status and bool(r.failed[i]) == (status != 0)
        np.testing.assert_array_equal(r.fail_time[i], fail_time)  # the failing sample's own time (NaN: none)
        np.testing.assert_allclose(r.state[i], x, rtol=1e-14)  # frozen at the failure
        np.testing.assert_allclose(r.aux[i], aux, rtol=1e-14)  # never frozen
        np.testing.assert_allclose(r.metrics[0][i], integral, rtol=1e-13)
        assert float(r.metrics[1][i]) == entered
        np.testing.assert_array_equal(r.records[0][i], ts)
        np.testing.assert_allclose(r.records[1][i], xs, rtol=1e-14)
    assert [int(s) for s in r.status] == [0, 2, 2, 1, 1, 2]


def test_recording_switch_scalar_inputs_and_checkpointing_change_nothing():
    p = Params(*(jnp.asarray(v, float) for v in (1.0, 0.5, 0.1)))
    ref = loop.run(integrator(False), p, N, record=True)
    off = loop.run(integrator(False), p, N, record=False)
    assert off.records is None
    np.testing.assert_array_equal(off.metrics, ref.metrics)
    opts = loop.run(
        integrator(False),
        p,
        N,
        record=False,
        scalar_inputs=True,
        checkpoint_policy=jax.checkpoint_policies.nothing_saveable,
    )
    np.testing.assert_array_equal(opts.metrics, ref.metrics)

    def loss(b, **kw):
        return loop.run(integrator(False), p._replace(b=b), N, record=False, **kw).metrics[0]

    g = jax.grad(loss)(0.1)
    h = 1e-6
    assert float(g) == pytest.approx((float(loss(0.1 + h)) - float(loss(0.1 - h))) / (2 * h), rel=1e-6)
    g2 = jax.grad(lambda b: loss(b, scalar_inputs=True, checkpoint_policy=jax.checkpoint_policies.nothing_saveable))(
        0.1
    )
    assert float(g2) == pytest.approx(float(g), rel=1e-12)


def test_checkpoint_segments_are_square_roots_of_the_samples_above_the_byte_threshold():
    """Per-sample checkpoints up to :data:`loop.SEGMENT_BYTES` of carry over all samples of the runs a
    device evaluates together; beyond, segments of ``ceil(sqrt(n))`` samples."""
    seg = loop.checkpoint_segment
    limit = loop.SEGMENT_BYTES
    assert seg(4001, 100, limit // (4001 * 100)) == 0
    assert seg(4001, 100, limit // (4001 * 100) + 1) == 64  # ceil(sqrt(4001)) = 64
    # a divisor of n from ceil(sqrt(n)) down to half of it: no last partial segment
    assert seg(4096, limit, 2) == 64 and seg(4097, limit, 2) == 65 and seg(2001, limit, 2) == 29
    assert seg(4095, limit, 2) == 63 and seg(2, limit, 2) == 2 and seg(38, limit, 2) == 7
    assert seg(10**9, limit, 0) == seg(10**9, limit, 1) == 0  # a run alone (placed batches: runs 0)


def test_the_benchmarks_reverse_mode_is_checkpointed_as_it_states(monkeypatch):
    """``pfjax bench`` reports reverse mode's segments from :func:`loop.carry_bytes` and the traced
    batch's runs per device; the loop, traced for the benchmark's gradient (2,000 float32 runs,
    4,001 samples), weighs the same carry (100 bytes) and runs, and decides the same 64 samples."""
    from pfjax.bench import problem as P
    from pfjax.controllers import state_feedback
    from pfjax.sim import SimConfig, simulate_batch
    from pfjax.sim.simulate import system

    sim = SimConfig(dt=P.DT, horizon=P.HORIZON, newton_iters=P.NEWTON_ITERS, record=False)
    k = len(jax.devices())
    seen = []
    real = loop.checkpoint_segment
    monkeypatch.setattr(loop, "checkpoint_segment", lambda *a: seen.append(a) or real(*a))
    loss = lambda K, s: jnp.sum(
        simulate_batch(s._replace(gains=s.gains._replace(K=K)), controller=state_feedback, config=sim).metrics.iae
    )
    with jax.enable_x64(False):  # as the benchmark's float32 runs (the tests run with x64 on)
        sc = P.scenarios(P.random_batch(2000, 0), np.float32)
        one = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype), sc)
        stated = (sim.n_steps + 1, loop.carry_bytes(system(state_feedback, sim), one), -(-2000 // k))
        jax.make_jaxpr(jax.grad(loss))(sc.gains.K, sc)  # traced, not compiled
    assert stated[:2] == (4001, 100) and seen == [stated]
    assert real(*stated) == 64  # over the threshold on up to 5 devices (more than 335 runs each)


@pytest.mark.parametrize("n_samples", [N, N - 1])  # 5 segments of 6; 4 of 6 and a tail of 5
def test_checkpoint_segments_change_no_value_record_or_gradient(n_samples):
    """The loop in checkpointed segments (forced by ``runs``) gives the per-sample loop's values,
    records and reverse-mode gradient; its program holds the segments' nested loop."""
    p = Params(*(jnp.asarray(v, float) for v in (1.0, 0.5, 0.1)))
    policy = jax.checkpoint_policies.nothing_saveable
    many = 10**9  # runs: any carry over that many runs is above the threshold

    def run(b, runs, record=True):
        return loop.run(
            integrator(False), p._replace(b=b), n_samples, record=record, checkpoint_policy=policy, runs=runs
        )

    assert loop.checkpoint_segment(n_samples, 8 * 6, many) in (6, 5)
    one, seg = jax.jit(lambda b: run(b, 1))(0.1), jax.jit(lambda b: run(b, many))(0.1)
    for a, b in zip(jax.tree_util.tree_leaves(one), jax.tree_util.tree_leaves(seg), strict=True):
        np.testing.assert_array_equal(a, b)
    assert seg.records[0].shape == (n_samples,)

    def loss(b, runs):
        out = run(b, runs, record=False)
        return out.metrics[0] + out.state

    scans = [str(jax.make_jaxpr(jax.grad(lambda b, r=r: loss(b, r)))(0.1)).count("scan[") for r in (1, many)]
    assert scans[0] < scans[1]  # the segments' outer and inner loops (and a tail)
    g1, g2 = (float(jax.jit(jax.grad(lambda b, r=r: loss(b, r)))(0.1)) for r in (1, many))
    h = 1e-6
    fd = (float(loss(0.1 + h, 1)) - float(loss(0.1 - h, 1))) / (2 * h)
    assert g1 == pytest.approx(fd, rel=1e-6) and g2 == pytest.approx(g1, rel=1e-13)


def test_the_carry_is_named():
    assert loop.LoopCarry._fields == ("state", "aux", "metrics", "status", "fail_time", "k")


def test_slip_vehicle_and_tracker_run_through_the_loop(monkeypatch):
    from pfjax import controllers as C
    from pfjax import tracking as T
    from pfjax.sim import SimConfig
    from pfjax.sim.scenario import paper_scenario
    from pfjax.tracking import leader as L

    slip = importlib.import_module("pfjax.sim.simulate")  # the modules (their packages export functions of that name)
    tracking = importlib.import_module("pfjax.tracking.simulate")

    calls = []
    real = loop.run

    def spy(system, inputs, n_samples, **kw):
        calls.append((system, n_samples, kw))
        return real(system, inputs, n_samples, **kw)

    monkeypatch.setattr(loop, "run", spy)
    cfg = SimConfig(dt=0.01, horizon=0.1, record=False)
    out = jax.eval_shape(
        lambda s: slip.simulate(C.state_feedback, s, cfg), paper_scenario("sine", C.state_feedback_params())
    )
    assert isinstance(out, slip.SimResult)
    params = T.FollowerParams(a=1.0, f=1.0, l=1.0, p=1.0)
    tcfg = T.TrackConfig(dt=0.02, horizon=0.2, window=0.1)
    out = jax.eval_shape(lambda s: tracking.simulate(s, tcfg), T.scenario(params, L.sine()))
    assert isinstance(out, tracking.TrackResult)
    assert [(isinstance(s, loop.System), n) for s, n, _ in calls] == [(True, cfg.n_steps + 1), (True, tcfg.n_steps)]
    assert calls[0][2]["scalar_inputs"] and calls[0][2]["checkpoint_policy"] is not None  # the slip's tuning kept
    assert math.isnan(calls[0][0].no_failure) and calls[1][0].no_failure == math.inf


def test_one_status_table_for_every_system():
    """The loop's docstring table lists every code of :class:`Status`, ``TrackStatus`` and the parking
    robot's ``Status`` under its name, and the codes the slip vehicle and the tracker share mean the
    same name."""
    from pfjax.parking.runs import Status as ParkingStatus
    from pfjax.tracking.simulate import TrackStatus

    rows = re.findall(r"^\s{4}(-?\d+)\s+(.+?)\s{2,}(.+?)\s{2,}(.+)$", loop.__doc__, re.MULTILINE)
    name = lambda cell: None if cell.strip() == "-" else cell.split(":")[0].split()[0]
    slip, track, park = ({int(r[0]): name(r[i]) for r in rows if name(r[i])} for i in (1, 2, 3))
    assert slip == {int(s): s.name.lower() for s in Status}
    assert set(track) == {int(s) for s in TrackStatus}
    assert all(TrackStatus(c).name == Status(c).name for c in track)
    assert park == {int(s): s.name.lower() for s in ParkingStatus}


# ------------------------------------------------------------------------ event-terminated runs
RUNNING, DONE, R, THRESHOLD = -1, 0, 0.8, 0.1  # x_{k+1} = R x_k; done once x < THRESHOLD


def decay() -> loop.System:
    """``x_{k+1} = R x_k``, stopping (status DONE) at the first sample whose new state is below
    ``THRESHOLD``; live code RUNNING; a run that starts below it starts DONE. Metrics: samples run."""

    def init(x0):
        zero = jnp.zeros((), jnp.result_type(float))
        status = jnp.where(x0 < THRESHOLD, DONE, RUNNING).astype(zero.dtype)
        return loop.Start(state=x0 + zero, metrics=zero, zero=zero, status=status)

    def step(x0, carry, k):
        new = R * carry.state
        return loop.Sample(new, jnp.where(new < THRESHOLD, DONE, RUNNING), (k + 1) * DT, new)

    return loop.System(
        init,
        step,
        update=lambda x0, m, s, live, was_live: m + was_live,
        record=lambda x0, s, state: s.out,
        finish=lambda x0, r: r,
        no_failure=math.nan,
        live=RUNNING,
    )


def test_event_terminated_mode_stops_each_run_at_its_closed_form_sample():
    """A run stops after k* = ceil(log(THRESHOLD / x0) / log R) samples (closed form), its state
    frozen before the stopping step (x0 R^(k*-1)) and its stop time k* DT (s); a run still above the
    threshold after n samples stops there, RUNNING; one that starts below it runs no sample. Exact
    up to rounding of the powers (rtol 1e-14: a handful of multiplications)."""
    x0 = np.array([1.0, 0.5, 0.2, 0.05, 3.0, 1e6])
    n = 20
    r = jax.jit(jax.vmap(lambda x: loop.run(decay(), x, n, record=False, until_done=True)))(x0)
    k_star = np.where(x0 < THRESHOLD, 0, np.ceil(np.log(THRESHOLD / x0) / np.log(R)))
    ran = np.minimum(k_star, n)
    np.testing.assert_array_equal(r.metrics, ran)  # samples entered live
    stopped = k_star <= n
    np.testing.assert_array_equal(r.status, np.where(stopped, DONE, RUNNING))
    np.testing.assert_array_equal(r.failed, stopped)
    # frozen at the stop: the state before the stopping step, x0 R^(k*-1); the stop time k* DT
    ok = stopped & (k_star > 0)
    np.testing.assert_allclose(r.state[ok], (x0 * R ** (k_star - 1))[ok], rtol=1e-14)
    np.testing.assert_allclose(r.fail_time[ok], (k_star * DT)[ok], rtol=1e-14)
    assert np.isnan(r.fail_time[~ok]).all()
    np.testing.assert_allclose(r.state[~stopped], (x0 * R**n)[~stopped], rtol=1e-12)
    # recorded: a scan over all n samples, the same outcome
    rec = jax.vmap(lambda x: loop.run(decay(), x, n, record=True, until_done=True))(x0)
    assert rec.records.shape == (len(x0), n)
    for a, b in zip(r[:6], rec[:6]):
        np.testing.assert_array_equal(a, b)
