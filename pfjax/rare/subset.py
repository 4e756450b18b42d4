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

**Error.** The level-``j`` estimate has squared coefficient of variation (Au and Beck, eq. 29)

$$
δ_j^2 = \\frac{1 - p_j}{N p_j}(1 + γ_j), \\qquad
γ_j = 2 \\sum_{k=1}^{N_s - 1} \\Bigl(1 - \\frac{k}{N_s}\\Bigr) \\frac{R_j(k)}{R_j(0)},
$$

with ``R_j(k)`` the lag-``k`` autocovariance of the failure indicators along the chains
(``γ_0 = 0``: level 0 is independent sampling). Levels are taken as uncorrelated,
``δ² = Σ_j δ_j²`` (the usual estimate; it neglects the correlation between levels through
the seeds, so it is slightly optimistic). The 95 % interval is the lognormal one of
:func:`pfjax.rare.estimate.lognormal_interval`. ``repeat`` independent runs until the pooled
relative error reaches ``target_rel_error`` average as ``p = mean(p_r)``,
``Var p = Σ (δ_r p_r)² / R²``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pfjax import errors
from pfjax.rare.estimate import RareEstimate, check_common, evaluate, lognormal_interval

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


def _one_run(g, dim, n, p0, rng, batch, max_levels):
    """One subset simulation: ``(p, δ², rollouts, level records, failure points)``."""
    nc = int(round(p0 * n))
    ns = n // nc
    u = rng.standard_normal((n, dim))
    m = evaluate(g, u, batch)
    rollouts, levels, p, d2 = n, [], 1.0, 0.0
    ind_chains, lam = None, 0.6
    for level in range(max_levels + 1):
        order = np.argsort(m, kind="stable")
        b = 0.5 * (m[order[nc - 1]] + m[order[nc]])
        final = b <= 0 or level == max_levels
        b = max(b, 0.0) if not final else 0.0
        fails = m <= b
        pj = float(np.mean(fails))
        gamma = 0.0 if ind_chains is None else _gamma((ind_chains <= b).astype(float), pj)
        d2 += (1 - pj) / (n * pj) * (1 + gamma) if pj > 0 else math.inf
        p *= pj
        levels.append({"threshold": float(b), "p": pj, "gamma": gamma})
        if final or pj == 0:
            failures = u[fails] if b <= 0 else u[:0]
            break
        seeds, seed_m = u[order[:nc]], m[order[:nc]]
        s_hat = np.maximum(seeds.std(axis=0), 1e-3)
        chains_u, chains_m = [seeds], [seed_m]
        cur_u, cur_m, acc_sum = seeds, seed_m, 0.0
        for t in range(1, ns):
            sigma = np.minimum(1.0, lam * s_hat)
            rho = np.sqrt(1 - sigma**2)
            cand = rho * cur_u + sigma * rng.standard_normal(cur_u.shape)
            cm = evaluate(g, cand, batch)
            rollouts += nc
            ok = cm <= b
            cur_u = np.where(ok[:, None], cand, cur_u)
            cur_m = np.where(ok, cm, cur_m)
            acc = float(np.mean(ok))
            acc_sum += acc
            lam = float(np.clip(lam * math.exp((acc - TARGET_ACCEPTANCE) / math.sqrt(t)), 1e-3, 10.0))
            chains_u.append(cur_u)
            chains_m.append(cur_m)
        levels[-1]["acceptance"] = acc_sum / max(ns - 1, 1)
        u = np.stack(chains_u, axis=1).reshape(nc * ns, dim)
        ind_chains = np.stack(chains_m, axis=1)
        m = ind_chains.reshape(-1)
        n = nc * ns
    return p, d2, rollouts, levels, failures


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
        each run's levels (threshold, conditional probability, γ, acceptance) and the last run's
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
        ps = np.array([r[0] for r in runs])
        var = float(np.sum(ps**2 * np.array([r[1] for r in runs]))) / len(runs) ** 2
        est = float(ps.mean())
        rel = math.sqrt(var) / est if est > 0 else math.inf
        per_run = total / len(runs)
        if target_rel_error is None or rel <= target_rel_error or total + per_run > max_rollouts:
            break
    return RareEstimate(
        est,
        lognormal_interval(est, rel),
        rel,
        int(total),
        "subset",
        {"runs": len(runs), "levels": [r[2] for r in runs], "n_per_level": n, "p0": p0, "failure_points": failures},
    )
