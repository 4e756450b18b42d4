"""pfjax.rare on the edges a reliability study meets: arguments checked before ``g`` is called,
margins that are infinite or NaN, runs that end at the first level, and the interval of a single
subset-simulation run.

References: ``Φ(-β)`` for the linear limit state ``g(u) = β - u_1`` (whatever ``g`` is where it
cannot fail), the exact binomial (Clopper-Pearson) interval of ``k`` failures in ``n`` draws
(``scipy.stats.beta`` quantiles), and the coverage of 95 % intervals over independent seeds.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy import stats
from scipy.special import ndtr

from pfjax.errors import InputError
from pfjax.rare import cross_entropy_is, lognormal_interval, monte_carlo, subset_simulation


def linear(beta):
    return lambda u: beta - u[:, 0]


def never_called(u):
    raise AssertionError("g was called")


def inside(r, p):
    return r.ci95[0] <= p <= r.ci95[1]


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"refine": float("nan")}, "refine"),
        ({"refine": -1}, "refine"),
        ({"refine": 1.5}, "refine"),
        ({"refine": True}, "refine"),
        ({"starts": np.zeros((0, 2))}, "starts"),
    ],
)
def test_importance_sampling_arguments_are_checked_before_g_is_called(kwargs, key):
    with pytest.raises(InputError) as e:
        cross_entropy_is(never_called, 2, **kwargs)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ") and "\n" not in str(e.value)


def safe_where_negative(beta):
    """``β - u_1`` where ``u_1 >= 0``, ``+inf`` (no failure possible) elsewhere: ``p = Φ(-β)``."""
    return lambda u: np.where(u[:, 0] < 0, np.inf, beta - u[:, 0])


@pytest.mark.parametrize(
    "estimate",
    [
        lambda g: monte_carlo(g, 2, n=20_000, seed=0),
        lambda g: subset_simulation(g, 2, n_per_level=1000, seed=0, target_rel_error=0.2, max_rollouts=50_000),
        lambda g: cross_entropy_is(g, 2, n_per_level=500, seed=0),
    ],
)
def test_an_infinite_margin_is_no_failure(estimate):
    """``+inf`` is a margin (as safe as can be), not a failure; NaN is one."""
    r = estimate(safe_where_negative(2.0))
    assert inside(r, ndtr(-2.0)), r
    r = estimate(lambda u: np.full(len(u), np.inf))
    assert r.p_fail == 0, r
    r = estimate(lambda u: np.full(len(u), np.nan))
    assert r.p_fail > 0.99, r


def test_subset_simulation_steps_below_margins_that_are_mostly_infinite():
    """91 % of the mass at ``+inf``: the levels step below it (no threshold at infinity)."""
    g = lambda u: np.where(u[:, 0] < 1.34, np.inf, 3.719 - u[:, 0])
    r = subset_simulation(g, 2, n_per_level=1000, seed=1, target_rel_error=0.2, max_rollouts=100_000)
    assert all(math.isfinite(lv["threshold"]) for run in r.detail["levels"] for lv in run)
    assert inside(r, ndtr(-3.719)), r


def test_no_warning_where_every_margin_fails():
    """Margins all NaN (every run left the model's domain): ``p`` about 1, no RuntimeWarning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = cross_entropy_is(lambda u: np.full(len(u), np.nan), 2, n_per_level=200, max_rollouts=1000)
    assert r.p_fail > 0.99


def clopper_pearson_reference(k, n):
    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return lo, hi


@pytest.mark.parametrize("beta", [-10.0, 1.0])
def test_runs_that_end_at_level_0_are_binomial(beta):
    """Every run ends at level 0 (``p`` above ``p_0``): independent draws, ``k`` failures in ``R N``,
    the exact interval (a failure in every draw is no certainty: the interval is not ``(1, 1)``)."""
    r = subset_simulation(linear(beta), 2, n_per_level=500, seed=2, target_rel_error=0.05, max_rollouts=5000)
    n = 500 * r.detail["runs"]
    k = round(r.p_fail * n)
    assert r.detail["error"] == "binomial" and r.p_fail == k / n
    assert r.ci95 == pytest.approx(clopper_pearson_reference(k, n), rel=1e-9)
    assert r.rel_error == pytest.approx(math.sqrt((1 - r.p_fail) / (n * r.p_fail)), rel=1e-12)
    assert r.ci95[0] < 1.0 and inside(r, ndtr(-beta))


def test_one_subset_run_takes_the_fully_correlated_bound():
    r = subset_simulation(linear(4.0), 2, n_per_level=500, seed=3)
    d = r.detail["run_estimates"][0]
    assert r.detail["runs"] == 1 and r.detail["error"] == "levels fully correlated"
    assert d["delta_uncorrelated"] < d["delta_correlated"] == r.rel_error
    assert r.ci95 == lognormal_interval(r.p_fail, d["delta_correlated"])


#: Of :func:`test_one_subset_run_interval_covers_at_3e_7`'s 200 runs, those whose 95 % interval holds
#: ``p``: with the levels-uncorrelated error, and with the fully-correlated one the runs report
#: (quoted by docs/rare-events.md).
COVERAGE_3E7 = {"uncorrelated": 0.825, "correlated": 0.99}


def test_one_subset_run_interval_covers_at_3e_7():
    """200 single runs (no target) at ``p = Φ(-5) = 2.9e-7``, ``N = 500``: the reported 95 %
    intervals (levels fully correlated) hold ``p`` in at least 95 % of them, the levels-uncorrelated
    ones in fewer (the levels are correlated through the seeds each passes to the next)."""
    p = ndtr(-5.0)
    runs = [subset_simulation(linear(5.0), 2, n_per_level=500, seed=5000 + s) for s in range(200)]
    hits = np.mean([inside(r, p) for r in runs])
    weak = [lognormal_interval(r.p_fail, r.detail["run_estimates"][0]["delta_uncorrelated"]) for r in runs]
    weak_hits = np.mean([lo <= p <= hi for lo, hi in weak])
    assert weak_hits < 0.95 <= hits, (weak_hits, hits)
    assert {"uncorrelated": weak_hits, "correlated": hits} == COVERAGE_3E7
    doc = " ".join((Path(__file__).resolve().parents[1] / "docs" / "rare-events.md").read_text().split())
    assert f"held `p` in {100 * weak_hits:g} % of them, the fully-correlated one in {100 * hits:g} %" in doc


def test_a_level_below_an_infinite_margin_is_finite():
    """The ``N_c``-th smallest margin finite, the next ``+inf``: the threshold is the finite one
    (no midpoint with infinity), and it holds exactly the ``N_c`` finite points."""
    from pfjax.rare.subset import below, level

    m = np.concatenate([np.arange(10.0), np.full(90, np.inf)])
    t = np.zeros(100)
    b = level(m, t, 10)
    assert b == (9.0, math.inf) and below(m, t, b).sum() == 10


def test_the_modes_are_distinct_failure_points():
    """Components that reach one mean are one failure point, their weights summed; the mixture they
    come from is the same distribution."""
    from pfjax.rare import Mixture
    from pfjax.rare.importance import modes, proposal_logpdf

    means = np.array([[1.0, 0.0], [4.0, 0.0], [1.0, 0.0], [0.0, -4.0]])
    mix = Mixture(np.array([0.1, 0.4, 0.2, 0.3]), means, np.repeat(np.eye(2)[None], 4, axis=0))
    m = modes(mix)
    found = {tuple(mu): w for mu, w in zip(m["means"], m["weights"])}
    assert found == pytest.approx({(4.0, 0.0): 0.4, (0.0, -4.0): 0.3, (1.0, 0.0): 0.3}, abs=1e-15)
    assert m["weights"] == sorted(m["weights"], reverse=True)
    merged = Mixture(np.asarray(m["weights"]), np.asarray(m["means"]), np.repeat(np.eye(2)[None], 3, axis=0))
    u = np.random.default_rng(0).standard_normal((50, 2)) * 3
    assert proposal_logpdf(u, merged, 0.1) == pytest.approx(proposal_logpdf(u, mix, 0.1), rel=1e-12)


def test_cross_entropy_modes_hold_no_duplicate():
    """Elite weights on one point pull two components onto it (here: 4 components, 3 means)."""
    from pfjax.rare.importance import explore

    g = lambda u: np.minimum(4.5 - u[:, 0], 4.0 + u[:, 1])
    starts, _ = explore(g, 4, n=100, seed=2)
    r = cross_entropy_is(g, 4, starts=starts, n_components=4, n_per_level=100, n_batch=100, max_rollouts=1000, seed=2)
    means = np.asarray(r.detail["modes"]["means"])
    assert len(np.unique(means, axis=0)) == len(means)
    assert sum(r.detail["modes"]["weights"]) == pytest.approx(1.0, abs=1e-12)


def test_command_line_help_names_the_config_defaults(capsys):
    """The defaults of ``--method``, ``--target-rel-error``, ``--max-rollouts`` and ``--seed`` are the
    config's ``[rare_event]`` values, and without them :class:`RareEventSpec`'s."""
    from pfjax.cli import main
    from pfjax.montecarlo.config import RareEventSpec

    with pytest.raises(SystemExit):
        main(["rare-event", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    spec = RareEventSpec()
    for key in ("method", "target_rel_error", "max_rollouts", "seed"):
        assert f"(default: the config's rare_event.{key}, else {getattr(spec, key)})" in out, key


def _study_pi(method: str, max_rollouts: int, **overrides) -> dict:
    """The packaged rare-event study's PI (16 s runs) by ``method``: its result."""
    import pfjax

    root = Path(__file__).resolve().parents[1]
    out = pfjax.rare_event(
        str(root / "studies" / "rare_events.toml"),
        controller="pi-table3",
        method=method,
        max_rollouts=max_rollouts,
        **{"sim.horizon": 16.0, **overrides},
    )
    return out["controllers"]["pi-table3"]


def test_a_stratum_without_a_failure_is_flagged_no_failures():
    """Plain Monte Carlo on too small a budget sees no failure of the study's PI: every stratum's
    estimate is 0, and the controller says so (status ``no_failures``, each path named with the
    rollouts spent and the interval's upper end) instead of ``ok``."""
    r = _study_pi("mc", 300)
    assert r["p_fail"] == 0 and r["status"] == "no_failures", r["status"]
    for s in r["strata"]:
        assert f"{s['path']}: no failure found in {s['n_rollouts']} rollouts" in r["warning"], r["warning"]
    assert f"a 95 % upper bound of {r['strata'][0]['ci95'][1]:.3g} (exact binomial)" in r["warning"]


def test_no_failures_says_what_bounds_p_by_method():
    """Importance sampling and subset simulation that never reach the failure region give no bound
    (their interval reaches 1), and the flag says so; plain Monte Carlo's exact upper end is given."""
    from pfjax.rare.study import no_failures

    never = lambda u: np.full(len(u), np.inf)
    for est in (cross_entropy_is(never, 2, n_per_level=500), subset_simulation(never, 2, n_per_level=500)):
        assert est.p_fail == 0 and est.ci95[1] == 1.0
        flag = no_failures(est)
        assert flag["status"] == "no_failures" and f"{est.method} gives no bound" in flag["warning"], flag
    mc = monte_carlo(never, 2, n=1000)
    assert "95 % upper bound of" in no_failures(mc)["warning"]


def test_a_subset_study_says_what_each_stratum_interval_rests_on():
    """A study by subset simulation carries each stratum's ``error`` (what its interval rests on:
    one run per stratum here, so the fully-correlated bound), as the estimator's ``detail`` does."""
    strata = _study_pi("subset", 6000, **{"rare_event.n_per_level": 500})["strata"]
    assert len(strata) == 3
    for s in strata:
        assert len(s["run_estimates"]) == 1 and s["error"] == "levels fully correlated", s


@pytest.mark.parametrize("metric", ["iae", "ise"])
def test_a_metric_not_in_metres_needs_its_own_threshold(metric, tmp_path, capsys):
    """The default threshold is the success band, a distance in m: for IAE (m s) or ISE (m^2 s) it
    would compare numbers of different units, so the config refuses no threshold for them, in the
    command line, the Python API and a study alike (one check, in RareEventSpec)."""
    import pfjax
    from pfjax.cli import main
    from pfjax.config import ConfigError
    from pfjax.montecarlo.analysis_config import RareEventSpec

    with pytest.raises(ValueError, match=rf"threshold: needed for metric = '{metric}'"):
        RareEventSpec(metric=metric)
    assert RareEventSpec(metric=metric, threshold=1.0).threshold == 1.0
    assert RareEventSpec(metric="overshoot").threshold is None  # in m: the band serves
    toml = Path(__file__).resolve().parents[1] / "studies" / "rare_events.toml"
    text = toml.read_text().replace("threshold = 0.5", "")
    assert text != toml.read_text()
    config = tmp_path / "no_threshold.toml"
    config.write_text(text)
    args = ["rare-event", str(config), "--controller", "pi-table3", "--set", f'rare_event.metric="{metric}"']
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("pfjax rare-event: error: rare_event.threshold: needed for metric") and err.count("\n") == 1
    with pytest.raises(ConfigError, match=r"^rare_event\.threshold: needed for metric"):
        pfjax.rare_event(str(config), controller="pi-table3", rare_event__metric=metric)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["no_threshold.toml"]  # nothing written


def test_the_api_takes_the_budget_bounds_from_the_config_model():
    from pfjax.config import field_limits
    from pfjax.montecarlo.analysis_config import RareEventSpec

    assert field_limits(RareEventSpec, "target_rel_error") == {"gt": 0, "le": 10}
    assert field_limits(RareEventSpec, "max_rollouts") == {"ge": 100, "le": 100_000_000}
