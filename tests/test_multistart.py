"""Multi-start gradient tuning, the local-minimum check and ``pfjax tune --check`` / ``--method ga+gradient``.

References: analytic costs with known minima (a narrow deep well beside a broad shallow basin, a
convex quadratic, a saddle, a kink); the rollout count is recounted independently by a host
callback inside the cost (one call per evaluated point, whatever the batching and differentiation).
"""

import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pfjax
from pfjax.sim import SimConfig
from pfjax.tuning.check import check_point, parse_gains, probe_directions
from pfjax.tuning.gradient import gradient_tune
from pfjax.tuning.multistart import MultistartOptions, multistart_tune, space_filling

SHORT = SimConfig(dt=0.01, horizon=4.0, record=False)
WELL, BOWL = jnp.asarray([0.15, 0.1]), jnp.asarray([0.75, 0.7])


def _two_basins(th):
    """A broad shallow basin (minimum ~ -0.3 at BOWL) and a narrow deep well (minimum ~ -1 at WELL)."""
    return (
        0.3 * jnp.sum((th - BOWL) ** 2)
        - 0.3 * jnp.exp(-jnp.sum((th - BOWL) ** 2) / (2 * 0.4**2))
        - 1.0 * jnp.exp(-jnp.sum((th - WELL) ** 2) / (2 * 0.08**2))
    )


def test_multistart_reaches_the_narrow_basin_where_single_starts_fail():
    o = MultistartOptions(n_screen=32, n_starts=4, separation=0.25, steps=24, rounds=2, n_restarts=2, restart_steps=4)
    single, multi, crowded = [], [], []
    hit = lambda th: bool(np.linalg.norm(th - np.asarray(WELL)) < 0.02)
    for seed in range(8):
        key = jax.random.PRNGKey(seed)
        r = multistart_tune(_two_basins, [0, 0], [1, 1], key=key, options=o)
        multi.append(hit(r.theta))
        p = gradient_tune(_two_basins, [0, 0], [1, 1], key=key, steps=r.n_rollouts, learning_rate=0.05)
        single.append(hit(p.theta))
        assert r.n_rollouts == p.n_rollouts  # the same budget
        crowded.append(
            hit(multistart_tune(_two_basins, [0, 0], [1, 1], key=key, options=o._replace(separation=0.0)).theta)
        )
    assert all(multi), multi
    assert sum(single) <= 4, single  # the well covers ~6 % of the box; plain descent mostly lands in the bowl
    # the screening ranks points on the bowl's broad floor first: without separated starts some seeds miss the well
    assert not all(crowded), crowded


def test_rollouts_are_counted_exactly():
    calls = [0]

    def cost(th):
        jax.debug.callback(lambda _: calls.__setitem__(0, calls[0] + 1), th[0])
        return jnp.sum((th - 0.3) ** 2)

    o = MultistartOptions(n_screen=16, n_starts=4, steps=7, rounds=3, n_restarts=2, restart_steps=3, polish_steps=2)
    r = multistart_tune(cost, [0, 0, 0], [1, 1, 1], key=jax.random.PRNGKey(0), options=o, candidates=[[0.5] * 3])
    # 17 screened, chains 4, 2, 1 for 3, 2, 2 steps, 3 restart chains for 3 steps, 2 compass iterations of 6 points
    n_grad = 4 * 3 + 2 * 2 + 1 * 2 + 3 * 3
    expected = 17 + n_grad + 2 * 6
    assert calls[0] == expected == r.n_rollouts == r.history_rollouts[-1]
    # forward mode, 3 gains: 1 + 3 passes per gradient rollout, 1 per value-only rollout
    assert r.n_forward_passes == 17 + 4 * n_grad + 2 * 6
    assert np.all(np.diff(r.history) <= 0) and r.cost == r.history[-1] == pytest.approx(0.0, abs=1e-12)
    assert r.compile_s > 0 and r.wall_s > 0


@pytest.fixture
def step_programs(monkeypatch):
    """The ``(chains, local)`` of every step program the multi-start tuner asks for (cache emptied);
    its ``values`` attribute: the points of every value-only program asked for."""
    from pfjax.tuning import multistart

    class Asked(list):
        values: list

    compiled = Asked()
    compiled.values = []
    real = multistart._compiled

    def spy(fun, shape_dtype, **static):
        if fun is multistart._step:
            compiled.append((shape_dtype[0][0], static["local"]))
        else:
            compiled.values.append(shape_dtype[0][0])
        return real(fun, shape_dtype, **static)

    monkeypatch.setattr(multistart, "_COMPILED", {})
    monkeypatch.setattr(multistart, "_compiled", spy)
    return compiled


def test_restarts_share_the_halving_rounds_step_program(step_programs):
    """BFGS's first radius is state, not a static argument: restarts at a quarter of it reuse the
    step program of the round with their chain count; Adam's schedule is static, so its restarts
    compile their own."""
    compiled = step_programs
    cost = lambda th: jnp.sum((th - 0.3) ** 2)
    o = MultistartOptions(n_screen=8, n_starts=4, steps=4, rounds=2, n_restarts=1, restart_steps=2, polish_steps=0)
    r = multistart_tune(cost, [0, 0], [1, 1], key=jax.random.PRNGKey(0), options=o)
    assert sorted(m for m, _ in compiled) == [2, 4]  # chains 4 then 2; the 2 restart chains reuse the second
    assert r.n_rollouts == 8 + 4 * 2 + 2 * 2 + 2 * 2  # the restarts ran
    compiled.clear()
    multistart_tune(cost, [0, 0], [1, 1], key=jax.random.PRNGKey(0), options=o._replace(local="adam"))
    assert sorted(m for m, _ in compiled) == [2, 2, 4]
    assert len({lc for _, lc in compiled}) == 2  # the restarts' Adam schedule differs


@jax.custom_jvp
def _nan_slope(x):
    return x


_nan_slope.defjvp(lambda primals, tangents: (primals[0], jnp.where(tangents[0] == 0, 0.0, jnp.nan)))  # forward mode


@pytest.mark.parametrize("local", ["bfgs", "adam"])
def test_cheap_costs_share_one_step_program_with_the_same_result(step_programs, local):
    """With ``rollout_steps`` small the halving rounds (and BFGS's restarts) run on the first
    round's program, their chains padded with copies of the first, and the polish's compass points
    on the screening's value-only program: the same points, costs, counts and non-finite gradient
    components as one program per chain count and purpose."""
    from pfjax.tuning import multistart

    chains = lambda: sorted(m for m, _ in step_programs)  # chain counts of the compiled step programs

    def cost(th):  # the second gain's derivative is NaN (zeroed and counted)
        return jnp.sum((th - jnp.asarray([0.3, 0.6, 0.2])) ** 2) + 0.1 * _nan_slope(th[1])

    o = MultistartOptions(n_screen=8, n_starts=4, steps=7, rounds=3, n_restarts=2, restart_steps=3, polish_steps=2)
    o = o._replace(local=local)
    args = (cost, [0, 0, 0], [1, 1, 1])
    own = multistart_tune(*args, key=jax.random.PRNGKey(1), options=o)
    assert chains() == [1, 2, 3, 4] and step_programs.values == [8, 6]  # screening 8 points, polish 2 D
    step_programs.clear()
    step_programs.values.clear()
    shared = multistart_tune(*args, key=jax.random.PRNGKey(1), options=o, rollout_steps=1)
    # adam's restarts keep a program of their own (their schedule is static)
    assert chains() == ([4] if local == "bfgs" else [3, 4]) and step_programs.values == [8, 8]
    n_grad = 4 * 3 + 2 * 2 + 1 * 2 + 3 * 3  # chains 4, 2, 1 for 3, 2, 2 steps; 3 restart chains for 3 steps
    for r in (own, shared):
        assert r.n_rollouts == 8 + n_grad + 2 * 6  # screened, descended, polished
        assert r.n_nonfinite_grad == n_grad  # one NaN component per real chain's gradient
    np.testing.assert_array_equal(shared.theta, own.theta)
    np.testing.assert_array_equal(shared.history, own.history)
    # too much padded work for the budget: one program per chain count again
    step_programs.clear()
    multistart._COMPILED.clear()
    step_programs.values.clear()
    multistart_tune(*args, key=jax.random.PRNGKey(1), options=o, rollout_steps=10**9)
    assert chains() == [1, 2, 3, 4] and step_programs.values == [8, 6]


def test_the_padding_budget_counts_gradient_and_value_only_rollouts():
    """The step programs are shared where the padded chain-steps times the 1 + D passes of a
    gradient fit the budget (forward-pass rollout-steps); the polish's program too where what is
    left covers its padded points (1 pass each); an unknown evaluation size shares nothing."""
    from pfjax.tuning.gradient import PAD_FORWARD_PASSES
    from pfjax.tuning.multistart import _Plan

    o = MultistartOptions(n_screen=8, n_starts=4, steps=7, rounds=3, n_restarts=2, restart_steps=3, polish_steps=2)
    # chains 4, 2, 1 for 3, 2, 2 steps and 3 restart chains for 3 steps on 4-chain programs: 13
    # padded chain-steps of 1 + D = 4 passes; the polish's 2 D = 6 points padded to the screening's
    # 8 for 2 iterations: 4 value-only rollouts
    steps_only, both = 13 * 4, 13 * 4 + 4
    fits = _Plan.of(o, 8, 3, PAD_FORWARD_PASSES // both, 4)
    assert fits.programs == (4, 4, 4) and fits.restart_program == 4 and fits.polish_program == 8
    steps = _Plan.of(o, 8, 3, PAD_FORWARD_PASSES // both + 1, 4)  # the steps' padding alone fits
    assert steps.programs == (4, 4, 4) and steps.restart_program == 4 and steps.polish_program == 6
    over = _Plan.of(o, 8, 3, PAD_FORWARD_PASSES // steps_only + 1, 4)
    assert over.programs == (4, 2, 1) and over.restart_program == 3 and over.polish_program == 6
    unknown = _Plan.of(o, 8, 3, None, 4)
    assert unknown.programs == (4, 2, 1) and unknown.polish_program == 6
    assert _Plan.of(o._replace(rounds=1, n_restarts=0), 8, 3, None, 4).polish_program == 6  # no step padding
    # a polish with more compass points than screened points keeps its own program
    few = _Plan.of(o._replace(n_screen=4), 4, 3, 1, 4)
    assert few.programs == (4, 4, 4) and few.polish_program == 6


def test_compass_polish_walks_along_a_kink_where_bfgs_stalls():
    """A V-shaped valley along the kink z1 = 0.5 (minimum 0 at (0.8, 0.5), closed form): a gradient
    step crosses the kink and is rejected, so the BFGS chain creeps along z0; the compass polish
    (value only) walks along it."""
    valley = lambda th: 5.0 * jnp.abs(th[1] - 0.5) + 0.5 * (th[0] - 0.8) ** 2
    o = MultistartOptions(n_screen=0, n_starts=1, steps=12, rounds=1, n_restarts=0, polish_steps=0)
    kw = dict(key=jax.random.PRNGKey(0), candidates=[[0.1, 0.5]])
    plain = multistart_tune(valley, [0, 0], [1, 1], options=o, **kw)
    polished = multistart_tune(valley, [0, 0], [1, 1], options=o._replace(polish_steps=20), **kw)
    assert plain.cost > 0.05  # 0.245 at the start: the chain creeps
    assert polished.cost < 1e-3 and abs(polished.theta[0] - 0.8) < 0.03
    assert polished.n_rollouts == plain.n_rollouts + 20 * 4
    assert polished.n_forward_passes == plain.n_forward_passes + 20 * 4  # value only: 1 pass each


def test_space_filling_samplers_are_seeded_and_stratified():
    for s in ("sobol", "lhs", "uniform"):
        a = space_filling(16, 3, s, jax.random.PRNGKey(1))
        assert a.shape == (16, 3) and np.all((a >= 0) & (a < 1))
        np.testing.assert_array_equal(a, space_filling(16, 3, s, jax.random.PRNGKey(1)))
    lhs = space_filling(16, 3, "lhs", jax.random.PRNGKey(2))
    for d in range(3):  # one point per stratum in every coordinate
        assert sorted(np.floor(lhs[:, d] * 16).astype(int)) == list(range(16))
    with pytest.raises(ValueError, match="^sampler: "):
        MultistartOptions(sampler="halton").check()


def test_check_known_minimum_saddle_and_kink():
    lo, hi = [-1.0, -1.0], [1.0, 1.0]
    bowl = lambda th: (th[0] - 0.2) ** 2 + 3.0 * (th[1] + 0.1) ** 2 + th[0] * th[1]
    xs = np.linalg.solve([[2.0, 1.0], [1.0, 6.0]], [0.4, -0.6])  # the stationary point
    r = check_point(bowl, xs, lo, hi)
    assert r.verdict == "local minimum" and r.quadratic_model == "positive definite"
    # Hessian in box units: span^2 * [[2, 1], [1, 6]]
    np.testing.assert_allclose(r.eigenvalues, 4.0 * np.linalg.eigvalsh([[2.0, 1.0], [1.0, 6.0]]), rtol=1e-6)
    assert r.newton_decrease < 1e-12 and np.linalg.norm(r.projected_gradient) < 1e-9
    assert r.n_rollouts == 1 + 4 + len(probe_directions(2)) * 2
    off = check_point(bowl, xs + [0.05, 0.0], lo, hi)
    assert off.verdict == "not a local minimum" and off.probe_decrease > 0
    saddle = check_point(lambda th: th[0] ** 2 - th[1] ** 2, [0.0, 0.0], lo, hi)
    assert saddle.verdict == "not a local minimum" and saddle.quadratic_model == "indefinite"
    # minimum on the bound x = 1 (gradient pushes outward): active, still a minimum
    edge = check_point(lambda th: -th[0] + (th[1] - 0.3) ** 2, [1.0, 0.3], lo, hi)
    assert edge.verdict == "local minimum" and edge.active.tolist() == [1, 0]
    # a kink: the gradient is not small on either side, the point is still a minimum
    kink = check_point(lambda th: jnp.abs(th[0] - 0.3) + (th[1] - 0.6) ** 2, [0.3, 0.6], lo, hi)
    assert kink.verdict == "local minimum" and abs(kink.gradient[0]) == pytest.approx(1.0)


def test_a_checks_gradients_are_one_program_unless_unused_pairs_would_cost_much():
    """The gradients at ``z`` and at ``z ± h e_i`` are one call of one program at a point inside the
    box (every pair is used) and on a bound when ``rollout_steps`` says the pairs that may go unused
    are cheap; otherwise (a bound, and no ``rollout_steps`` or too many) ``z``'s gradient first and
    the free coordinates' pairs after, two programs. Both give the same check (1e-12; independent
    lanes of a vmapped program) and count the same rollouts (the unused pairs not among them)."""
    from pfjax.tuning import check as CK
    from pfjax.tuning.gradient import PAD_FORWARD_PASSES

    lo, hi = [-1.0, -1.0], [1.0, 1.0]

    def programs(theta, **kw):
        cost = lambda th: -th[0] + (th[1] - 0.3) ** 2 + 0.5 * th[0] * th[1]  # a new function: programs of its own
        before = CK._values_and_gradients._cache_size()
        r = check_point(cost, theta, lo, hi, **kw)
        return r, CK._values_and_gradients._cache_size() - before

    inside, n = programs([0.5, 0.2])
    assert n == 1 and inside.active.tolist() == [0, 0] and inside.n_rollouts == 1 + 4 + 2 * len(probe_directions(2))
    apart, n_apart = programs([1.0, 0.3])  # x on its upper bound, pushed against it: active
    together, n_together = programs([1.0, 0.3], rollout_steps=10)
    # the limit: 2 pairs' rows of one coordinate on a bound, 1 + D forward passes each
    too_many, n_too_many = programs([1.0, 0.3], rollout_steps=PAD_FORWARD_PASSES // 6 + 1)
    assert (n_apart, n_together, n_too_many) == (2, 1, 2)
    assert apart.active.tolist() == together.active.tolist() == [1, 0]
    assert apart.n_rollouts == together.n_rollouts == 1 + 2 + 2 * len(probe_directions(2))
    assert apart.n_forward_passes == together.n_forward_passes
    for a, b in zip(apart, together):
        if isinstance(a, str):
            assert a == b
        else:
            np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-15)


def test_check_point_refuses_a_point_outside_its_box():
    """A point outside the box (or not finite), or a box that is not one, is an input error naming
    the argument: the check works in box units and would otherwise check the clipped point."""
    from pfjax.errors import InputError

    bowl = lambda th: jnp.sum((th - 0.3) ** 2)
    for theta, lo, hi, key, msg in (
        ([2.0, 0.3], [0, 0], [1, 1], "theta", r"theta\[0\]: 2 is not a finite value in \[0, 1\]"),
        ([0.5, np.nan], [0, 0], [1, 1], "theta", r"theta\[1\]: nan"),
        ([0.5, 0.5], [0, 1], [1, 1], "lower", "lower < upper"),
        ([0.5, 0.5], [0, 0], [1, np.inf], "upper", "finite numbers"),
        ([0.5, 0.5], [0, 0], [1], "lower", "of one size"),
    ):
        with pytest.raises(InputError, match=f"^{key}") as e:
            check_point(bowl, theta, lo, hi)
        assert re.search(msg, str(e.value)) and e.value.key.startswith(key), str(e.value)


def test_check_of_a_plateau_is_flat_not_a_minimum():
    """A cost constant around the point (every run failed: the fail penalty), with a zero gradient,
    is "flat" (to 1e-12 relative); a minimum whose probes rise by more than that, though by less
    than rtol, is still a local minimum."""
    lo, hi = [-1.0, -1.0], [1.0, 1.0]
    plateau = check_point(lambda th: jnp.where(th[0] > -0.5, 100.0, th[0] ** 2) + 0.0 * th[1], [0.2, 0.1], lo, hi)
    assert plateau.verdict == "flat" and plateau.cost == 100.0 and plateau.probe_decrease == 0.0
    shallow = check_point(lambda th: 1.0 + 1e-5 * (th[0] ** 2 + th[1] ** 2), [0.0, 0.0], lo, hi)
    assert shallow.verdict == "local minimum"
    edge = check_point(lambda th: jnp.maximum(th[0], 0.0) + 0.0 * th[1], [0.0, 0.0], lo, hi)
    assert edge.verdict == "local minimum"  # flat on one side only: the gradient there is not zero


def test_check_of_a_non_finite_cost_or_gradient_is_data():
    """A failed rollout (nan cost, or a gradient that is not finite) gives a verdict, not an exception."""
    lo, hi = [-1.0, -1.0], [1.0, 1.0]
    nan_cost = check_point(lambda th: jnp.where(th[0] > 0.0, jnp.nan, th[0] ** 2 + th[1] ** 2), [0.5, 0.0], lo, hi)
    assert nan_cost.verdict == "non-finite cost" and nan_cost.quadratic_model == "non-finite"
    assert np.isnan(nan_cost.probe_decrease)
    # finite cost, gradient infinite at the point (sqrt at 0): the Hessian is not formed, the probes still decide
    cusp = check_point(lambda th: jnp.sqrt(jnp.abs(th[0])) + th[1] ** 2, [0.0, 0.0], lo, hi)
    assert cusp.quadratic_model == "non-finite" and cusp.verdict == "local minimum"


def test_parse_gains_forms_and_errors():
    f, n, lo, hi = ("a", "K"), (1, 2), [0, -5, -5], [10, 0, 0]
    want = [1.0, -2.0, -3.0]
    for g in ("1,-2,-3", [1, -2, -3], {"a": 1, "K": [-2, -3]}, '{"a": 1, "K": [-2, -3]}'):
        np.testing.assert_array_equal(parse_gains(g, f, n, lo, hi), want)
    for g, msg in (
        ("1,2", "2 values, expected 3"),
        ("1,x,3", "expected numbers"),
        ({"a": 1, "b": 2}, r"K missing; b unknown; expected a, K\[2\]$"),
        ({"a": 1}, r"K missing; expected a, K\[2\]$"),
        ({"a": 1, "K": [-2, -3], "z": 0}, r"z unknown; expected a, K\[2\]$"),
        ('{"a": 1, "K": [1]}', "K has 1 values"),
        ('{"a": ', "not valid JSON"),
        ("nan,-1,-1", "finite"),
        ("1,,-2,-3", "an empty item"),
        ("1,-2,-3,", "an empty item"),
        ("", "an empty item"),
    ):
        with pytest.raises(ValueError, match=f"^check: .*{msg}"):
            parse_gains(g, f, n, lo, hi)
    # a value outside the box is named by its field (and element)
    with pytest.raises(ValueError, match=r"^check\.K\[1\]: 3 outside the tuning box \[-5, 0\]") as e:
        parse_gains("1,-2,3", f, n, lo, hi)
    assert e.value.key == "check.K[1]"


def test_tune_api_methods_and_check_on_the_simulator():
    small = MultistartOptions(n_screen=8, n_starts=2, steps=4, rounds=2, n_restarts=1, restart_steps=2, polish_steps=0)
    out = pfjax.tune("state_feedback", "paper-line", "gradient", config=SHORT, key=0, multistart=small)
    # 8 screened + the default (source) K; chains 2, 1 for 2 steps; 2 restart chains for 2 steps
    assert out["n_rollouts"] == 9 + 2 * 2 + 1 * 2 + 2 * 2 and out["n_forward_passes"] == 9 + 3 * 10
    # pfjax.tune ran every round on the 2-chain program (a cheap cost); one program per chain count
    # gives the same simulator-cost result to the bit
    from pfjax.tuning.multistart import _Plan
    from pfjax.tuning.problem import make_problem, tune

    # 9 screened points, D = 2; one run per evaluation, a gradient charged 1 + D passes
    assert _Plan.of(small, 9, 2, SHORT.n_steps, 3).programs == (2, 2)
    own = tune(
        make_problem("state_feedback", "paper-line", config=SHORT),
        "gradient",
        key=jax.random.PRNGKey(0),
        multistart=small,
        shared_programs=False,
    )
    np.testing.assert_array_equal(own.theta, out["result"].theta)
    np.testing.assert_array_equal(own.history, out["result"].history)
    both = pfjax.tune("state_feedback", "paper-line", "ga+gradient", config=SHORT, generations=2, population=6, steps=3)
    ga = pfjax.tune("state_feedback", "paper-line", "ga", config=SHORT, generations=2, population=6)
    assert both["cost"] <= ga["cost"] and both["n_rollouts"] == ga["n_rollouts"] + 3
    c = pfjax.tune("state_feedback", "paper-line", config=SHORT, check=out["result"].theta.tolist())
    assert c["check"]["verdict"] in ("local minimum", "not a local minimum") and np.isfinite(c["cost"])
    with pytest.raises(ValueError, match="^check: 1 values, expected 2"):
        pfjax.tune("state_feedback", "paper-line", config=SHORT, check="-3")
    with pytest.raises(ValueError, match="^method: "):
        pfjax.tune("state_feedback", "paper-line", "newton", config=SHORT)


def test_tune_help_lists_methods_and_check(capsys):
    from pfjax.cli import main

    with pytest.raises(SystemExit) as e:
        main(["tune", "--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    for word in (
        "--check GAINS",
        "ga+gradient",
        "gradient-plain",
        "--screen",
        "--sampler",
        "--rounds",
        "--restarts",
        "--polish",
    ):
        assert word in text, word


@pytest.mark.parametrize(
    "argv,flag",
    [
        (["--controller", "pi"], "--method"),
        (["--method", "gradient", "--check", "1,0,1,0", "--controller", "pi"], "--check"),
        (["--check", "1,0,1", "--controller", "pi"], "--check"),
        (["--check", "100,0,1,0", "--controller", "pi"], "--check"),
        (["--method", "gradient", "--controller", "pi", "--sampler", "halton"], "--sampler"),
        (["--method", "gradient", "--controller", "pi", "--screen", "-1"], "--screen"),
        (["--method", "gradient", "--controller", "pi", "--smoothing", "-0.1"], "--smoothing"),
        (["--method", "gradient", "--controller", "pi", "--steps", "0"], "--steps"),
    ],
)
def test_tune_cli_bad_values_exit_2(argv, flag, capsys):
    from pfjax.cli import main

    assert main(["tune", *argv, "--json"]) == 2
    err = capsys.readouterr()
    assert err.out == "" and err.err.startswith(f"pfjax tune: error: {flag}") and err.err.count("\n") == 1


def test_tune_cli_check_json(capsys):
    from pfjax.cli import main

    argv = ["tune", "--check", "-2.7381,-2.0772", "--controller", "state-feedback", "--horizon", "4", "--dt", "0.01"]
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    c = out["check"]
    assert set(c["gradient"]) == {"K[0]", "K[1]"} and c["n_rollouts"] == 1 + 4 + 16
    # the units by the controller's registration: the gains', the box's elements' and the check's
    u = out["units"]
    assert u["gains.k_d"] == "rad/m" and u["gains.k_theta"] == "rad/rad" and u["bounds.lower"] == "rad/m, rad/rad"
    assert u["check.gradient.K[0]"] == "cost per rad/m" and u["check.best_probe.K[1]"] == "rad/rad"
    assert c["verdict"] == "not a local minimum"  # the source's K is far from the IAE optimum
