"""The parking robot on the one loop (:mod:`pfjax.parking.period` through :func:`pfjax.sim.loop.run`
with ``until_done``): bit-identical to a ``lax.while_loop`` written out here over the same period
(its own period counter and integer status, the loop's structure before parking joined it), on the
cases, a Monte Carlo batch and a GA population; and against stored reference results of that
structure (``tests/data/parking_reference.json``, computed by jax 0.10.2 on a 2-core AMD EPYC with
AVX-512, where the comparison is exact: integers exact, times and poses to rtol 1e-12 so that another
CPU's vector code, whose last bits may differ, passes too)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import lax

from pfjax.parking import period
from pfjax.parking.maps import GARAGE, PARALLEL, to_obstacle_map
from pfjax.parking.montecarlo import Scatter, sample
from pfjax.parking.schedules import CASES, GARAGE_START, decode_bits
from pfjax.parking.simulate import (
    ParkingConfig,
    Status,
    run,
    run_batch,
    run_jit,
    run_params,
    run_recorded,
    stack_params,
)
from pfjax.parking.switch_search import SEARCH_CONFIG, batch_params, garage_base

PMAP, GMAP = to_obstacle_map(list(PARALLEL.values())), to_obstacle_map(list(GARAGE.values()))
REFERENCE = Path(__file__).parent / "data" / "parking_reference.json"


class OwnCarry(NamedTuple):
    k: jax.Array  # periods done
    status: jax.Array  # int Status
    c: period.Carry


def own_while_loop(p, omap, cfg: ParkingConfig):
    """One run as a ``lax.while_loop`` of its own over decide + integrate, integer status."""
    start = period.start(omap, cfg, p)

    def body(o: OwnCarry) -> OwnCarry:
        c, status = period.decide(o.c, o.status, p, omap, cfg)
        c, status = period.integrate(c, status, p, cfg)
        return OwnCarry(o.k + 1, status, c)

    o = lax.while_loop(
        lambda o: (o.status == Status.RUNNING) & (o.k < cfg.max_samples),
        body,
        OwnCarry(jnp.asarray(0), start.status.astype(int), start.aux),
    )
    status = jnp.where(o.status == Status.RUNNING, int(Status.TIMEOUT), o.status)
    return status, o.c.t, o.c.state[:3], o.c.n_switches, o.c.distance, o.c.log_t, o.c.log_pose, o.c.log_cause


def _assert_identical(r, ref):
    got = (r.status, r.time, r.final, r.n_switches, r.distance, r.log_t, r.log_pose, r.log_cause)
    for name, a, b in zip(
        ("status", "time", "final", "n_switches", "distance", "log_t", "log_pose", "log_cause"), got, ref
    ):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=name)
        assert np.asarray(a).dtype == np.asarray(b).dtype, name


def _cases():
    items = [
        run_params(c["x0"], c["direction"], c["schedule"], **kw)
        for c in CASES.values()
        for kw in ({}, {"pause": 1.0}, {"decision_delay": True})
    ]
    return stack_params(items)


@pytest.mark.parametrize("which", ["cases", "monte carlo", "ga population"])
def test_the_loop_is_bit_identical_to_a_while_loop_of_its_own(which):
    if which == "cases":
        ps, omap, cfg = _cases(), PMAP, ParkingConfig()
    elif which == "monte carlo":
        ps, omap, cfg = sample(jax.random.PRNGKey(0), 16, garage_base(), Scatter()), GMAP, ParkingConfig()
    else:
        bits = jax.random.bernoulli(jax.random.PRNGKey(1), 0.5, (12, 24)).astype(int)
        ps, omap, cfg = batch_params(garage_base(), *decode_bits(bits)), GMAP, SEARCH_CONFIG
    new = jax.jit(jax.vmap(lambda p: run(p, omap, cfg)))(ps)
    ref = jax.jit(jax.vmap(lambda p: own_while_loop(p, omap, cfg)))(ps)
    _assert_identical(new, ref)
    assert set(np.asarray(new.status).tolist()) - {int(Status.TIMEOUT)}  # the runs stop at events


def test_the_recorded_run_stays_a_scan_with_the_same_outcome():
    p = run_params(*(CASES["D"][k] for k in ("x0", "direction", "schedule")))
    r, traj = jax.jit(run_recorded, static_argnums=(2, 3))(p, PMAP, ParkingConfig(), 600)
    _assert_identical(r, own_while_loop(p, PMAP, ParkingConfig()))
    assert traj.t.shape == (600,) and traj.state.shape == (600, 4)
    stopped = int(np.argmin(np.asarray(traj.running)))  # the first period that starts stopped
    assert float(traj.t[stopped]) == float(r.time) and np.all(~np.asarray(traj.running)[stopped:])


def test_stored_reference_results():
    ref = json.loads(REFERENCE.read_text())
    for name, want in ref.items():
        if name.startswith("monte carlo"):
            ps, omap = sample(jax.random.PRNGKey(0), 8, run_params(GARAGE_START, 1, (1.0,), xs=-0.9), Scatter()), GMAP
            r = run_batch(ps, omap, ParkingConfig())
        else:
            case, _, variant = name.partition(" ")
            if case == "garage":
                p, omap = run_params(GARAGE_START, 1, (1.0,), xs=-0.9), GMAP
            else:
                kw = {"pause": 1.0} if "pause" in variant else {"decision_delay": True} if variant else {}
                p, omap = run_params(*(CASES[case][k] for k in ("x0", "direction", "schedule")), **kw), PMAP
            r = run_jit(p, omap, ParkingConfig())
            np.testing.assert_allclose(
                np.asarray(r.log_t)[: int(r.n_switches)], want["log_t"], rtol=1e-12, err_msg=name
            )
        np.testing.assert_array_equal(np.asarray(r.status), want["status"], err_msg=name)
        np.testing.assert_array_equal(np.asarray(r.n_switches), want["n_switches"], err_msg=name)
        for key in ("time", "final", "distance"):
            np.testing.assert_allclose(
                np.asarray(getattr(r, key)), want[key], rtol=1e-12, atol=1e-15, err_msg=f"{name} {key}"
            )


def test_a_parking_run_is_the_period_system_on_the_one_loop(monkeypatch):
    from pfjax.parking import simulate
    from pfjax.sim import loop

    calls = []
    real = loop.run
    monkeypatch.setattr(
        loop, "run", lambda system, p, n, **kw: calls.append((system, n, kw)) or real(system, p, n, **kw)
    )
    p = run_params(*(CASES["A"][k] for k in ("x0", "direction", "schedule")))
    out = jax.eval_shape(lambda p: simulate.run(p, PMAP, ParkingConfig(max_samples=300)), p)
    rec = jax.eval_shape(lambda p: simulate.run_recorded(p, PMAP, ParkingConfig(), 40), p)
    assert out.status.shape == () and rec[1].t.shape == (40,)
    assert [(n, kw) for _, n, kw in calls] == [
        (300, {"record": False, "until_done": True}),
        (40, {"record": True, "until_done": True}),
    ]
    assert all(s.live == Status.RUNNING for s, _, _ in calls)
