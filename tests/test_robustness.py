"""Robustness statistics against independent references.

* Clopper-Pearson against ``scipy.stats.binomtest(k, n).proportion_ci(method="exact")`` and its
  coverage (exact sum over the binomial pmf, and seeded simulation) at least nominal;
* the sample-size bounds against their closed forms and their defining inequalities
  (``n`` satisfies it, ``n - 1`` does not);
* the slip margin on synthetic sweeps with a known logistic success curve
  ``p(a) = 1 / (1 + exp((a - a50) / s))``, whose ``1 - eps`` crossing is
  ``a* = a50 + s ln(eps / (1 - eps))``;
* failure drivers on synthetic runs whose failure depends on ``|beta_r|`` only;
* quantiles against ``numpy.nanquantile``.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from pfjax.metrics.margins import slip_margin
from pfjax.metrics.robustness import (
    clopper_pearson,
    failure_drivers,
    hoeffding_n,
    metric_quantiles,
    success_summary,
    supported_statement,
    zero_failure_n,
)

# scipy finds the exact interval by root finding (brentq, xtol = 2e-12): agreement to 1e-11
# absolute; the defining tail equations are checked to ~1e-15 separately.
CP_ABS = 1e-11


def _scipy_exact(k, n, conf):
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=conf, method="exact")
    return ci.low, ci.high


def _check_against_scipy(k, n, conf):
    lo, hi = clopper_pearson(k, n, conf)
    ref_lo, ref_hi = _scipy_exact(k, n, conf)
    assert lo == pytest.approx(ref_lo, rel=1e-9, abs=CP_ABS)
    assert hi == pytest.approx(ref_hi, rel=1e-9, abs=CP_ABS)
    # the defining tails: P(Bin(n, lo) >= k) = alpha/2 = P(Bin(n, hi) <= k)
    half_alpha = (1 - conf) / 2
    if k > 0:
        assert stats.binom.sf(k - 1, n, lo) == pytest.approx(half_alpha, rel=1e-9)
    if k < n:
        assert stats.binom.cdf(k, n, hi) == pytest.approx(half_alpha, rel=1e-9)
    return lo, hi


# --- Clopper-Pearson ---------------------------------------------------------------------------


@pytest.mark.parametrize("conf", [0.8, 0.9, 0.95, 0.99])
@pytest.mark.parametrize("n", [1, 2, 3, 7, 20, 101, 1000, 10_000])
def test_clopper_pearson_matches_scipy_binomtest(n, conf):
    ks = sorted({0, 1, 2, n // 3, n // 2, n - 2, n - 1, n} & set(range(n + 1)))
    for k in ks:
        _check_against_scipy(k, n, conf)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, 5000), frac=st.floats(0.0, 1.0), conf=st.floats(0.5, 0.999))
def test_clopper_pearson_matches_scipy_property(n, frac, conf):
    k = round(frac * n)
    lo, hi = _check_against_scipy(k, n, conf)
    assert 0.0 <= lo <= k / n <= hi <= 1.0


@settings(max_examples=200, deadline=None)
@given(n=st.integers(1, 10**6), frac=st.floats(0, 1), conf=st.sampled_from([0.5, 0.8, 0.9, 0.95, 0.99, 0.999]))
def test_clopper_pearson_is_the_beta_quantile_of_scipy_stats(n, frac, conf):
    # the inverse regularised incomplete beta function is scipy.stats.beta.ppf's own: equal, not close
    k, alpha = round(frac * n), 1 - conf
    lo, hi = clopper_pearson(k, n, conf)
    assert lo == (0.0 if k == 0 else float(stats.beta.ppf(alpha / 2, k, n - k + 1)))
    assert hi == (1.0 if k == n else float(stats.beta.ppf(1 - alpha / 2, k + 1, n - k)))


def test_clopper_pearson_edges():
    assert clopper_pearson(0, 10)[0] == 0.0
    assert clopper_pearson(10, 10)[1] == 1.0
    # k = 0: hi solves (1 - hi)^n = alpha/2; k = n: lo solves lo^n = alpha/2
    assert clopper_pearson(0, 10)[1] == pytest.approx(1 - 0.025 ** (1 / 10), rel=1e-12)
    assert clopper_pearson(10, 10)[0] == pytest.approx(0.025 ** (1 / 10), rel=1e-12)
    assert all(math.isnan(v) for v in clopper_pearson(0, 0))
    for bad in [(-1, 5), (6, 5), (1, -1)]:
        with pytest.raises(ValueError):
            clopper_pearson(*bad)
    with pytest.raises(ValueError, match="conf"):
        clopper_pearson(1, 5, conf=1.0)


@pytest.mark.parametrize("n", [10, 40, 200])
def test_clopper_pearson_exact_coverage_is_at_least_nominal(n):
    """coverage(p) = sum_k Bin(k; n, p) 1[lo_k <= p <= hi_k] >= conf for every p (dense grid)."""
    conf = 0.95
    lo, hi = np.array([clopper_pearson(k, n, conf) for k in range(n + 1)]).T
    ps = np.linspace(0.001, 0.999, 999)
    pmf = stats.binom.pmf(np.arange(n + 1)[None, :], n, ps[:, None])
    covered = (lo[None, :] <= ps[:, None]) & (ps[:, None] <= hi[None, :])
    coverage = (pmf * covered).sum(axis=1)
    assert coverage.min() >= conf - 1e-12


@pytest.mark.parametrize("p", [0.02, 0.3, 0.5, 0.93, 0.995])
def test_clopper_pearson_simulated_coverage(p):
    """Seeded simulation: the fraction of intervals covering p is nominal or above, within 3 SE."""
    conf, n, draws = 0.95, 60, 20_000
    rng = np.random.default_rng(1234)
    lo, hi = np.array([clopper_pearson(k, n, conf) for k in range(n + 1)]).T
    k = rng.binomial(n, p, size=draws)
    coverage = np.mean((lo[k] <= p) & (p <= hi[k]))
    assert coverage >= conf - 3 * math.sqrt(conf * (1 - conf) / draws)


def test_success_summary():
    s = np.array([True] * 97 + [False] * 3)
    out = success_summary(s)
    assert out["n"] == 100 and out["k"] == 97 and out["success_rate"] == pytest.approx(0.97)
    assert out["success_ci95"] == pytest.approx(list(_scipy_exact(97, 100, 0.95)), rel=1e-9)
    assert success_summary(s.astype(int))["success_ci95"] == out["success_ci95"]
    json.dumps(out)
    empty = success_summary(np.array([], dtype=bool))
    assert empty["n"] == 0 and math.isnan(empty["success_rate"])
    with pytest.raises(ValueError):
        success_summary(np.array([0.5, 1.0]))


# --- quantiles ---------------------------------------------------------------------------------


def test_metric_quantiles_against_nanquantile():
    rng = np.random.default_rng(0)
    n = 1001
    settle = rng.exponential(2.0, n)
    settle[rng.random(n) < 0.2] = np.nan  # not settled
    df = pd.DataFrame(
        {
            "iae": rng.lognormal(0.0, 1.0, n),
            "settling_time": settle,
            "never": np.full(n, np.nan),
            "success": rng.random(n) < 0.9,
        }
    )
    df.loc[3, "iae"] = np.inf  # a diverged run: not finite, not counted
    qs = (0.05, 0.25, 0.5, 0.75, 0.95, 0.99)
    out = metric_quantiles(df, ["iae", "settling_time", "never", "success"])
    for col in ["iae", "settling_time", "success"]:
        x = df[col].to_numpy(dtype=float)
        x = np.where(np.isfinite(x), x, np.nan)
        ref = np.nanquantile(x, qs)
        got = [out[col][key] for key in ["q05", "q25", "q50", "q75", "q95", "q99"]]
        np.testing.assert_allclose(got, ref, rtol=1e-14)
        assert out[col]["mean"] == pytest.approx(np.nanmean(x), rel=1e-14)
        assert out[col]["std"] == pytest.approx(np.nanstd(x, ddof=1), rel=1e-12)
        assert out[col]["n_finite"] == int(np.isfinite(x).sum())
    assert out["iae"]["n_finite"] == n - 1
    assert out["never"]["n_finite"] == 0 and math.isnan(out["never"]["q50"])
    assert set(metric_quantiles(df, ["iae"], qs=(0.5, 0.975))["iae"]) == {"mean", "std", "q50", "q97.5", "n_finite"}
    with pytest.raises(KeyError, match="nope"):
        metric_quantiles(df, ["nope"])


# --- sample-size bounds ------------------------------------------------------------------------


def test_sample_sizes_known_values():
    # ln(40) / (2 * 0.01^2) = 18444.4 ; ln(20) / -ln(0.99) = 298.07
    assert hoeffding_n(0.01, 0.05) == 18445
    assert zero_failure_n(0.01, 0.05) == 299
    assert zero_failure_n(0.05, 0.05) == 59  # the "rule of three": about 3 / eps


@settings(max_examples=200, deadline=None)
@given(eps=st.floats(1e-3, 0.5), delta=st.floats(1e-6, 0.5))
def test_sample_sizes_formulas_and_defining_inequalities(eps, delta):
    tol = 1e-12  # relative: `1 - eps` and `exp` round; the bounds sit exactly on a boundary at times
    nh = hoeffding_n(eps, delta)
    assert abs(nh - math.ceil(math.log(2 / delta) / (2 * eps**2))) <= 1  # +-1: float rounding only
    assert 2 * math.exp(-2 * nh * eps**2) <= delta * (1 + tol)
    assert nh == 1 or 2 * math.exp(-2 * (nh - 1) * eps**2) > delta * (1 - tol)
    nz = zero_failure_n(eps, delta)
    assert abs(nz - math.ceil(math.log(1 / delta) / math.log(1 / (1 - eps)))) <= 1
    assert (1 - eps) ** nz <= delta * (1 + tol)
    assert nz == 1 or (1 - eps) ** (nz - 1) > delta * (1 - tol)
    assert nz <= nh  # -ln(1 - eps) >= eps >= 2 eps^2 for eps <= 1/2: zero failures need fewer runs


def test_sample_sizes_reject_bad_arguments():
    for f in (hoeffding_n, zero_failure_n):
        with pytest.raises(ValueError, match="eps"):
            f(0.0, 0.05)
        with pytest.raises(ValueError, match="delta"):
            f(0.1, 1.0)


# --- supported statement -----------------------------------------------------------------------


def test_supported_statement_zero_failures():
    eps, delta = 0.01, 0.05
    n = zero_failure_n(eps, delta)
    out = supported_statement(n, 0, delta)
    assert out["zero_failure_eps"] == pytest.approx(1 - delta ** (1 / n), rel=1e-12)
    assert out["zero_failure_eps"] <= eps < supported_statement(n - 1, 0, delta)["zero_failure_eps"]
    # the one-sided Clopper-Pearson bound with no failure is delta^(1/n) = 1 - eps_0
    assert out["cp_lower"] == pytest.approx(1 - out["zero_failure_eps"], rel=1e-12)
    assert out["success_rate"] == 1.0 and out["confidence"] == pytest.approx(0.95)
    assert out["hoeffding_eps"] == pytest.approx(math.sqrt(math.log(2 / delta) / (2 * n)), rel=1e-14)
    assert out["hoeffding_lower"] == pytest.approx(1 - out["hoeffding_eps"])
    assert "299 runs" in out["text"] and f"{out['zero_failure_eps']:.3g}" in out["text"]
    json.dumps(out)


@pytest.mark.parametrize("n,k_fail,delta", [(100, 3, 0.05), (10_000, 37, 0.01), (50, 50, 0.05), (7, 1, 0.1)])
def test_supported_statement_with_failures(n, k_fail, delta):
    out = supported_statement(n, k_fail, delta)
    p_hat = (n - k_fail) / n
    ref = stats.binomtest(n - k_fail, n, alternative="greater").proportion_ci(
        confidence_level=1 - delta, method="exact"
    )
    assert out["cp_lower"] == pytest.approx(ref.low, rel=1e-9, abs=CP_ABS)
    assert out["zero_failure_eps"] is None
    assert out["success_rate"] == pytest.approx(p_hat)
    eps_h = math.sqrt(math.log(2 / delta) / (2 * n))
    assert out["hoeffding_eps"] == pytest.approx(eps_h, rel=1e-14)
    assert out["hoeffding_lower"] == pytest.approx(max(0.0, p_hat - eps_h), abs=1e-15)
    assert out["cp_lower"] >= out["hoeffding_lower"]  # the exact bound is the tighter one here
    # at the Hoeffding sample size for (eps, delta) the radius is within eps
    assert supported_statement(hoeffding_n(0.02, delta), 0, delta)["hoeffding_eps"] <= 0.02
    assert str(k_fail) in out["text"] and f"{out['cp_lower']:.4f}" in out["text"]
    with pytest.raises(ValueError):
        supported_statement(0, 0)
    with pytest.raises(ValueError):
        supported_statement(5, 6)


# --- slip margin -------------------------------------------------------------------------------

A50, SCALE = 8.0, 0.8  # logistic success curve p(a) = 1 / (1 + exp((a - A50) / SCALE)), a in deg


def _p_true(a):
    return 1.0 / (1.0 + np.exp((np.asarray(a) - A50) / SCALE))


def _crossing(eps):
    return A50 + SCALE * math.log(eps / (1 - eps))


def _margin_reference(a, r, thr):
    """Brute force: the largest a_j with r_i >= thr for all i <= j (0 if none)."""
    best = 0.0
    for j in range(len(a)):
        if all(r[i] >= thr for i in range(j + 1)):
            best = a[j]
    return best


@pytest.mark.parametrize("eps", [0.01, 0.05, 0.2])
def test_slip_margin_large_n_finds_true_crossing(eps):
    rng = np.random.default_rng(7)
    a = np.arange(0.0, 14.01, 0.5)
    n = np.full(a.size, 200_000)
    out = slip_margin(a, rng.binomial(n, _p_true(a)), n, eps=eps)
    a_true = _crossing(eps)
    assert out["resolution"] == pytest.approx(0.5)
    assert out["margin"] <= a_true < out["margin"] + out["resolution"]
    assert out["margin_lo"] <= out["margin"] <= out["margin_hi"]
    assert abs(out["margin_lo"] - a_true) <= out["resolution"]
    assert abs(out["margin_hi"] - a_true) <= out["resolution"]
    assert not out["censored"] and out["eps"] == eps
    rows = out["table"]
    assert [r["amplitude"] for r in rows] == list(a) and rows[3]["n"] == 200_000
    assert rows[3]["lo"] <= rows[3]["rate"] == rows[3]["k"] / rows[3]["n"] <= rows[3]["hi"]
    json.dumps(out)


def test_slip_margin_lower_bound_is_conservative():
    """P(margin_lo > true crossing) <= alpha/2: it needs a CP miss at the first amplitude past it."""
    rng = np.random.default_rng(11)
    a = np.arange(0.0, 14.01, 1.0)
    n = np.full(a.size, 100)
    a_true = _crossing(0.05)
    reps = 400
    too_high = sum(slip_margin(a, rng.binomial(n, _p_true(a)), n)["margin_lo"] > a_true for _ in range(reps))
    assert too_high / reps <= 0.025 + 3 * math.sqrt(0.025 * 0.975 / reps)


@settings(max_examples=80, deadline=None)
@given(data=st.data(), m=st.integers(1, 12), eps=st.sampled_from([0.01, 0.05, 0.1, 0.3]))
def test_slip_margin_rule_and_ordering_property(data, m, eps):
    a = np.cumsum(data.draw(st.lists(st.floats(0.1, 3.0), min_size=m, max_size=m)))
    n = np.array(data.draw(st.lists(st.integers(1, 60), min_size=m, max_size=m)))
    k = np.array([data.draw(st.integers(0, int(nj))) for nj in n])
    out = slip_margin(a, k, n, eps=eps)
    rows = out["table"]
    for key, col in [("margin", "rate"), ("margin_lo", "lo"), ("margin_hi", "hi")]:
        assert out[key] == _margin_reference(a, [r[col] for r in rows], 1 - eps)
    assert out["margin_lo"] <= out["margin"] <= out["margin_hi"]
    assert out["censored"] == (out["margin"] == a[-1] and all(k / n >= 1 - eps))


def test_slip_margin_every_smaller_amplitude_rule():
    a = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    n = np.full(5, 1000)
    k = np.array([1000, 990, 800, 1000, 995])  # a dip at 3 deg, passes again at 4 and 5
    out = slip_margin(a, k, n, eps=0.05)
    assert out["margin"] == 2.0 and not out["censored"]
    assert out["resolution"] == 1.0
    assert out["margin_hi"] == 2.0  # 0.8 is far from 0.95 even optimistically


def test_slip_margin_censored_and_failing_first():
    a = np.array([2.0, 4.0, 6.0, 10.0])
    n = np.full(4, 500)
    allpass = slip_margin(a, n, n, eps=0.05)
    assert allpass["margin"] == 10.0 and allpass["censored"] and allpass["resolution"] == 4.0
    assert allpass["margin_hi"] == 10.0
    first_fails = slip_margin(a, np.array([300, 500, 500, 500]), n, eps=0.05)
    assert first_fails["margin"] == 0.0 and not first_fails["censored"]
    assert first_fails["margin_lo"] == 0.0 and first_fails["resolution"] == 2.0
    assert first_fails["fails_at_smallest"] and first_fails["fails_at_smallest_lo"]
    assert first_fails["fails_at_smallest_hi"] and first_fails["table"][0]["hi"] < 0.7  # 300 of 500
    single = slip_margin([5.0], [10], [10], eps=0.05)
    assert single["censored"] and math.isnan(single["resolution"]) and single["margin_lo"] == 0.0
    assert not allpass["fails_at_smallest"] and not allpass["fails_at_smallest_lo"]


def test_a_reading_that_fails_at_the_smallest_amplitude_is_flagged_not_told_by_its_zero():
    """A sweep from 0 deg whose every amplitude passes 20 of 20: the point estimate is safe to 10 deg
    (censored), but the lower CP bound at 20 of 20, (0.025)^(1/20) = 0.83, misses 0.95 already at
    0 deg: margin_lo is 0 with its flag (no conservative margin), unlike a sweep that passes at 0 and
    fails at the next amplitude, whose margin of 0 is a margin."""
    a, n = np.array([0.0, 5.0, 10.0]), np.full(3, 20)
    out = slip_margin(a, n, n, eps=0.05)
    assert out["table"][0]["lo"] == pytest.approx(0.025 ** (1 / 20)) and out["table"][0]["lo"] < 0.95
    assert out["margin"] == 10.0 and out["censored"] and not out["fails_at_smallest"]
    assert out["margin_lo"] == 0.0 and out["fails_at_smallest_lo"] and not out["fails_at_smallest_hi"]
    safe_at_0 = slip_margin(a, np.array([1000, 500, 500]), np.array([1000, 1000, 1000]), eps=0.05)
    assert safe_at_0["margin"] == safe_at_0["margin_lo"] == 0.0
    assert not safe_at_0["fails_at_smallest"] and not safe_at_0["fails_at_smallest_lo"]
    from pfjax.report.study_format import fmt_margin

    assert fmt_margin(out) == "≥ 10° [none, 10]" and fmt_margin(safe_at_0) == "0° [0, 0]"


def test_slip_margin_sorts_and_validates():
    a, n, k = np.array([3.0, 1.0, 2.0]), np.array([100, 100, 100]), np.array([10, 100, 99])
    out = slip_margin(a, k, n, eps=0.05)
    assert [r["amplitude"] for r in out["table"]] == [1.0, 2.0, 3.0]
    assert [r["k"] for r in out["table"]] == [100, 99, 10] and out["margin"] == 2.0
    for bad in [
        ([1.0, 1.0], [1, 1], [1, 1]),
        ([1.0], [2], [1]),
        ([1.0], [0], [0]),
        ([-1.0], [1], [1]),
        ([1.0, 2.0], [1], [1, 1]),
        ([], [], []),
    ]:
        with pytest.raises(ValueError):
            slip_margin(*(np.asarray(v) for v in bad))


# --- failure drivers ---------------------------------------------------------------------------


def _synthetic_runs(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    beta_r = rng.uniform(-10.0, 10.0, n)
    df = pd.DataFrame(
        {
            "beta_r": beta_r,
            "beta_f": rng.uniform(-10.0, 10.0, n),
            "speed": rng.uniform(0.5, 2.0, n),
            "d0": rng.normal(0.0, 0.3, n),
        }
    )
    p_fail = 1.0 / (1.0 + np.exp(-(np.abs(beta_r) - 7.0) / 0.5))  # depends on |beta_r| only
    df["success"] = rng.random(n) >= p_fail
    df["iae"] = 0.1 + 0.02 * np.abs(beta_r) ** 2 + rng.normal(0.0, 0.05, n)
    return df


def test_failure_drivers_finds_abs_beta_r():
    df = _synthetic_runs()
    out = failure_drivers(df, ["beta_r", "beta_f", "speed", "d0"])
    assert list(out.columns) == ["parameter", "rho_failure", "p_failure", "rho_metric", "p_metric", "effect_size", "n"]
    assert set(out["parameter"]) == {
        "beta_r",
        "abs_beta_r",
        "beta_f",
        "abs_beta_f",
        "speed",
        "d0",
        "abs_d0",
    }  # speed > 0: no abs row
    top = out.iloc[0]
    assert top["parameter"] == "abs_beta_r"
    assert top["rho_failure"] > 0.4 and top["p_failure"] < 1e-50
    assert top["rho_metric"] > 0.9 and top["effect_size"] > 1.0
    others = out[out["parameter"] != "abs_beta_r"]
    assert (others["rho_failure"].abs() < 0.06).all()  # SE ~ 1/sqrt(n) = 0.016
    assert (others["rho_metric"].abs() < 0.06).all()
    assert np.all(np.diff(out["rho_failure"].abs().to_numpy()) <= 0)  # sorted by |rho| descending
    # effect size by hand
    x, f = np.abs(df["beta_r"].to_numpy()), ~df["success"].to_numpy()
    assert top["effect_size"] == pytest.approx((x[f].mean() - x[~f].mean()) / x.std(ddof=1), rel=1e-12)
    ref = stats.spearmanr(x, f.astype(float))
    assert top["rho_failure"] == pytest.approx(ref.statistic, rel=1e-12)
    assert top["n"] == len(df)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(3, 400),
    ties=st.sampled_from([None, 0, 1]),
    kind=st.sampled_from(["noise", "binary", "monotone", "reversed"]),
    seed=st.integers(0, 2**32 - 1),
)
def test_spearman_is_scipys_statistic_and_p_value(n, ties, kind, seed):
    from pfjax.metrics.robustness import _spearman

    rng = np.random.default_rng(seed)
    x = rng.normal(size=n)
    x = x if ties is None else np.round(x, ties)  # ties in x
    y = {
        "noise": 0.5 * x + rng.normal(size=n),
        "binary": (rng.random(n) < 0.3).astype(float),  # a failure indicator: ties in y
        "monotone": np.exp(x),  # rho = 1 without ties in x
        "reversed": -(x**3),
    }[kind]
    if np.ptp(x) == 0 or np.ptp(y) == 0:
        assert all(math.isnan(v) for v in _spearman(x, y))
        return
    ref = stats.spearmanr(x, y)
    # the same arithmetic (average ranks, their correlation, Student's t): equal, not close
    assert _spearman(x, y) == (float(ref.statistic), float(ref.pvalue))


def test_failure_drivers_degenerate_cases_are_nan_not_errors():
    df = _synthetic_runs(n=200)
    df["success"] = True  # no failure: nothing to correlate with
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = failure_drivers(df, ["beta_r", "speed"], metric=None)
    assert out["rho_failure"].isna().all() and out["effect_size"].isna().all()
    assert out["rho_metric"].isna().all()
    df = _synthetic_runs(n=200)
    df.loc[:9, "iae"] = np.nan  # a NaN metric drops those rows from the metric correlation only
    out = failure_drivers(df, ["beta_r"], metric="iae")
    assert out["rho_metric"].notna().all()
    with pytest.raises(KeyError, match="nope"):
        failure_drivers(df, ["nope"])


def test_a_studys_metric_statistics_leave_failed_runs_out():
    """A run that diverges at once has an IAE of 0 (its metrics stop at the failure): the summary's
    IAE statistics are over the runs that ran the whole horizon, the success rate over every run."""
    import pandas as pd

    from pfjax.metrics.running import METRIC_NAMES
    from pfjax.montecarlo.summary import run_statistics

    n = 6
    df = pd.DataFrame({m: np.ones(n) for m in METRIC_NAMES if m != "success"})
    df["iae"] = [2.0, 4.0, 6.0, 0.0, 0.0, 0.0]
    df["success"] = [True, True, False, False, False, False]
    df["status"] = ["ok", "ok", "ok", "diverged", "diverged", "nonfinite"]
    b = run_statistics(df)
    assert b["n"] == 6 and b["k"] == 2
    assert b["iae_mean"] == 4.0 and b["quantiles"]["iae"]["n_finite"] == 3
    assert b["status_counts"] == {"ok": 3, "diverged": 2, "nonfinite": 1}
    every_run_failed = run_statistics(df.assign(status="diverged", success=False))
    assert np.isnan(every_run_failed["iae_mean"]) and every_run_failed["success_rate"] == 0.0


def test_rho_iae_of_the_failure_drivers_leaves_failed_runs_out():
    """Runs that diverge at once (IAE 0) at large offsets would make IAE fall with the offset; over
    the runs with status ok it rises, and equals scipy's Spearman rho there. rho fail uses every run."""
    import pandas as pd
    from scipy.stats import spearmanr

    from pfjax.montecarlo.summary import driver_table

    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1.0, 200)
    failed = x > 0.7
    iae = np.where(failed, 0.0, x + 0.1 * rng.normal(size=200))
    df = pd.DataFrame({"d0": x, "iae": iae, "success": ~failed, "status": np.where(failed, "diverged", "ok")})
    row = driver_table(df, ["d0"]).set_index("parameter").loc["d0"]
    ok = ~failed
    assert row["rho_metric"] == pytest.approx(spearmanr(x[ok], iae[ok]).statistic, abs=1e-12)
    assert row["rho_metric"] > 0.5 and spearmanr(x, iae).statistic < 0
    assert row["rho_failure"] == pytest.approx(spearmanr(x, failed).statistic, abs=1e-12)


def test_worst_first_orders_failures_by_time_then_late_error():
    """The report's and notebook 02's order of the worst runs: failed first (earliest first), then
    the largest |d| over the success window, stable on ties; checked against a sort by a key tuple."""
    from pfjax.metrics.robustness import worst_first

    rng = np.random.default_rng(5)
    n = 200
    runs = pd.DataFrame(
        {
            "status": rng.choice(["ok", "diverged", "singular"], n, p=[0.7, 0.2, 0.1]),
            "fail_time": rng.choice([1.0, 2.5, 7.0], n),
            "late_max_abs_d": rng.choice([0.01, 0.02, np.nan, 0.5], n),
            "run": np.arange(n),
        }
    )
    runs.loc[runs.status == "ok", "fail_time"] = np.nan
    got = worst_first(runs)["run"].tolist()

    def key(r):
        late = np.inf if np.isnan(r.late_max_abs_d) else r.late_max_abs_d
        ft = np.inf if np.isnan(r.fail_time) else r.fail_time
        return (r.status == "ok", ft, -late, r.run)

    assert got == [r.run for r in sorted(runs.itertuples(), key=key)]
    assert runs.loc[got[0], "status"] != "ok" and worst_first(runs.iloc[:0]).empty
    twice = pd.concat([runs, runs])  # repeated index labels: the rows themselves, each once
    again = worst_first(twice)["run"]
    assert len(again) == 2 * n and again.value_counts().eq(2).all() and again.iloc[0] == got[0]


@pytest.mark.parametrize("eps", [0.01, 0.05, 0.2])
@pytest.mark.parametrize("delta", [0.05, 0.025])
def test_certify_n_is_the_smallest_n_whose_cp_bound_reaches_the_claim(eps, delta):
    """certify_n against a scan of n with scipy's beta quantile (the one-sided Clopper-Pearson lower
    bound of n - k successes in n runs); k = 0 is zero_failure_n's closed form."""
    from scipy.stats import beta

    from pfjax.metrics.robustness import certify_n, zero_failure_n

    def bound(n, k):
        return beta.ppf(delta, n - k, k + 1)

    for k in (0, 1, 2, 5):
        n = certify_n(eps, delta, k)
        assert bound(n, k) >= 1 - eps - 1e-12 and (n - 1 <= k or bound(n - 1, k) < 1 - eps + 1e-12)
    assert certify_n(eps, delta) == zero_failure_n(eps, delta)
    assert certify_n(0.01, 0.05, 1) == 473 and certify_n(0.01, 0.05, 10) == 1693
    with pytest.raises(ValueError, match="k_fail"):
        certify_n(eps, delta, -1)
    for bad in (0.5, 0.6):  # a one-sided bound below 50 % confidence: refused naming delta, for every k
        for k in (0, 2):
            with pytest.raises(ValueError, match=r"^delta: must be < 0\.5"):
                certify_n(eps, bad, k)


@pytest.mark.parametrize(
    ("b", "c", "n", "said"),
    [
        (5, 0, 3, r"^need b, c >= 0 and b \+ c <= n"),
        (2, 3, 4, r"^need b, c >= 0 and b \+ c <= n"),
        (-1, 0, 3, r"^b: expected a whole number >= 0"),
        (1.5, 0, 3, r"^b: expected a whole number >= 0"),
        (True, 0, 3, r"^b: expected a whole number >= 0"),
        (0, float("nan"), 3, r"^c: expected a whole number >= 0"),
    ],
)
def test_paired_interval_refuses_counts_that_are_no_pairs(b, c, n, said):
    from pfjax.metrics.robustness import paired_interval

    with pytest.raises(ValueError, match=said):
        paired_interval(b, c, n)
    assert paired_interval(2.0, 1, 4) == paired_interval(2, 1, 4)  # a whole float is a count
