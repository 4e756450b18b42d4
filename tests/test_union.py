"""The union of controllers (pfjax.controllers.union): each run steered by its own controller's
law, in a batch that mixes them, in one run and in continuous mode; its parameters checked; a
study's side jobs compiled once for all its controllers.

Tolerances: 1e-12 relative for the same run in two programs (the same arithmetic; the compiler may
contract a multiply-add differently); 1e-9 between a batch and one run (pfjax.sim.simulate_one: the
batch's numbers up to rounding) and between searches of a few gradient steps, whose rounding
differences the ascent carries along.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pfjax import controllers as C
from pfjax.controllers.union import UnionParams, shared, union, union_params
from pfjax.errors import InputError
from pfjax.models import Pose
from pfjax.sim import SimConfig, simulate_batch, stack
from pfjax.sim.scenario import paper_scenario
from pfjax.sim.simulate import simulate_one

CFG = SimConfig(dt=0.01, horizon=6.0)
#: Parts with states of three shapes: the PI's two integrators, none, the integral term.
PARTS = (C.linear, C.stanley, C.integral)
GAINS = (
    C.linear_params(C.pi_params(kp_d=1.0, ki_d=0.5, kp_theta=1.5, ki_theta=0.2, k_aw=5.0)),
    C.stanley_params(k=2.0),
    C.integral_params(),
)
#: A second run of each kind with other gains (two controllers of one kind in a batch, as a study's
#: state feedback and PI), and the unselected parts' parameters, unlike either.
OTHER = (
    C.linear_params(C.state_feedback_params()),
    C.stanley_params(k=4.0, k_soft=0.3),
    C.integral_params(K=(-2.0, -1.5, -0.8)),
)
FILL = (
    C.linear_params(C.pi_params(kp_d=3.0, ki_d=0.1, kp_theta=0.5, ki_theta=0.0)),
    C.stanley_params(k=0.7, k_soft=1.0),
    C.integral_params(K=(-1.0, -3.0, -0.2)),
)
POSES = [(0.0, 0.5, 0.3), (0.5, -0.4, -0.2)]


def _rows(k: int, wrap=lambda k, g: g):
    """Run ``k``'s two scenarios (its gains, then the other gains of its kind), each gains set
    passed through ``wrap(k, gains)``."""
    gains = (GAINS[k], OTHER[k])
    return [paper_scenario("sine", wrap(k, g), beta_r_deg=4.0, beta_f_deg=-3.0, pose0=p) for p, g in zip(POSES, gains)]


def _selecting(k, g):
    return union_params(PARTS, k, g, FILL)


def _leaves(res):
    return [np.asarray(a) for a in jax.tree_util.tree_leaves((res.metrics, res.final, res.fail_time))]


def test_a_mixed_batch_and_one_run_steer_as_each_part():
    """Runs of three controllers, two of each kind with different gains, in one batch of the union
    (every part evaluated, each run's own kept; the unselected parts with other gains) give each
    controller's own metrics, final state and status; one run of the union (only its part
    evaluated) gives the batch's."""
    u = union(PARTS)
    mixed = [r for k in range(len(PARTS)) for r in _rows(k, _selecting)]
    got = jax.device_get(simulate_batch(stack(mixed), controller=u, config=CFG))
    for k, part in enumerate(PARTS):
        want = jax.device_get(simulate_batch(stack(_rows(k)), controller=part, config=CFG))
        rows = slice(len(POSES) * k, len(POSES) * (k + 1))
        np.testing.assert_array_equal(got.status[rows], want.status)
        for a, b in zip(_leaves(got), _leaves(want)):
            np.testing.assert_allclose(a[rows], b, rtol=1e-12, atol=1e-14)
    assert np.all(got.status == 0) and np.ptp(got.metrics.iae) > 0.01  # distinct runs, all converged
    for i in (0, len(POSES)):  # a PI run and a Stanley run, each alone
        one = jax.device_get(simulate_one(mixed[i], controller=u, config=CFG))
        assert int(one.status) == int(got.status[i])
        for a, b in zip(_leaves(one), _leaves(got)):
            np.testing.assert_allclose(a, b[i], rtol=1e-9, atol=1e-12)


def test_a_union_in_continuous_mode_integrates_only_the_selected_state():
    """With the controller evaluated inside every RK4 stage (``control_every=None``), a PI run of
    the union (its integrators integrated with the plant) and a Stanley run give their own
    controllers' numbers."""
    cfg = SimConfig(dt=0.01, horizon=3.0, control_every=None)
    u = union(PARTS[:2])
    fill = FILL[:2]
    rows = [paper_scenario("sine", union_params(PARTS[:2], k, GAINS[k], fill), pose0=POSES[0]) for k in (0, 1)]
    got = jax.device_get(simulate_batch(stack(rows), controller=u, config=cfg))
    for k in (0, 1):
        plain = paper_scenario("sine", GAINS[k], pose0=POSES[0])
        want = jax.device_get(simulate_batch(stack([plain]), controller=PARTS[k], config=cfg))
        assert int(got.status[k]) == int(want.status[0])
        for a, b in zip(_leaves(got), _leaves(want)):
            np.testing.assert_allclose(a[k], b[0], rtol=1e-12, atol=1e-14)


def test_union_params_refuses_what_its_parts_do_not_take():
    """An index out of the parts, a fill of another length or gains of another kind: an InputError
    naming the argument, before anything is traced."""
    with pytest.raises(InputError, match=r"^which: must be <= 2"):
        union_params(PARTS, 3, GAINS[0], FILL)
    with pytest.raises(InputError, match=r"^fill: 2 parameter sets for 3 parts"):
        union_params(PARTS, 0, GAINS[0], FILL[:2])
    with pytest.raises(InputError, match=r"^gains: controller 'stanley' takes StanleyParams, got LinearParams"):
        union_params(PARTS, 1, GAINS[0], FILL)


def test_unselected_parts_keep_their_initial_state():
    """The state of every part but the selected one has rate 0 (it stays at its ``init``); the
    selected part's rate and output are its own (to 1e-14: the union is compiled as a conditional,
    the part here op by op, so a multiply-add may round once instead of twice)."""
    u = union(PARTS)
    path = paper_scenario("sine", GAINS[0]).path
    obs = C.Observation(
        d=jnp.asarray(0.3),
        theta_e=jnp.asarray(-0.1),
        kappa=jnp.asarray(0.2),
        s=jnp.asarray(1.0),
        u=jnp.asarray(1.0),
        pose=Pose(jnp.asarray(1.0), jnp.asarray(1.1), jnp.asarray(0.5)),
        v=jnp.asarray(1.0),
        L=jnp.asarray(0.2),
        delta_max=jnp.asarray(math.radians(30.0)),
        path=path,
    )
    for k, part in enumerate(PARTS):
        p = union_params(PARTS, k, GAINS[k], FILL)
        c = jax.tree_util.tree_map(lambda a: a + 0.01, u.init(p))  # away from 0, so an own rate shows
        cmd = u.output(p, c, obs)
        np.testing.assert_allclose(cmd, part.output(GAINS[k], c[k], obs), rtol=1e-14)
        rates = u.rate(p, c, obs, cmd, jnp.clip(cmd, -obs.delta_max, obs.delta_max))
        own = part.rate(GAINS[k], c[k], obs, cmd, jnp.clip(cmd, -obs.delta_max, obs.delta_max))
        for j, r in enumerate(rates):
            want = own if j == k else jax.tree_util.tree_map(jnp.zeros_like, c[j])
            for a, b in zip(jax.tree_util.tree_leaves(r), jax.tree_util.tree_leaves(want)):
                np.testing.assert_allclose(a, b, rtol=1e-14, atol=0)  # the unselected: exactly 0
        assert any(np.any(np.asarray(a) != 0) for a in jax.tree_util.tree_leaves(own)) == (k != 1)


def test_shared_gives_one_controller_and_keeps_each_ones_gains():
    """A study's controllers of two kinds become one union controller (the same object, so one
    compiled program), each selecting its own kind with its own gains; one kind stays as it is."""
    lmi, pi = C.linear_params(C.state_feedback_params()), GAINS[0]
    given = {"lmi": (C.linear, lmi, {}), "pi": (C.linear, pi, {"kp_d": 1.0}), "stanley": (C.stanley, GAINS[1], {})}
    out = shared(given)
    assert {name: v[0] for name, v in out.items()} == dict.fromkeys(given, union((C.linear, C.stanley)))
    assert union((C.linear, C.stanley)) is union((C.linear, C.stanley))
    for name, (_, gains, flat) in given.items():
        p = out[name][1]
        assert isinstance(p, UnionParams) and out[name][2] is flat
        assert int(p.which) == (1 if name == "stanley" else 0)
        assert p.parts[int(p.which)] is gains
        assert p.parts[1 - int(p.which)] is (GAINS[1] if name != "stanley" else lmi)  # the kind's first gains
    one_kind = {k: v for k, v in given.items() if k != "stanley"}
    assert shared(one_kind) is one_kind


def test_a_worst_case_search_is_one_program_for_all_controllers():
    """The worst-case search of controllers of two kinds through their union (as a study's side
    jobs search) compiles one gradient step for both, and finds what each controller's own search
    finds (Stanley's compared here; the state feedback's steering is the batch test's)."""
    from pfjax.falsification import falsify, search

    given = {"lmi": (C.linear, GAINS[0], {}), "stanley": (C.stanley, GAINS[1], {})}
    one = shared(given)
    path = paper_scenario("sine", GAINS[1]).path
    kw = dict(
        path=path,
        config=CFG,
        slip_bound_deg=5.0,
        f_max_hz=0.5,
        ic_bounds={"d": (-0.3, 0.3), "theta_e_deg": (-20.0, 20.0), "u": 0.0},
        n_restarts=2,
        steps=2,
        key=jax.random.PRNGKey(4),
    )
    before = search._ascent_step._cache_size()
    got = {name: falsify(ctrl, gains, **kw) for name, (ctrl, gains, _) in one.items()}
    assert search._ascent_step._cache_size() == before + 1
    want = falsify(C.stanley, GAINS[1], **kw)
    assert int(got["stanley"].status) == int(want.status)
    for field in ("objective", "slip", "ic", "pose0", "history", "n_rollouts", "n_nonfinite_grad", "restarts"):
        for a, b in zip(*(jax.tree_util.tree_leaves(getattr(r, field)) for r in (got["stanley"], want))):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-9, atol=1e-12, err_msg=field)
    assert float(got["lmi"].objective) != float(want.objective)


def test_a_studys_side_jobs_search_and_check_every_controller_through_one(monkeypatch):
    """A study's worst-case searches and float64 re-simulations get one controller for all (the
    union of the study's kinds), each search its own controller's gains."""
    from test_montecarlo import spec_of

    import pfjax.montecarlo.checks as checks
    import pfjax.montecarlo.worst_case as worst
    from pfjax.montecarlo.runner import controllers_of
    from pfjax.montecarlo.side_jobs import SideJobs

    spec = spec_of("falsifier.enabled=true")
    plain = controllers_of(spec)
    seen = []
    monkeypatch.setattr(worst, "worst_case", lambda spec, ctrls, i, devices=None: seen.append((ctrls, i)) or ({}, {}))
    monkeypatch.setattr(checks, "float64_runs", lambda spec, ctrls, n, p, devices=None: seen.append((ctrls, p)) or {})
    side = SideJobs(spec, plain, overlap=False, report=False)
    side.worst_cases(), side.float64_runs()
    assert len(seen) == len(plain) + len(spec.paths)
    kinds = tuple(dict.fromkeys(v[0] for v in plain.values()))
    assert len(kinds) == 2
    for ctrls, _ in seen:
        assert list(ctrls) == list(plain) and {v[0] for v in ctrls.values()} == {union(kinds)}
    for name, (ctrl, gains, _) in plain.items():
        p = seen[0][0][name][1]
        assert p.parts[int(p.which)] is gains


def test_the_paper_reproductions_runs_are_one_program_for_all_controllers():
    """The paper reproduction runs its six controllers (two state feedbacks, the PI and three
    trackers: five kinds) through their union, one compiled program, each run's numbers its own
    controller's to rounding."""
    from types import SimpleNamespace

    from pfjax.reproduce import paper_config, paper_runs
    from pfjax.sim.simulate import _simulate_vmapped

    cfg = paper_config.load(None, ["trackers=true"], quick=True).model_dump(mode="json")
    before = _simulate_vmapped._cache_size()
    rows, _ = paper_runs.part_paper_runs(cfg, list(C.PAPER_K), SimpleNamespace(update=lambda n: None))
    assert _simulate_vmapped._cache_size() - before <= 1
    assert len({r["controller"] for r in rows}) == 6
    row = next(r for r in rows if r["controller"] == "stanley" and r["path"] == "sine")
    own = jax.device_get(paper_runs.run_batch(C.stanley, [C.stanley_params()], "sine", cfg, paper_runs.sim_config(cfg)))
    assert row["status"] == "ok" and int(own.status[0]) == 0
    for name in ("iae", "late_max_abs_d", "steer_energy"):
        np.testing.assert_allclose(row[name], float(getattr(own.metrics, name)[0]), rtol=1e-12)
