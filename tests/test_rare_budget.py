"""The rare-event budget and the combination over strata, on Python limit-state functions.

``pfjax.rare.study.limit_state`` and ``falsifier_points`` are replaced by functions of ``u`` alone,
so each test runs a study's estimator code in a fraction of a second without simulating a run:
the importance-sampling estimate rests on a batch of draws, a budget that passes the up-front
check completes (the falsifier's rollouts included, and reported per stratum), and a stratum with
no failure keeps its upper bound in the controller's interval.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ndtr

from pfjax.errors import InputError
from pfjax.montecarlo.config import load_study
from pfjax.rare import cross_entropy_is, study
from pfjax.rare.importance import _moments, least_rollouts


def _spec(paths=("line",), **rare):
    """A study whose inputs are the two constant slips (``u`` of dimension 2)."""
    slip = {"dist": "truncnormal", "mean": 0.0, "std": 1.0, "low": -30.0, "high": 30.0}
    data = {
        "name": "budget",
        "n_runs": 1,
        "seed": 0,
        "slip": {"kind": "constant", "beta_r_deg": slip, "beta_f_deg": slip},
        "margin": {"enabled": False},
        "paths": [{"kind": k} for k in paths],
        "controllers": [{"name": "sf", "type": "state_feedback", "K": [-2.7, -2.1]}],
        "falsifier": {"n_restarts": 2, "steps": 5},
        "rare_event": {"enabled": True, "n_per_level": 100, "batch": 100, **rare},
    }
    return load_study(data=data)[0]


def _fake_studies(monkeypatch, margins, u_star=None):
    """``limit_state`` of stratum ``k``: ``margins[k](u)``, counting its rollouts; the falsifier
    returns ``u_star`` (``1 + n_restarts`` rows) with ``n_restarts x steps`` gradient rollouts."""
    calls = []

    def limit_state(spec, stratum, inputs, controller, *, seed=0, stream=0, counter=None):
        def g(u):
            calls.append(len(u))
            return margins[stream](u)

        return g

    def falsifier_points(spec, stratum, inputs, controller, *, seed=0):
        f = spec.falsifier
        return np.asarray(u_star, dtype=float), f.n_restarts * f.steps, f.n_restarts * f.steps

    monkeypatch.setattr(study, "limit_state", limit_state)
    monkeypatch.setattr(study, "falsifier_points", falsifier_points)
    return calls


def tail(u):
    return 2.0 - u[:, 0]  # p = Φ(-2) = 0.0228


# ------------------------------------------------------------------------- defect: one-draw estimate


def test_the_estimate_rests_on_n_per_level_draws_at_the_least_budget():
    """At the least budget (two levels' worth) and one rollout more, the estimate is a batch of
    ``n_per_level`` draws, with a spread and an interval that holds ``p``."""
    for budget in (200, 201, 301):
        r = cross_entropy_is(tail, 1, n_per_level=100, max_rollouts=budget, seed=0)
        assert r.detail["n_is"] >= 100 and r.n_rollouts == budget, (budget, r.detail)
        assert 0 < r.rel_error < math.inf and r.ci95[0] < r.p_fail < r.ci95[1], r
        assert r.ci95[0] <= ndtr(-2.0) <= r.ci95[1], r


def test_an_estimate_from_fewer_than_two_draws_has_infinite_error():
    assert _moments(0.3, 0.09, 1) == (0.3, math.inf, math.inf)
    assert _moments(0.0, 0.0, 0)[2] == math.inf


# ------------------------------------------------------------------------- defect: budget exhausted


def test_a_budget_below_a_level_and_the_estimate_is_refused_before_g_is_called():
    calls = []

    def g(u):
        calls.append(len(u))
        return tail(u)

    with pytest.raises(InputError, match=r"^max_rollouts: needs at least 200 .* got 199$"):
        cross_entropy_is(g, 1, n_per_level=100, max_rollouts=199)
    assert calls == []
    r = cross_entropy_is(g, 1, n_per_level=100, max_rollouts=300)  # the levels leave the estimate its draws
    assert sum(calls) == r.n_rollouts == 300 and r.detail["n_is"] >= 100


@pytest.mark.parametrize("max_levels, least", [(30, 200), (0, 100)])
def test_the_least_budget_is_one_rule_for_the_estimator_and_the_study(max_levels, least):
    """``least_rollouts`` is the budget ``cross_entropy_is`` refuses below (one rollout less is
    refused, the least itself runs), with and without cross-entropy levels."""
    assert least_rollouts(100, max_levels)[0] == least
    with pytest.raises(InputError, match=rf"^max_rollouts: needs at least {least} "):
        cross_entropy_is(tail, 1, n_per_level=100, max_levels=max_levels, max_rollouts=least - 1)
    r = cross_entropy_is(tail, 1, n_per_level=100, max_levels=max_levels, max_rollouts=least)
    assert r.n_rollouts <= least and r.detail["n_is"] >= 100


def test_the_falsifiers_rollouts_are_not_asked_for_where_it_does_not_run():
    """Fixed slip angles (no slip among the uncertain inputs, the start offset uncertain instead):
    the falsifier does not run, so the least budget is that of ``explore``."""
    data = _spec(starts="falsifier", max_rollouts=300).model_dump(mode="json")
    data["slip"]["beta_r_deg"] = data["slip"]["beta_f_deg"] = {"dist": "constant", "value": 2.0}
    data["initial"]["lateral_offset"] = {"dist": "uniform", "low": -0.5, "high": 0.5}
    spec = load_study(data=data)[0]
    assert study.falsifier_rollouts_at_most(spec) == 0
    assert study.rollouts_needed(spec)[0] == 300
    study.check_budget(spec)


@pytest.mark.parametrize(
    ("starts", "need"),
    [("none", 200), ("explore", 300), ("falsifier", 2 * 5 + 3 * 32 + 300)],  # falsifier: 2 x 5 steps, 3 rays
)
def test_rollouts_needed_counts_every_part_of_the_estimate(starts, need):
    spec = _spec(starts=starts, max_rollouts=need)
    assert study.rollouts_needed(spec)[0] == need
    study.check_budget(spec)
    with pytest.raises(InputError, match=rf"^rare_event\.max_rollouts: is needs at least {need} rollouts per stratum"):
        study.check_budget(_spec(starts=starts, max_rollouts=need - 1))


@pytest.mark.parametrize("finds", [True, False])
def test_the_least_budget_with_the_falsifier_completes_and_reports_its_rollouts(monkeypatch, finds):
    """The falsifier's rollouts (gradients and rays) are inside the budget and ``n_rollouts``, and
    reported per stratum, whether its points lead to failure (starts) or not (explore's fallback)."""
    need = 2 * 5 + 3 * 32 + 300
    u_star = np.full((3, 2), 4.0 if finds else 0.0)  # rays out to u = (4, 4) fail; rays to 0 do not
    calls = _fake_studies(monkeypatch, [tail], u_star)
    spec = _spec(starts="falsifier", max_rollouts=need)
    r = study.estimate_controller(spec, "sf", None)
    s = r["strata"][0]
    assert s["falsifier_rollouts"] == 2 * 5 + 3 * 32, s
    assert r["n_rollouts"] == s["n_rollouts"] == sum(calls) + 2 * 5 <= need, (r["n_rollouts"], sum(calls))
    assert 0 < r["rel_error"] < math.inf and r["ci95"][0] <= ndtr(-2.0) <= r["ci95"][1], r
    _fake_studies(monkeypatch, [tail])
    r = study.estimate_controller(_spec(max_rollouts=300), "sf", None)
    assert r["strata"][0]["falsifier_rollouts"] == 0 and r["n_rollouts"] == 300


# ------------------------------------------------------------------------- defect: strata without failure


def never(u):
    return np.ones(len(u))


@pytest.mark.parametrize("method", ["mc", "is"])
def test_a_stratum_without_failure_keeps_its_upper_bound_in_the_controllers(monkeypatch, method):
    """Two strata of weight 1/2: no failure on the first, ``Φ(-2)`` on the second. The controller's
    relative error is infinite and its interval's top holds both strata's tops, weighted."""
    _fake_studies(monkeypatch, [never, tail])
    spec = _spec(paths=("line", "sine"), method=method, max_rollouts=2000)
    r = study.estimate_controller(spec, "sf", None)
    zero, other = r["strata"]
    assert zero["p_fail"] == 0 and zero["ci95"][1] > 0 and other["p_fail"] > 0
    assert r["p_fail"] == pytest.approx(0.5 * other["p_fail"])
    assert r["rel_error"] == math.inf
    assert r["ci95"][1] >= 0.5 * zero["ci95"][1] + 0.5 * other["p_fail"], r["ci95"]
    assert r["ci95"][0] <= r["p_fail"] <= r["ci95"][1]


def test_strata_with_failures_combine_as_before():
    """Every stratum with a failure and a finite error: the lognormal interval of the weighted sum."""
    from pfjax.rare.estimate import RareEstimate, lognormal_interval

    a = RareEstimate(1e-4, (8e-5, 1.2e-4), 0.1, 100, "is", {})
    b = RareEstimate(3e-4, (2e-4, 4e-4), 0.2, 100, "is", {})
    p, ci, rel = study.combine([(0.5, a), (0.5, b)])
    assert p == pytest.approx(2e-4) and rel == pytest.approx(math.hypot(0.5e-5, 3e-5) / 2e-4)
    assert ci == pytest.approx(lognormal_interval(p, rel))
    assert study.combine([(1.0, a)]) == (1e-4, (8e-5, 1.2e-4), 0.1)
