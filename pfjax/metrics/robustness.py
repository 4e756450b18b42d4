"""Robustness statistics of a Monte Carlo study, per controller (NumPy/SciPy/pandas, never under jit).

A study runs ``n`` independent scenarios per controller; run ``i`` succeeds (``S_i = 1``) or not.
With ``k = sum S_i`` successes the success probability ``p = P(S = 1)`` is estimated by
``p_hat = k / n`` and bounded by

* the exact (Clopper-Pearson) binomial interval, :func:`clopper_pearson`;
* Hoeffding's inequality ``P(p_hat - p >= eps) <= exp(-2 n eps^2)``, whose two-sided form
  ``P(|p_hat - p| >= eps) <= 2 exp(-2 n eps^2)`` gives the sample size
  ``N >= ln(2/delta) / (2 eps^2)`` of :func:`hoeffding_n`;
* the zero-failure ("success run") bound: if ``P(failure) > eps`` the chance of ``n`` failure-free
  runs is below ``(1 - eps)^n``, hence ``N >= ln(1/delta) / ln(1/(1 - eps))`` of
  :func:`zero_failure_n`.

:func:`supported_statement` turns a sample into the statement it supports,
:func:`pfjax.metrics.margins.slip_margin` reads the largest safe slip amplitude off a batched
sweep, :func:`metric_quantiles` summarises
the per-run metrics and :func:`failure_drivers` ranks the sampled parameters that drive failure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pandas as pd

__all__ = [
    "certify_n",
    "check_open_unit",
    "clopper_pearson",
    "failure_drivers",
    "hoeffding_n",
    "metric_quantiles",
    "paired_interval",
    "success_summary",
    "supported_statement",
    "worst_first",
    "zero_failure_n",
]

DEFAULT_QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95, 0.99)


def check_open_unit(name: str, value: float) -> float:
    value = float(value)
    if not 0.0 < value < 1.0:
        raise ValueError(f"{name} must lie in (0, 1), got {value!r}")
    return value


def clopper_pearson(k: int, n: int, conf: float = 0.95) -> tuple[float, float]:
    """Exact two-sided binomial confidence interval for a success probability (Clopper-Pearson).

    With ``alpha = 1 - conf`` and ``Beta^{-1}(q; a, b)`` the beta quantile function::

        lo = Beta^{-1}(alpha/2;     k,     n - k + 1)     (lo = 0 if k = 0)
        hi = Beta^{-1}(1 - alpha/2; k + 1, n - k)         (hi = 1 if k = n)

    ``lo`` is the ``p`` at which ``P(Bin(n, p) >= k) = alpha/2`` and ``hi`` the one at which
    ``P(Bin(n, p) <= k) = alpha/2``, so the interval covers the true ``p`` with probability at
    least ``conf`` for every ``p`` (conservative). The one-sided lower bound at confidence
    ``1 - delta`` is ``clopper_pearson(k, n, 1 - 2 delta)[0]``.

    Args:
        k: number of successes, ``0 <= k <= n``.
        n: number of trials, ``n >= 0``.
        conf: two-sided confidence level in (0, 1).

    Returns:
        ``(lo, hi)`` as floats; ``(nan, nan)`` when ``n = 0`` (nothing observed).
    """
    k, n = int(k), int(n)
    conf = check_open_unit("conf", conf)
    if n < 0 or not 0 <= k <= max(n, 0):
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return math.nan, math.nan
    alpha = 1.0 - conf
    # the beta quantile is scipy.special's inverse regularised incomplete beta function, which is
    # scipy.stats.beta.ppf's own (bit-identical) without scipy.stats' 0.5 s of imports; imported
    # here, since the simulator imports this module
    from scipy.special import betaincinv

    lo = 0.0 if k == 0 else float(betaincinv(k, n - k + 1, alpha / 2))
    hi = 1.0 if k == n else float(betaincinv(k + 1, n - k, 1 - alpha / 2))
    return lo, hi


def success_summary(success: np.ndarray, conf: float = 0.95) -> dict:
    """Success count, rate and its Clopper-Pearson interval.

    Args:
        success: ``(n,)`` booleans (or 0/1), one per run.
        conf: confidence level of the interval (the key keeps the name ``success_ci95``).

    Returns:
        ``{"n", "k", "success_rate", "success_ci95": [lo, hi]}`` with ``success_rate = k / n``
        (NaN and ``[nan, nan]`` when ``n = 0``); plain Python numbers, ready for JSON.
    """
    s = np.asarray(success).reshape(-1)
    if s.dtype != bool and not np.isin(s, (0, 1)).all():
        raise ValueError("success must be boolean or 0/1")
    n, k = int(s.size), int(np.count_nonzero(s))
    lo, hi = clopper_pearson(k, n, conf)
    return {"n": n, "k": k, "success_rate": k / n if n else math.nan, "success_ci95": [lo, hi]}


def _quantile_key(q: float) -> str:
    """``0.05 -> "q05"``, ``0.5 -> "q50"``, ``0.975 -> "q97.5"``."""
    pct = 100.0 * q
    return f"q{round(pct):02d}" if abs(pct - round(pct)) < 1e-9 else f"q{pct:g}"


def metric_quantiles(df: pd.DataFrame, columns: Sequence[str], qs: Sequence[float] = DEFAULT_QUANTILES) -> dict:
    """NaN-aware mean, standard deviation and quantiles of per-run metrics.

    Only finite values count (``settling_time`` is NaN for a run that never settles; a run
    that failed may carry inf); their number is reported as ``n_finite`` so a reader sees how many
    runs a statistic rests on. Over the ``m = n_finite`` finite values ``x_1..x_m``::

        mean = (1/m) sum x_i        std = sqrt( sum (x_i - mean)^2 / (m - 1) )   (NaN if m < 2)

    and ``q<100 q>`` is ``numpy.nanquantile`` (linear interpolation between order statistics).

    Args:
        df: one row per run.
        columns: the metric columns to summarise.
        qs: quantile levels in [0, 1]; keys are ``q05``, ``q50``, ``q99``, ``q97.5``, ...

    Returns:
        ``{col: {"mean", "std", "q05", ..., "n_finite"}}``; NaN statistics when ``n_finite = 0``.
    """
    qs = tuple(float(q) for q in qs)
    if any(not 0.0 <= q <= 1.0 for q in qs):
        raise ValueError(f"quantile levels must lie in [0, 1], got {qs}")
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise KeyError(f"columns not in the data frame: {missing}")
    out = {}
    for col in columns:
        x = df[col].to_numpy(dtype=float)
        x = x[np.isfinite(x)]
        m = int(x.size)
        entry = {"mean": float(x.mean()) if m else math.nan, "std": float(x.std(ddof=1)) if m > 1 else math.nan}
        values = np.quantile(x, qs) if m else np.full(len(qs), np.nan)
        entry.update({_quantile_key(q): float(v) for q, v in zip(qs, values)})
        entry["n_finite"] = m
        out[col] = entry
    return out


def _smallest_n(satisfied, guess: float) -> int:
    """Smallest ``n >= 1`` with ``satisfied(n)``, starting from the closed form ``ceil(guess)``.

    The closed form is exact in real arithmetic; the +-1 correction makes the result the
    smallest ``n`` satisfying the defining inequality as evaluated in floating point.
    """
    n = max(1, math.ceil(guess))
    while not satisfied(n):
        n += 1
    while n > 1 and satisfied(n - 1):
        n -= 1
    return n


def hoeffding_n(eps: float, delta: float) -> int:
    """Runs needed so that ``|p_hat - p| < eps`` with probability ``>= 1 - delta`` (Hoeffding).

    Hoeffding's two-sided bound ``P(|p_hat - p| >= eps) <= 2 exp(-2 n eps^2)`` is at most
    ``delta`` once::

        n >= ln(2/delta) / (2 eps^2)

    Args:
        eps: accuracy in (0, 1).
        delta: failure probability of the statement in (0, 1).

    Returns:
        The smallest integer ``n`` with ``2 exp(-2 n eps^2) <= delta``.
    """
    eps, delta = check_open_unit("eps", eps), check_open_unit("delta", delta)
    return _smallest_n(lambda n: 2.0 * math.exp(-2.0 * n * eps**2) <= delta, math.log(2.0 / delta) / (2.0 * eps**2))


def zero_failure_n(eps: float, delta: float) -> int:
    """Failure-free runs needed to claim ``P(failure) <= eps`` with confidence ``1 - delta``.

    The worst-case ("success run") bound: if ``P(failure) > eps``, ``n`` runs all succeed with
    probability below ``(1 - eps)^n``, which is at most ``delta`` once::

        n >= ln(1/delta) / ln(1/(1 - eps))        (about 3/eps for delta = 0.05)

    Args:
        eps: tolerated failure probability in (0, 1).
        delta: in (0, 1), one minus the confidence.

    Returns:
        The smallest integer ``n`` with ``(1 - eps)^n <= delta``.
    """
    eps, delta = check_open_unit("eps", eps), check_open_unit("delta", delta)
    log1m = math.log1p(-eps)
    return _smallest_n(lambda n: n * log1m <= math.log(delta), math.log(delta) / log1m)


def _one_sided_delta(delta: float) -> float:
    """``delta`` of a one-sided bound at confidence ``1 - delta``: in (0, 0.5) (the bound is the
    lower end of the two-sided interval at ``1 - 2 delta``); ValueError naming ``delta`` otherwise."""
    delta = check_open_unit("delta", delta)
    if delta >= 0.5:
        raise ValueError(f"delta: must be < 0.5 (a one-sided bound at confidence 1 - delta), got {delta!r}")
    return delta


def certify_n(eps: float, delta: float, k_fail: int = 0) -> int:
    """Runs needed to claim ``P(success) >= 1 - eps`` at confidence ``1 - delta`` when ``k_fail`` of
    them fail: the smallest ``n`` whose one-sided Clopper-Pearson lower bound
    ``Beta^{-1}(delta; n - k_fail, k_fail + 1)`` (:func:`supported_statement`'s ``cp_lower``)
    reaches ``1 - eps``. With ``k_fail = 0`` it is :func:`zero_failure_n` (the bound is then
    ``delta^(1/n)``); each failure allowed costs runs. The bound grows with ``n`` at fixed
    ``k_fail``: doubling, then bisection.

    Args:
        eps: tolerated failure probability in (0, 1).
        delta: in (0, 0.5), one minus the confidence (the two-sided 95 % interval's lower end is
            ``delta = 0.025``).
        k_fail: failures the sample may hold, ``>= 0``.
    """
    eps, delta = check_open_unit("eps", eps), _one_sided_delta(delta)
    if isinstance(k_fail, bool) or not isinstance(k_fail, (int, np.integer)) or k_fail < 0:
        raise ValueError(f"k_fail: expected an integer >= 0, got {k_fail!r}")
    k = int(k_fail)
    if k == 0:
        return zero_failure_n(eps, delta)

    def ok(n: int) -> bool:
        return clopper_pearson(n - k, n, 1.0 - 2.0 * delta)[0] >= 1.0 - eps

    lo = hi = k + 1
    while not ok(hi):  # doubling: every n below lo fails, hi passes at the end
        lo, hi = hi + 1, 2 * hi
    while lo < hi:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if ok(mid) else (mid + 1, hi)
    return hi


def supported_statement(n: int, k_fail: int, delta: float = 0.05) -> dict:
    """What ``n`` runs with ``k_fail`` failures support about ``P(success)``, at confidence ``1 - delta``.

    With ``p_hat = (n - k_fail) / n``:

    * Hoeffding: ``P(success) >= p_hat - eps_H`` with ``eps_H = sqrt(ln(2/delta) / (2 n))``
      (the two-sided radius of :func:`hoeffding_n` solved for ``eps``; distribution-free);
    * zero failures only: ``P(failure) <= eps_0 = 1 - delta^(1/n)`` (:func:`zero_failure_n`
      solved for ``eps``);
    * Clopper-Pearson one-sided lower bound ``p_CP = Beta^{-1}(delta; n - k_fail, k_fail + 1)``
      (0 if every run failed): ``P(success) >= p_CP``, the tightest of the three (with no
      failures ``p_CP = delta^(1/n) = 1 - eps_0``).

    Args:
        n: number of runs, ``>= 1``.
        k_fail: number of failed runs, ``0 <= k_fail <= n``.
        delta: one minus the confidence, in (0, 0.5).

    Returns:
        ``{"n", "k_fail", "delta", "confidence", "success_rate", "hoeffding_eps",
        "hoeffding_lower", "zero_failure_eps", "cp_lower", "text"}``; ``hoeffding_lower`` is
        ``max(0, p_hat - eps_H)``, ``zero_failure_eps`` is None when ``k_fail > 0`` and ``text``
        is one English sentence.
    """
    n, k_fail = int(n), int(k_fail)
    delta = _one_sided_delta(delta)
    if n < 1 or not 0 <= k_fail <= n:
        raise ValueError(f"need n >= 1 and 0 <= k_fail <= n, got n={n}, k_fail={k_fail}")
    p_hat = (n - k_fail) / n
    eps_h = math.sqrt(math.log(2.0 / delta) / (2.0 * n))
    eps_0 = -math.expm1(math.log(delta) / n) if k_fail == 0 else None
    cp_lower = clopper_pearson(n - k_fail, n, 1.0 - 2.0 * delta)[0]
    conf_pct = f"{100 * (1 - delta):g} %"
    if k_fail == 0:
        text = (
            f"No failure in {n} runs: P(failure) <= {eps_0:.3g} with {conf_pct} confidence "
            f"(Hoeffding alone: P(success) >= {max(0.0, p_hat - eps_h):.4f})."
        )
    else:
        text = (
            f"{k_fail} failures in {n} runs: P(success) >= {cp_lower:.4f} with {conf_pct} "
            f"confidence (Clopper-Pearson; Hoeffding: >= {p_hat:.4f} - {eps_h:.4f} "
            f"= {max(0.0, p_hat - eps_h):.4f})."
        )
    return {
        "n": n,
        "k_fail": k_fail,
        "delta": delta,
        "confidence": 1.0 - delta,
        "success_rate": p_hat,
        "hoeffding_eps": eps_h,
        "hoeffding_lower": max(0.0, p_hat - eps_h),
        "zero_failure_eps": eps_0,
        "cp_lower": cp_lower,
        "text": text,
    }


def _spearman(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Spearman ``(rho, p)`` on the rows where both are finite; NaN if either is constant there.

    ``rho`` is the Pearson correlation of the average ranks, and ``p`` the two-sided p-value of
    ``t = rho sqrt((n - 2) / (1 - rho^2))`` under Student's t with ``n - 2`` degrees of freedom:
    ``scipy.stats.spearmanr``'s statistic and p-value (bit-identical, tested), from pandas' ranks
    and ``scipy.special`` (scipy.stats takes about 0.5 s more to import)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return math.nan, math.nan
    from scipy.special import stdtr

    rx, ry = (pd.Series(v).rank(method="average").to_numpy() for v in (x, y))
    rho = np.corrcoef(rx, ry)[1, 0]
    dof = x.size - 2
    with np.errstate(divide="ignore"):  # rho = +-1: t infinite, p = 0
        t = rho * np.sqrt(np.clip(dof / ((rho + 1.0) * (1.0 - rho)), 0.0, None))
    return float(rho), float(2.0 * stdtr(dof, -np.abs(t)))


def failure_drivers(
    df: pd.DataFrame, params: list[str], outcome: str = "success", metric: str | None = "iae"
) -> pd.DataFrame:
    """Rank the sampled parameters by how strongly they drive failure.

    For each parameter ``x`` (one value per run) and the failure indicator ``F = 1 - success``:

    * ``rho_failure``, ``p_failure``: Spearman rank correlation of ``x`` with ``F`` and its
      p-value (as ``scipy.stats.spearmanr``; ties in ``F`` get average ranks);
    * ``rho_metric``, ``p_metric``: the same with the metric column (rows where it is finite);
    * ``effect_size``: the point-biserial effect size
      ``(mean(x | F = 1) - mean(x | F = 0)) / std(x)`` (``std`` over all runs, ``ddof = 1``):
      how many standard deviations the failed runs sit above the successful ones.

    Slip can hurt in either direction, so a signed parameter (negative and positive values both
    sampled) gets a second row ``abs_<name>`` for ``|x|``: a failure driven by ``|beta_r|``
    correlates with ``abs_beta_r`` but hardly with ``beta_r``. Statistics are NaN where undefined
    (no failure, no success, a constant parameter, or ``metric=None``).

    Args:
        df: one row per run with the parameter columns, ``outcome`` and ``metric``.
        params: the sampled parameter columns.
        outcome: boolean (or 0/1) success column.
        metric: a per-run metric column, or None.

    Returns:
        One row per parameter (and ``abs_`` variant) with columns ``parameter, rho_failure,
        p_failure, rho_metric, p_metric, effect_size, n``, sorted by ``|rho_failure|`` descending
        (NaN last).
    """
    needed = list(params) + [outcome] + ([metric] if metric is not None else [])
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise KeyError(f"columns not in the data frame: {missing}")
    fail = 1.0 - df[outcome].to_numpy(dtype=float)
    y = df[metric].to_numpy(dtype=float) if metric is not None else None
    rows = []
    for name in params:
        x = df[name].to_numpy(dtype=float)
        variants = [(name, x)]
        if np.any(x < 0) and np.any(x > 0):
            variants.append((f"abs_{name}", np.abs(x)))
        for label, v in variants:
            rho_f, p_f = _spearman(v, fail)
            rho_m, p_m = _spearman(v, y) if y is not None else (math.nan, math.nan)
            ok = np.isfinite(v) & np.isfinite(fail)
            vf, vs = v[ok & (fail > 0.5)], v[ok & (fail < 0.5)]
            sd = np.std(v[ok], ddof=1) if ok.sum() > 1 else 0.0
            effect = (vf.mean() - vs.mean()) / sd if vf.size and vs.size and sd > 0 else math.nan
            rows.append(
                {
                    "parameter": label,
                    "rho_failure": rho_f,
                    "p_failure": p_f,
                    "rho_metric": rho_m,
                    "p_metric": p_m,
                    "effect_size": float(effect),
                    "n": int(ok.sum()),
                }
            )
    out = pd.DataFrame(
        rows, columns=["parameter", "rho_failure", "p_failure", "rho_metric", "p_metric", "effect_size", "n"]
    )
    order = np.argsort(-np.nan_to_num(np.abs(out["rho_failure"].to_numpy()), nan=-1.0), kind="stable")
    return out.iloc[order].reset_index(drop=True)


def worst_first(runs: pd.DataFrame) -> pd.DataFrame:
    """``runs`` (rows of a run table: ``status``, ``fail_time`` s, ``late_max_abs_d`` m) ordered worst
    first: the runs that failed (status other than ``ok``) first, the earliest failure first, then
    the largest ``late_max_abs_d`` (|d| over the success window); ties keep their order (a stable
    sort). The order of the report's worst runs and of a replay of the worst run."""
    key = pd.DataFrame(  # by position: an index with repeated labels (a concatenation) orders alike
        {
            "failed": (runs["status"] != "ok").to_numpy(),
            "fail_time": runs["fail_time"].fillna(np.inf).to_numpy(),
            "late": runs["late_max_abs_d"].fillna(np.inf).to_numpy(),
        }
    )
    order = key.sort_values(["failed", "fail_time", "late"], ascending=[False, True, False], kind="stable").index
    return runs.iloc[order.to_numpy()]


def _count(name: str, x) -> int:
    """``x`` as a count (a whole number >= 0, not a bool); ValueError naming ``name`` otherwise."""
    if (
        isinstance(x, bool)
        or not isinstance(x, (int, np.integer, float, np.floating))
        or not (math.isfinite(x) and x >= 0 and float(x).is_integer())
    ):
        raise ValueError(f"{name}: expected a whole number >= 0, got {x!r}")
    return int(x)


def _tango_z(b: int, c: int, n: int, delta: float) -> float:
    """Tango's score statistic of the paired difference ``delta`` (:func:`paired_interval`)."""
    w = -b - c + (2 * n - b + c) * delta
    q21 = (math.sqrt(max(w * w + 8 * n * c * delta * (1 - delta), 0.0)) - w) / (4 * n)  # restricted MLE of c / n
    var = n * (2 * q21 + delta * (1 - delta))
    return (b - c - n * delta) / math.sqrt(var) if var > 0 else math.copysign(math.inf, b - c - n * delta)


def paired_interval(b: int, c: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The score interval of Tango (1998) for the difference of two paired proportions, ``(b - c) / n``
    over ``n`` pairs, ``b`` of them a success in the first arm only and ``c`` in the second only: the
    ``Delta`` in ``[-1, 1]`` with ``|Z(Delta)| <= z``, where

        Z(Delta) = (b - c - n Delta) / sqrt(n (2 q21 + Delta (1 - Delta)))

    and ``q21`` is the maximum-likelihood probability of the second kind of discordant pair given
    ``Delta`` (T. Tango, "Equivalence test and confidence interval for the difference in proportions
    for the paired-sample design", *Statistics in Medicine* 17, 891-908, 1998). ``Z`` falls with
    ``Delta``; its roots are found by bisection to 1e-12. Unlike the Wald interval it has a width
    when ``b = c = 0`` (identical outcomes): ``+-z^2 / (n + z^2)``. ``(nan, nan)`` for ``n = 0``."""
    b, c, n = (_count(name, x) for name, x in (("b", b), ("c", c), ("n", n)))
    if b + c > n:
        raise ValueError(f"need b, c >= 0 and b + c <= n, got b={b}, c={c}, n={n}")
    if n == 0:
        return math.nan, math.nan
    d = (b - c) / n

    def root(lo: float, hi: float, target: float) -> float:
        # Z(lo) >= target >= Z(hi); the Delta where Z = target, or the end of [-1, 1] it does not reach
        while hi - lo > 1e-12:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _tango_z(b, c, n, mid) > target else (lo, mid)
        return 0.5 * (lo + hi)

    lo = -1.0 if d == -1.0 else root(-1.0, d, z)
    hi = 1.0 if d == 1.0 else root(d, 1.0, -z)
    return max(lo, -1.0), min(hi, 1.0)
