"""The falsifier (pfjax.falsification): known worst cases on a linear loop found by brute force, the
paper's sine case against random search at the same number of rollouts, bounds, finite
gradients, determinism and one compile per search shape.

The linear case: the straight line ``y = x``, starting on the path, the source's gain K, slip bound
1 deg. The loop stays linear to ~1e-4 relative (slip and errors ~1e-2 rad, steering ~2 deg, far
from the 30 deg limit), so ``IAE(beta) = ||G beta||_1`` is convex and positively homogeneous in
the slip: its maximum over a bounded set sits on the set's extreme points. For constant slip
those are the four vertices ``(+-A, +-A)``; for a slip at one frequency, full-amplitude
sinusoids, one phase per axle (a 24 x 24 grid). Linear theory adds the worst vertex: at steady
state ``theta_e = -beta_r`` and ``delta = beta_r + beta_f``, so ``d_ss = ((1 + K_2) beta_r + beta_f) / K_1``;
with ``K = (-2.74, -2.08)``, ``|d_ss|`` is largest where ``beta_r = -beta_f``, and the reflection
about the line makes ``(A, -A)`` and ``(-A, A)`` equally bad.
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.falsification import OBJECTIVES, falsify, random_search, search_space, worst_trajectory
from pfjax.falsification import search as falsify_search
from pfjax.paths import line, sine
from pfjax.sim import SimConfig, sampled_slip, simulate_batch
from pfjax.sim.scenario import make_scenario

DEG = math.pi / 180
SF = C.state_feedback_params()  # the source's K
SEQ_DT = 0.05  # s

# Linear case.
LINE_CFG = SimConfig(dt=0.02, horizon=8.0, newton_iters=1, record=False)  # Newton is exact on a line
A_LIN = 1.0  # deg
ON_PATH = {"d": 0.0, "theta_e_deg": 0.0, "u": 0.0}
F_LIN = 0.5  # Hz
N_PHASE = 24
VERTICES = [(1, 1), (1, -1), (-1, 1), (-1, -1)]

# Paper case: the source's sine path and K, 10 deg slip up to 0.5 Hz, 20 cm and 10 deg initial errors.
PAPER_CFG = SimConfig(dt=0.02, horizon=10.0)
PAPER = dict(
    config=PAPER_CFG, slip_bound_deg=10.0, f_max_hz=0.5, ic_bounds={"d": (-0.2, 0.2), "theta_e_deg": (-10.0, 10.0)}
)
RESTARTS, STEPS = 8, 25  # 200 rollouts


@pytest.fixture(scope="module")
def brute():
    """IAE of the four constant vertices and of the N_PHASE^2 full-amplitude sinusoid pairs (one batch).

    Sinusoids are scaled to a held peak of exactly A, the boundary of the falsifier's set.
    """
    t = SEQ_DT * np.arange(int(math.ceil(LINE_CFG.horizon / SEQ_DT)) + 1)
    a = A_LIN * DEG
    seqs = [np.tile([sr * a, sf * a], (t.size, 1)) for sr, sf in VERTICES]
    phases = 2 * np.pi * np.arange(N_PHASE) / N_PHASE
    wave = [np.sin(2 * np.pi * F_LIN * t + p) for p in phases]
    wave = [a * w / np.abs(w).max() for w in wave]
    seqs += [np.stack([wave[i], wave[j]], axis=1) for i in range(N_PHASE) for j in range(N_PHASE)]
    one = make_scenario(line(), (0.0, 0.0, math.pi / 4), SF, slip=sampled_slip(seqs[0], SEQ_DT))
    runs = jax.tree_util.tree_map(lambda x: np.broadcast_to(x, (len(seqs), *np.shape(x))), one)
    runs = runs._replace(slip=runs.slip._replace(seq=np.stack(seqs)))
    res = simulate_batch(runs, controller=C.state_feedback, config=LINE_CFG)
    assert np.all(np.asarray(res.status) == 0)
    iae = np.asarray(res.metrics.iae)
    return iae[:4], iae[4:].reshape(N_PHASE, N_PHASE), phases


def test_constant_slip_worst_case_is_the_worst_vertex(brute):
    vertices, _, _ = brute
    # Reflection symmetry of the loop about the line: opposite vertices are equally bad.
    assert vertices[1] == pytest.approx(vertices[2], rel=1e-9)
    assert np.argmax(vertices) in (1, 2)
    r = falsify(
        C.state_feedback,
        SF,
        line(),
        config=LINE_CFG,
        slip_bound_deg=A_LIN,
        f_max_hz=0.0,
        ic_bounds=ON_PATH,
        n_restarts=8,
        steps=30,
        key=jax.random.PRNGKey(0),
    )
    best = vertices.max()
    assert 0.99 * best <= float(r.objective) <= best * (1 + 1e-3), (float(r.objective), vertices)
    slip = np.asarray(r.slip)
    assert np.all(slip == slip[0])  # constant
    assert np.sign(slip[0, 0]) == -np.sign(slip[0, 1])  # the worst vertex, beta_r = -beta_f
    assert np.abs(slip).max() >= 0.99 * A_LIN * DEG


def test_single_frequency_worst_phases_match_brute_force(brute):
    _, grid, phases = brute
    r = falsify(
        C.state_feedback,
        SF,
        line(),
        config=LINE_CFG,
        slip_bound_deg=A_LIN,
        f_max_hz=F_LIN,
        n_freq=1,
        with_constant=False,
        ic_bounds=ON_PATH,
        n_restarts=8,
        steps=30,
        key=jax.random.PRNGKey(1),
    )
    best = grid.max()
    assert 0.99 * best <= float(r.objective) <= 1.01 * best, (float(r.objective), best)
    # The phase difference between the axles: the falsifier's within one grid step of the brute force's.
    t = SEQ_DT * np.arange(len(r.slip))
    c, s = np.cos(2 * np.pi * F_LIN * t), np.sin(2 * np.pi * F_LIN * t)
    phase = [math.atan2(float(np.dot(col, c)), float(np.dot(col, s))) for col in np.asarray(r.slip).T]
    i, j = np.unravel_index(np.argmax(grid), grid.shape)
    gap = (phase[0] - phase[1]) - (phases[i] - phases[j])
    assert abs(math.remainder(gap, 2 * math.pi)) <= 2 * math.pi / N_PHASE, (phase, phases[i], phases[j])


@pytest.fixture(scope="module")
def paper():
    kw = dict(controller=C.state_feedback, gains=SF, path=sine(), **PAPER)
    f = falsify(**kw, n_restarts=RESTARTS, steps=STEPS, key=jax.random.PRNGKey(0))
    rs = [random_search(**kw, n_samples=RESTARTS * STEPS, key=jax.random.PRNGKey(k)) for k in range(3)]
    return kw, f, rs


def test_falsifier_beats_random_search_at_equal_budget(paper):
    _, f, rs = paper
    assert f.n_rollouts == f.n_gradients == RESTARTS * STEPS
    for r in rs:
        assert r.n_rollouts == RESTARTS * STEPS and r.n_gradients == 0
        assert float(f.objective) > float(r.objective), (float(f.objective), float(r.objective))
    # ... and at every budget the falsifier reports from 48 rollouts (its 6th step) on.
    for r in rs:
        at = np.asarray(r.history)[np.asarray(f.history_rollouts) - 1]
        assert np.all(np.asarray(f.history)[5:] > at[5:])


def test_bounds_gradients_determinism_and_one_compile(paper):
    kw, f, rs = paper
    a = PAPER["slip_bound_deg"] * DEG
    for r in [f, *rs]:
        assert np.abs(np.asarray(r.slip)).max() <= a
        d0, theta_e0, u0 = np.asarray(r.ic)
        assert abs(d0) <= 0.2 and abs(theta_e0) <= 10 * DEG and u0 == 0.0
        assert np.all(np.diff(np.asarray(r.history)) >= 0)
    assert f.n_nonfinite_grad == 0 and np.all(np.isfinite(np.asarray(f.history)))
    compiled = falsify_search._ascent_step._cache_size()
    r1, r2, r3 = (falsify(**kw, n_restarts=RESTARTS, steps=3, key=jax.random.PRNGKey(k)) for k in (5, 5, 6))
    assert falsify_search._ascent_step._cache_size() == compiled  # no recompilation across steps or calls
    for x, y in zip(jax.tree_util.tree_leaves(r1), jax.tree_util.tree_leaves(r2)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
    assert float(r1.objective) != float(r3.objective)


def test_worst_trajectory_reproduces_the_objective(paper):
    kw, f, _ = paper
    tr = worst_trajectory(C.state_feedback, f, PAPER_CFG)
    assert float(tr.metrics.iae) == pytest.approx(float(f.objective), rel=1e-9)
    n = len(f.slip)
    # sample index of each time in exact arithmetic (t = k dt lands on the boundaries j seq_dt; a
    # float quotient 5.999999999999999 must count as 6: slip_profiles.BOUNDARY_ULPS)
    j = np.floor(np.round(np.asarray(tr.trajectory.t) / float(f.seq_dt), 9)).astype(int)
    held = np.asarray(f.slip)[np.minimum(j, n - 1)]
    np.testing.assert_allclose(np.asarray(tr.trajectory.beta_r), held[:, 0], atol=1e-15)
    np.testing.assert_allclose(np.asarray(tr.trajectory.beta_f), held[:, 1], atol=1e-15)
    assert float(tr.trajectory.d[0]) == pytest.approx(float(f.ic[0]), abs=1e-9)
    assert float(tr.trajectory.theta_e[0]) == pytest.approx(float(f.ic[1]), abs=1e-9)


def test_every_objective_shares_one_compile(paper):
    kw, _, _ = paper
    compiled = falsify_search._ascent_step._cache_size()
    for name in OBJECTIVES:
        r = falsify(**kw, objective=name, n_restarts=RESTARTS, steps=2, key=jax.random.PRNGKey(3))
        tr = worst_trajectory(C.state_feedback, r, PAPER_CFG)
        assert float(getattr(tr.metrics, name)) == pytest.approx(float(r.objective), rel=1e-9), name
    assert falsify_search._ascent_step._cache_size() == compiled


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(ic_bounds={"y": (0, 1)}), "unknown key 'y'"),
        (dict(ic_bounds={"d": (0.2, -0.2)}), r"ic_bounds\['d'\]"),
        (dict(f_max_hz=20.0), "f_max_hz"),
        (dict(slip_bound_deg=-1.0), "slip_bound_deg"),
        (dict(f_max_hz=0.0, with_constant=False), "no slip"),
    ],
)
def test_search_space_rejects_bad_bounds(kw, match):
    args = dict(horizon=1.0, slip_bound_deg=5.0, f_max_hz=1.0, ic_bounds={}) | kw
    with pytest.raises(ValueError, match=match):
        search_space(**args)


def test_unknown_objective():
    with pytest.raises(ValueError, match="objective"):
        falsify(
            C.state_feedback, SF, line(), **{**PAPER, "config": LINE_CFG}, objective="iea", key=jax.random.PRNGKey(0)
        )


def test_a_search_compiles_few_programs():
    """A search of new shapes compiles its own few programs (the ascent step, the random search's
    simulator, the replay, the sampling, scenario building), not one per eager operation: 23 here
    (jax 0.10.2), against 81 before its small steps were jitted."""
    events = []
    listener = lambda name, secs, **kw: (
        events.append(name) if name == "/jax/core/compile/backend_compile_duration" else None
    )
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        cfg = SimConfig(dt=0.02, horizon=1.26)  # shapes no other test uses
        kw = dict(config=cfg, slip_bound_deg=5.0, f_max_hz=0.5, ic_bounds={"d": (-0.1, 0.1), "theta_e_deg": 5.0})
        f = falsify(C.state_feedback, SF, sine(), n_restarts=3, steps=2, key=jax.random.PRNGKey(1), **kw)
        random_search(C.state_feedback, SF, sine(), n_samples=5, batch_size=5, key=jax.random.PRNGKey(2), **kw)
        worst_trajectory(C.state_feedback, f, cfg)
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert 0 < len(events) <= 30, len(events)  # 81 before (jax 0.10.2)


def test_of_several_failed_runs_the_largest_objective_wins():
    """A failed run ranks above every healthy run, and of failed runs the larger J wins (not the
    first failed run found): random_search's reported run is the failed draw with the largest J,
    checked against the same draws simulated in one batch, and the ranking helpers on a batch."""
    import jax
    import jax.numpy as jnp

    from pfjax import controllers as C
    from pfjax import paths
    from pfjax.api.simulation import resolve_gains
    from pfjax.falsification import random_search
    from pfjax.falsification.search import _beats, _first_best, _rank, _scenarios, _setup
    from pfjax.falsification.space import sample
    from pfjax.models.slip import CONVENTIONS, SlipParams
    from pfjax.sim import SimConfig
    from pfjax.sim.simulate import simulate_batch

    failed, score = _rank(jnp.array([0.3, 0.1, 0.2, jnp.nan, 0.5]), jnp.array([1, 1, 1, 1, 0]))
    assert int(_first_best(failed, score)) == 0 and bool(_beats(True, 0.1, False, 9.0))
    assert int(_first_best(*_rank(np.array([0.2, 0.2]), np.array([0, 0]), np), np)) == 0  # the first of equals

    e, d = C.resolve("state_feedback")
    gains, _ = resolve_gains(e, d, None, 1.0, 0.2)
    path = paths.fixed_entry("sine").build()
    cfg = SimConfig(dt=0.02, horizon=3.0, d_fail=0.15, record=False)
    sp = SlipParams(
        v=np.asarray(1.0),
        L=np.asarray(0.2),
        delta_max=np.asarray(np.radians(30.0)),
        convention=np.asarray(CONVENTIONS["source"], np.int32),
    )
    ic = {"d": (-0.1, 0.1), "theta_e_deg": (-5, 5), "u": 0.0}
    key, n = jax.random.PRNGKey(0), 200
    r = random_search(
        e.controller,
        gains,
        path,
        config=cfg,
        slip_bound_deg=20,
        f_max_hz=1.0,
        ic_bounds=ic,
        n_samples=n,
        key=key,
        params=sp,
    )
    space, base, _ = _setup(
        path, gains, cfg, 20, 1.0, ic, "iae", sp, None, dict(n_freq=8, with_constant=True, seq_dt=0.05)
    )
    seq, icv = sample(space, key, n)
    res = simulate_batch(_scenarios(space, seq, icv, np.arange(n), base), controller=e.controller, config=cfg)
    v, s = np.asarray(res.metrics.iae), np.asarray(res.status)
    assert (s != 0).sum() >= 2 and np.unique(v[s != 0]).size >= 2  # several failed runs, of different J
    assert r.status_name != "ok" and float(r.objective) == pytest.approx(v[s != 0].max(), rel=1e-6)


def test_the_search_defaults_are_a_studys_falsifier_defaults():
    """pfjax.falsify, pfjax.falsification.falsify and a study's [falsifier] table have one set of
    defaults (FalsifierSpec's), and the objectives the search takes are the table's choices."""
    import inspect
    import typing

    import pfjax
    from pfjax.falsification import search
    from pfjax.montecarlo.analysis_config import FalsifierSpec

    spec = FalsifierSpec()
    api = inspect.signature(pfjax.falsify).parameters
    for arg, key in (
        ("slip_bound_deg", "slip_bound_deg"),
        ("f_max_hz", "f_max_hz"),
        ("lateral_offset", "lateral_offset"),
        ("heading_error_deg", "heading_error_deg"),
        ("objective", "objective"),
        ("restarts", "n_restarts"),
        ("steps", "steps"),
    ):
        assert api[arg].default == getattr(spec, key), arg
    lib = inspect.signature(search.falsify).parameters
    assert (lib["n_restarts"].default, lib["steps"].default, lib["objective"].default) == (
        spec.n_restarts,
        spec.steps,
        spec.objective,
    )
    assert typing.get_args(FalsifierSpec.model_fields["objective"].annotation) == search.OBJECTIVES
