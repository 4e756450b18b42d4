"""Subset simulation (Au and Beck, 2001) with adaptive conditional sampling (Papaioannou et al.,
2015), its chains advanced together in batches.

The failure event ``F = {g(u) <= 0}`` is reached through nested events
``F_j = {g(u) <= b_j}``, ``b_1 > b_2 > ... > b_m = 0``, each threshold the ``p0``-quantile of the
margins at the previous level, so

$$
p = P(F_1) \\prod_{j=2}^{m} P(F_j \\mid F_{j-1}) \\approx p_0^{m-1}\\, \\hat P_m .
$$

Level 0 draws ``N`` points from ``N(0, I)``. At each further level the ``N_c = p_0 N`` points with
the smallest margins seed ``N_c`` Markov chains of length ``N_s = 1 / p_0`` (seed included) whose
stationary law is ``φ`` restricted to ``F_j``. The move is conditional sampling: per coordinate
``i`` with spread ``σ_i`` and ``ρ_i = sqrt(1 - σ_i²)``,

$$
u'_i = ρ_i u_i + \\sqrt{1 - ρ_i^2}\\, ξ_i, \\qquad ξ \\sim N(0, I),
$$

which leaves ``N(0, I)`` invariant, so the candidate is accepted exactly when ``g(u') <= b_j``.
``σ_i = min(1, λ ŝ_i)`` with ``ŝ_i`` the seeds' standard deviation, and ``λ`` adapted after every
batch of steps towards a 44 % acceptance (``log λ += (â - 0.44) / sqrt(t)``).

**Plateaus.** A margin that is flat over much of the input space (a loop with integral action
converges wherever it does not saturate) ties many points at one value, and the ``p_0``-quantile
of tied values is no level: every tied point lies below it, ``P_j`` is 1 and the levels stall.
Each point is therefore ranked by the pair ``(g, t)`` in the lexicographic order, ``t`` a
tie-break that ``g`` may return beside the margin (:func:`pfjax.rare.estimate.evaluate_ranked`;
a continuous quantity that grows towards failure, so ties have none), and the events are
``F_j = {(g, t) <=_lex b_j}``, still nested, with ``F = {g <= 0}`` the last
(``b_m = (0, +inf)``). The threshold is the ``N_c``-th smallest key; where it is tied even so,
it is the largest key strictly below the tie, so ``P_j < p_0`` is the fraction of points strictly
below and the level lies strictly below the last one; the ``N_j`` seeds then run
``ceil(N / N_j)`` steps each. A level with every point tied ends the run with ``p = 0`` and an
infinite relative error (``detail``: ``stalled``): no level below can be placed.

**Error.** The level-``j`` estimate has squared coefficient of variation (Au and Beck, eq. 29)

$$
δ_j^2 = \\frac{1 - p_j}{N p_j}(1 + γ_j), \\qquad
γ_j = 2 \\sum_{k=1}^{N_s - 1} \\Bigl(1 - \\frac{k}{N_s}\\Bigr) \\frac{R_j(k)}{R_j(0)},
$$

with ``R_j(k)`` the lag-``k`` autocovariance of the failure indicators along the chains
(``γ_0 = 0``: level 0 is independent sampling). One run's ``δ_r² = Σ_j δ_j²`` takes the levels as
uncorrelated and is a lower bound: the levels are correlated through the seeds each passes to the
next, and Au and Beck's upper bound, the levels fully correlated, is ``(Σ_j δ_j)²`` (both are in
``detail["levels"]``'s runs as ``delta_uncorrelated`` and ``delta_correlated``; on the known case
of ``studies/rare_events.py`` at ``p`` about 1e-4 the runs' observed spread lies between the two,
nearer the lower).

``repeat`` independent runs ``r = 1 ... R`` until the pooled relative error reaches
``target_rel_error`` average as ``p = mean(p_r)``, with two estimates of its variance: the
levels-uncorrelated ``V_a = Σ_r (δ_r p_r)² / R²`` and, from ``R >= 2`` runs, the batch estimate
``V_b = s² / R`` (``s²`` the sample variance of the ``p_r``: independent runs, so it holds every
correlation, between levels and along the chains, whatever its form). The relative error is
``sqrt(max(V_a, V_b)) / p``; the 95 % interval is on the log scale,
``p exp(±h)``, ``h = max(1.96 s_a, t_{0.975, R-1} s_b)``, ``s² = ln(1 + V / p²)`` for each
(Student's ``t`` with ``R - 1`` degrees of freedom: ``V_b`` rests on ``R`` runs). One run
(``target_rel_error`` None, the target met by the first, or the budget spent) has no spread of
runs to measure, and its levels-uncorrelated error understates its spread: it takes Au and
Beck's upper bound, relative error ``Σ_j δ_j`` and its lognormal interval
(:func:`pfjax.rare.estimate.lognormal_interval`; conservative). Runs that all end at level 0
(``p >= p_0`` about) are independent sampling: ``k`` failures in ``R N`` draws, ``p = k / (R N)``
with the exact (Clopper-Pearson) interval and relative error ``sqrt((1 - p) / (R N p))``.
``detail["error"]`` says which: ``"runs"``, ``"levels fully correlated"`` or ``"binomial"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pfjax import errors
from pfjax.rare.estimate import Z95, RareEstimate, check_common, evaluate_ranked, lognormal_interval

#: Each run's two errors of Au and Beck's bounds (levels uncorrelated, fully correlated).
DELTAS = ("delta_uncorrelated", "delta_correlated")
#: Acceptance rate the conditional-sampling spread is adapted towards.
TARGET_ACCEPTANCE = 0.44


def _gamma(ind: np.ndarray, p: float) -> float:
    """``γ`` of Au and Beck's eq. 29 from the failure indicators ``ind`` of shape ``(N_c, N_s)``."""
    nc, ns = ind.shape
    r0 = p * (1 - p)
    if r0 <= 0 or ns < 2:
        return 0.0
    gam = 0.0
    for k in range(1, ns):
        rk = np.sum(ind[:, : ns - k] * ind[:, k:]) / (nc * (ns - k)) - p * p
        gam += 2 * (1 - k / ns) * rk / r0
    return max(gam, 0.0)


def below(m: np.ndarray, t: np.ndarray, b: tuple[float, float]) -> np.ndarray:
    """``(m, t) <= b`` in the lexicographic order: the margin first, the tie-break among equal margins."""
    return (m < b[0]) | ((m == b[0]) & (t <= b[1]))


def level(m: np.ndarray, t: np.ndarray, nc: int) -> tuple[float, float]:
    """The next threshold ``b_j`` (module docstring, *Plateaus*): the ``nc``-th smallest ``(m, t)``
    in the lexicographic order, between it and the next; where the tie-break leaves that key tied
    with others, the largest key strictly below the tie (fewer than ``nc`` points below, every one
    of them strictly below the last threshold); the tied key itself only where nothing lies below."""
    order = np.lexsort((t, m))
    a, c = order[nc - 1], order[nc]
    if m[a] < m[c]:  # midway, or at m[a] where m[c] is infinite (no midpoint)
        return (0.5 * (m[a] + m[c]) if math.isfinite(m[c]) else float(m[a])), math.inf
    if t[a] < t[c]:
        return float(m[a]), 0.5 * (t[a] + t[c])
    tied = (m == m[a]) & (t == t[a])
    lower = ~tied & below(m, t, (float(m[a]), float(t[a])))
    if lower.any():
        k = np.flatnonzero(lower)[np.lexsort((t[lower], m[lower]))[-1]]
        return (float(m[k]), float(t[k])) if m[k] == m[a] else (float(m[k]), math.inf)
    return float(m[a]), float(t[a])


def _chains(g, seeds, seed_m, seed_t, b, n, rng, batch, lam):
    """``ceil(n / len(seeds))`` conditional-sampling steps of one chain per seed, all kept in
    ``{(m, t) <= b}`` (module docstring): ``(u, m, t, (N_c, N_s) margins, acceptance, rollouts, λ)``."""
    nc, dim = seeds.shape
    ns = -(-n // nc)
    s_hat = np.maximum(seeds.std(axis=0), 1e-3) if nc > 1 else np.ones(dim)
    cur_u, cur_m, cur_t = seeds, seed_m, seed_t
    us, ms, ts, acc_sum, rollouts = [seeds], [seed_m], [seed_t], 0.0, 0
    for step in range(1, ns):
        sigma = np.minimum(1.0, lam * s_hat)
        cand = np.sqrt(1 - sigma**2) * cur_u + sigma * rng.standard_normal(cur_u.shape)
        cm, ct = evaluate_ranked(g, cand, batch)
        rollouts += nc
        ok = below(cm, ct, b)
        cur_u = np.where(ok[:, None], cand, cur_u)
        cur_m, cur_t = np.where(ok, cm, cur_m), np.where(ok, ct, cur_t)
        acc = float(np.mean(ok))
        acc_sum += acc
        lam = float(np.clip(lam * math.exp((acc - TARGET_ACCEPTANCE) / math.sqrt(step)), 1e-3, 10.0))
        us.append(cur_u)
        ms.append(cur_m)
        ts.append(cur_t)
    u = np.stack(us, axis=1).reshape(nc * ns, dim)
    chain_m = np.stack(ms, axis=1)
    t = np.stack(ts, axis=1).reshape(-1)
    return u, chain_m.reshape(-1), t, chain_m, acc_sum / max(ns - 1, 1), rollouts, lam


def _one_run(g, dim, n, p0, rng, batch, max_levels):
    """One subset simulation: ``(p, δ², rollouts, level records, failure points)``."""
    nc = int(round(p0 * n))
    u = rng.standard_normal((n, dim))
    m, t = evaluate_ranked(g, u, batch)
    rollouts, levels, p, d2, dsum = n, [], 1.0, 0.0, 0.0
    chain_m, lam = None, 0.6
    for j in range(max_levels + 1):
        b = level(m, t, nc)
        if b[0] <= 0 or j == max_levels:
            b = (0.0, math.inf)
        fails = below(m, t, b)
        pj = float(np.mean(fails))
        gamma = 0.0 if chain_m is None else _gamma(below(chain_m, t.reshape(chain_m.shape), b).astype(float), pj)
        dj2 = (1 - pj) / (len(m) * pj) * (1 + gamma) if pj > 0 else math.inf
        d2, dsum = d2 + dj2, dsum + math.sqrt(dj2)
        p *= pj
        levels.append({"threshold": b[0], "tie_break": b[1], "p": pj, "gamma": gamma, "delta": math.sqrt(dj2)})
        if b == (0.0, math.inf) or pj == 0 or pj == 1:
            levels[-1]["stalled"] = pj == 1 and b[0] > 0
            failures = u[fails] if b[0] <= 0 else u[:0]
            if pj == 1 and b[0] > 0:  # every point tied on the plateau: no level below can be placed
                p, d2 = 0.0, math.inf
            break
        sel = np.flatnonzero(fails)
        u, m, t, chain_m, acc, used, lam = _chains(g, u[sel], m[sel], t[sel], b, n, rng, batch, lam)
        rollouts += used
        levels[-1]["acceptance"] = acc
    levels[-1]["delta_uncorrelated"], levels[-1]["delta_correlated"] = math.sqrt(d2), dsum
    return p, d2, rollouts, levels, failures


def pooled(ps: np.ndarray, d2: np.ndarray) -> tuple[float, float, tuple[float, float]]:
    """``(p, relative error, 95 % interval)`` of ``R`` independent runs with estimates ``ps`` and
    levels-uncorrelated squared coefficients of variation ``d2`` (module docstring, *Error*)."""
    from scipy import stats

    r = len(ps)
    est = float(ps.mean())
    va = float(sum(p * p * d if p > 0 else d for p, d in zip(ps, d2))) / r**2
    if not est > 0 or not math.isfinite(va):
        return est, math.inf, lognormal_interval(est, math.inf)
    vb = float(ps.var(ddof=1)) / r if r > 1 else 0.0
    rel = math.sqrt(max(va, vb)) / est
    if r == 1:
        return est, rel, lognormal_interval(est, rel)
    h = max(Z95 * math.sqrt(math.log1p(va / est**2)), stats.t.ppf(0.975, r - 1) * math.sqrt(math.log1p(vb / est**2)))
    return est, rel, (est * math.exp(-h), min(1.0, est * math.exp(h)))


def _error(runs: list, n: int) -> tuple[float, float, tuple[float, float], str]:
    """``(p, relative error, 95 % interval, error)`` of the runs ``(p_r, δ_r², levels)`` so far
    (module docstring, *Error*): ``"binomial"`` where every run ended at level 0 (independent
    draws: ``k`` failures in ``R N``, the exact interval), ``"levels fully correlated"`` for one
    run of several levels, ``"runs"`` for several (:func:`pooled`)."""
    from pfjax.metrics.robustness import clopper_pearson

    if all(len(r[2]) == 1 and not r[2][0]["stalled"] for r in runs):
        k, m = int(round(sum(r[0] for r in runs) * n)), n * len(runs)
        lo, hi = clopper_pearson(k, m, 0.95)
        rel = math.sqrt((m - k) / (m * k)) if k else math.inf
        return k / m, rel, (float(lo), float(hi)), "binomial"
    if len(runs) == 1:
        p, d = runs[0][0], runs[0][2][-1]["delta_correlated"]
        rel = d if p > 0 and math.isfinite(d) else math.inf
        return p, rel, lognormal_interval(p, rel), "levels fully correlated"
    return (*pooled(np.array([r[0] for r in runs]), np.array([r[1] for r in runs])), "runs")


def subset_simulation(
    g: Callable,
    dim: int,
    *,
    n_per_level: int = 2000,
    p0: float = 0.1,
    target_rel_error: float | None = None,
    max_rollouts: int = 1_000_000,
    max_levels: int = 30,
    seed: int = 0,
    batch: int = 4096,
) -> RareEstimate:
    """Estimate ``p = P[g(U) <= 0]`` by subset simulation (module docstring).

    Args:
        g: limit-state function: ``(n, dim)`` standard-normal points -> ``(n,)`` margins.
        dim: dimension of the standard-normal space.
        n_per_level: samples per level ``N`` (a multiple of ``1 / p0``).
        p0: intermediate conditional probability (0.1 is the usual choice).
        target_rel_error: repeat independent runs until the pooled relative error is at most this
            (None: one run).
        max_rollouts: no further run starts once this many rollouts are spent.
        max_levels: levels after level 0 before the last threshold is forced to 0.
        seed: seed of the runs (``numpy.random.default_rng``).
        batch: most points per call of ``g``.

    Returns:
        a :class:`~pfjax.rare.estimate.RareEstimate` with ``method="subset"``; ``detail`` holds
        each run's levels (threshold, conditional probability, γ, δ_j, acceptance), each run's
        estimate with its two errors (``run_estimates``), the error used (``error``: ``"runs"``,
        ``"levels fully correlated"`` or ``"binomial"``, module docstring) and the last run's
        failure points (``(m, dim)``, distributed as ``φ`` restricted to the failure region: the
        starts :func:`pfjax.rare.cross_entropy_is` takes).
    """
    dim, seed, batch = check_common(dim, seed, batch)
    n = errors.integer("n_per_level", n_per_level, low=10, high=100_000_000)
    p0 = errors.number("p0", p0, positive=True, below=0.5)
    if int(round(p0 * n)) < 2 or abs(round(1 / p0) * round(p0 * n) - n) > 0:
        raise errors.InputError(f"n_per_level: must be a multiple of 1/p0 = {1 / p0:g}, got {n}", "n_per_level")
    if target_rel_error is not None:
        errors.number("target_rel_error", target_rel_error, positive=True)
    max_rollouts = errors.integer("max_rollouts", max_rollouts, low=n, high=10**10)
    max_levels = errors.integer("max_levels", max_levels, low=1, high=1000)
    rng = np.random.default_rng(seed)
    runs, total = [], 0
    while True:
        p, d2, used, levels, failures = _one_run(g, dim, n, p0, rng, batch, max_levels)
        runs.append((p, d2, levels))
        total += used
        est, rel, ci, error = _error(runs, n)
        per_run = total / len(runs)
        if target_rel_error is None or rel <= target_rel_error or total + per_run > max_rollouts or math.isinf(d2):
            break
    detail: dict = {"runs": len(runs), "error": error}
    detail.update(levels=[r[2] for r in runs], n_per_level=n, p0=p0, failure_points=failures)
    detail["run_estimates"] = [{"p": r[0], **{k: r[2][-1][k] for k in DELTAS}} for r in runs]
    return RareEstimate(est, ci, rel, int(total), "subset", detail)
