"""Importance sampling with a Gaussian-mixture proposal fitted by the cross-entropy method
(Rubinstein and Kroese, 2004; the mixture form of Geyer, Papaioannou and Straub, 2019).

**Estimator.** With the proposal ``q`` and ``N`` draws ``u_k ~ q``,

$$
\\hat p = \\frac1N \\sum_k w_k\\, 1[g(u_k) \\le 0], \\qquad w_k = \\frac{φ(u_k)}{q(u_k)},
\\qquad δ = \\frac{\\operatorname{std}_k(w_k 1[g(u_k) \\le 0])}{\\sqrt N\\, \\hat p},
$$

unbiased for any ``q`` that covers the failure region; the 95 % interval is
``p̂ (1 ± 1.96 δ)`` (central limit theorem; cut at 0 and 1). Draws are added in batches until
``δ <= target_rel_error`` or the budget is spent. An estimate from fewer than 2 draws has no
spread to measure: ``δ = ∞`` and the interval ``(0, 1)``.

**Budget.** ``n_per_level`` draws of the budget are kept for the estimate: a cross-entropy level
runs only where ``n_per_level`` rollouts remain after it, so the estimate rests on at least
``n_per_level`` draws, and a budget below one level and that batch is refused before ``g`` is
called.

**Proposal.** ``q(u) = α φ(u) + (1 - α) Σ_c π_c N(u; μ_c, Σ_c)``, by default with
``Σ_c = I`` (the means shift, the spread stays that of the inputs: weighted covariance fits from a
few hundred elite points shrink level after level, and a proposal narrower than ``φ`` in any
direction gives weights that grow without bound along it; ``covariance="full"`` fits them too): a mixture of ``K`` Gaussians
plus a defensive share ``α`` of the input law itself, which bounds every weight by ``1 / α``
(Hesterberg, 1995). The mixture is fitted by cross-entropy: draw ``n_per_level`` points from the
current proposal, set the level ``γ_t = max(0, ρ-quantile of g)``, and refit the mixture to the
points with ``g <= γ_t`` weighted by ``φ / q`` (weighted EM, 20 iterations, covariances
regularised by ``10⁻⁶ I``; every component kept with at least 1 % weight, so a part of the
failure region that one level under-weighs is not lost) until ``γ_t = 0``, then
``refine`` more fits at ``γ = 0`` (the fit at a fixed level is a fixed-point iteration towards
the optimal proposal; its first step rests on few effective samples and comes out too narrow). The first
proposal is ``N(0, I)``, or, given ``starts`` (failure points found by a falsifier, in the
standard-normal space), a mixture centred on them with unit covariances. The fitted means are
the failure modes the proposal found (``detail["modes"]``): each the mean input of one part of
the failure region under the input law, at or just beyond that part's most likely point (for a
half-space at distance ``β`` from the origin, ``φ(β) / Φ(−β)`` along its normal: 4.23 for
``β = 4``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from scipy.special import logsumexp

from pfjax import errors
from pfjax.rare.estimate import Z95, RareEstimate, check_common, evaluate

#: Least weight of a mixture component after a fit: a part of the failure region that one level's
#: draws under-weigh keeps a component, whose draws restore its weight at the next fit (dropped,
#: the part would be lost for good and the estimate short by its probability).
MIN_WEIGHT = 0.01


class Mixture(NamedTuple):
    """A Gaussian mixture on the standard-normal space."""

    weights: np.ndarray  # (K,) mixing weights, sum 1
    means: np.ndarray  # (K, dim)
    covs: np.ndarray  # (K, dim, dim)


def _std_logpdf(u: np.ndarray) -> np.ndarray:
    return -0.5 * np.sum(u * u, axis=1) - 0.5 * u.shape[1] * math.log(2 * math.pi)


def _component_logpdf(u: np.ndarray, mix: Mixture) -> np.ndarray:
    """``log π_c + log N(u; μ_c, Σ_c)``, shape ``(n, K)``."""
    dim = u.shape[1]
    out = np.empty((len(u), len(mix.weights)))
    for c, (w, mu, cov) in enumerate(zip(mix.weights, mix.means, mix.covs)):
        chol = np.linalg.cholesky(cov)
        z = np.linalg.solve(chol, (u - mu).T)
        logdet = 2 * np.sum(np.log(np.diag(chol)))
        out[:, c] = (
            math.log(max(w, 1e-300)) - 0.5 * np.sum(z * z, axis=0) - 0.5 * (logdet + dim * math.log(2 * math.pi))
        )
    return out


def proposal_logpdf(u: np.ndarray, mix: Mixture, defensive: float) -> np.ndarray:
    """``log q(u)`` of the defensive mixture (module docstring)."""
    parts = [_component_logpdf(u, mix) + math.log1p(-defensive)]
    if defensive > 0:
        parts.append(_std_logpdf(u)[:, None] + math.log(defensive))
    return logsumexp(np.concatenate(parts, axis=1), axis=1)


def sample_proposal(rng, n: int, mix: Mixture, defensive: float) -> np.ndarray:
    """``n`` draws from the defensive mixture."""
    dim = mix.means.shape[1]
    probs = np.concatenate([(1 - defensive) * mix.weights, [defensive]])
    comp = rng.choice(len(probs), size=n, p=probs / probs.sum())
    z = rng.standard_normal((n, dim))
    u = z.copy()
    for c in range(len(mix.weights)):
        sel = comp == c
        u[sel] = mix.means[c] + z[sel] @ np.linalg.cholesky(mix.covs[c]).T
    return u


def _kmeanspp(rng, u: np.ndarray, w: np.ndarray, k: int) -> np.ndarray:
    """``k`` weighted k-means++ seeds among the points ``u``."""
    idx = [rng.choice(len(u), p=w / w.sum())]
    for _ in range(1, k):
        d2 = np.min(np.sum((u[:, None, :] - u[idx][None, :, :]) ** 2, axis=2), axis=1) * w
        if d2.sum() <= 0:
            break
        idx.append(rng.choice(len(u), p=d2 / d2.sum()))
    return u[idx]


def fit_mixture(
    u: np.ndarray, w: np.ndarray, init: Mixture, iters: int = 20, reg: float = 1e-6, full: bool = False
) -> Mixture:
    """Weighted EM for a Gaussian mixture, from ``init``; every component keeps at least
    :data:`MIN_WEIGHT`. ``full``: fit the covariances too (else they stay ``I``)."""
    dim = u.shape[1]
    w = w / w.sum()
    mix = init
    for _ in range(iters):
        lp = _component_logpdf(u, mix)
        r = np.exp(lp - logsumexp(lp, axis=1, keepdims=True)) * w[:, None]
        nk = r.sum(axis=0)
        alive = nk > 1e-12  # a component no point belongs to keeps its place
        means, covs = mix.means.copy(), mix.covs.copy()
        for c in np.flatnonzero(alive):
            means[c] = r[:, c] @ u / nk[c]
            x = u - means[c]
            covs[c] = (r[:, c, None] * x).T @ x / nk[c] + reg * np.eye(dim) if full else np.eye(dim)
        weights = np.maximum(nk / nk.sum(), MIN_WEIGHT)
        mix = Mixture(weights / weights.sum(), means, covs)
    return mix


def _initial(rng, u, w, k, mix: Mixture) -> Mixture:
    """EM's start: the current components if there are ``k``, else ``k`` k-means++ seeds with the
    weighted covariance of the points."""
    if len(mix.weights) == k:
        return mix
    seeds = _kmeanspp(rng, u, w, k)
    x = u - np.average(u, axis=0, weights=w)
    cov = (w[:, None] * x).T @ x / w.sum() + 1e-6 * np.eye(u.shape[1])
    return Mixture(np.full(len(seeds), 1 / len(seeds)), seeds, np.repeat(cov[None], len(seeds), axis=0))


def explore(g: Callable, dim: int, *, n: int = 1000, spread: float = 3.0, seed: int = 0, batch: int = 4096):
    """Failure points found by sampling a widened input law ``N(0, spread² I)``: ``(points (m, dim),
    rollouts)``. With ``spread = 3`` a failure region at distance ``β`` from the origin is hit with
    probability about ``Φ(-β / 3)`` per draw (2.5 % at ``β = 6``, ``p`` about 1e-9), wherever it
    lies, so every part of a failure region of a few dimensions gets points to start
    :func:`cross_entropy_is` from (a falsifier's job, done by sampling: the estimate stays unbiased
    whatever the starts)."""
    dim, seed, batch = check_common(dim, seed, batch)
    n = errors.integer("n", n, low=1, high=100_000_000)
    spread = errors.number("spread", spread, positive=True)
    u = spread * np.random.default_rng(seed).standard_normal((n, dim))
    return u[evaluate(g, u, batch) <= 0], n


def least_rollouts(n_per_level: int, max_levels: int = 30) -> tuple[int, str]:
    """The fewest rollouts :func:`cross_entropy_is` accepts (module docstring, *Budget*), and what
    they are for: a cross-entropy level of ``n_per_level`` and ``n_per_level`` draws to estimate
    from; the draws alone with ``max_levels = 0``."""
    n = n_per_level
    if max_levels > 0:
        return 2 * n, f"a cross-entropy level of n_per_level = {n} and {n} draws to estimate from"
    return n, f"{n} draws"


def cross_entropy_is(
    g: Callable,
    dim: int,
    *,
    starts: np.ndarray | None = None,
    n_components: int | None = None,
    n_per_level: int = 2000,
    rho: float = 0.1,
    defensive: float = 0.05,
    max_levels: int = 30,
    refine: int = 2,
    covariance: str = "unit",
    n_batch: int = 5000,
    target_rel_error: float = 0.1,
    max_rollouts: int = 100_000,
    seed: int = 0,
    batch: int = 4096,
) -> RareEstimate:
    """Estimate ``p = P[g(U) <= 0]`` by importance sampling with a cross-entropy-fitted Gaussian
    mixture (module docstring).

    Args:
        g: limit-state function: ``(n, dim)`` standard-normal points -> ``(n,)`` margins.
        dim: dimension of the standard-normal space.
        starts: optional ``(m, dim)`` failure points to centre the first proposal on.
        n_components: mixture components ``K`` (default: ``len(starts)``, or 2, at most 8).
        n_per_level: draws per cross-entropy level.
        rho: fraction of the draws kept as elite at each level.
        defensive: share ``α`` of ``N(0, I)`` in the proposal, in ``[0, 1)``.
        max_levels: cross-entropy levels before the fit stops where it is.
        refine: further fits at level 0 once it is reached (each moves the mixture closer to
            the optimal proposal ``φ 1[g <= 0] / p``; the first fit there rests on few effective
            samples).
        covariance: ``unit`` (each component ``N(μ_c, I)``: only the means are fitted) or
            ``full`` (covariances fitted too).
        n_batch: draws per batch of the final estimate.
        target_rel_error: stop adding batches once the relative error is at most this.
        max_rollouts: budget of rollouts, the cross-entropy levels included; at least
            ``2 n_per_level`` (a level and the estimate's draws; ``n_per_level`` with
            ``max_levels = 0``).
        seed: seed of the draws (``numpy.random.default_rng``).
        batch: most points per call of ``g``.

    Returns:
        a :class:`~pfjax.rare.estimate.RareEstimate` with ``method="is"``; ``detail`` holds the
        levels, the final mixture's distinct ``modes`` (means, weights: :func:`modes`), the final
        ``proposal`` itself (its :class:`Mixture`'s weights, means and covariances, as lists) with its
        ``defensive`` share of ``N(0, I)`` (what the estimate drew from), the effective sample size and
        the largest weight's share of the estimate (``max_weight_share``,
        :mod:`pfjax.rare.check`). ``p_fail`` is the weights' mean ``Σ w_i 1[g <= 0] / N`` capped at 1
        (where nearly every draw fails, the mean of the weights, about 1, can exceed it); a capped
        estimate keeps the mean in ``detail["uncapped_p"]``, its relative error is the mean's, and its
        interval ``[1 - h, 1]`` (``h`` the mean's half-width).

    Raises:
        pfjax.errors.InputError: a bad argument, named; ``max_rollouts`` below the least budget
            (module docstring, *Budget*), before ``g`` is called.
    """
    dim, seed, batch = check_common(dim, seed, batch)
    n = errors.integer("n_per_level", n_per_level, low=10, high=100_000_000)
    rho, defensive = _check_proposal_args(covariance, rho, defensive)
    errors.number("target_rel_error", target_rel_error, positive=True)
    max_rollouts = errors.integer("max_rollouts", max_rollouts, low=1, high=10**10)
    n_batch = errors.integer("n_batch", n_batch, low=10, high=100_000_000)
    max_levels = errors.integer("max_levels", max_levels, low=0, high=1000)
    refine = errors.integer("refine", refine, low=0, high=1000)
    least, what = least_rollouts(n, max_levels)
    if max_rollouts < least:
        raise errors.InputError(f"max_rollouts: needs at least {least} ({what}), got {max_rollouts}", "max_rollouts")
    starts, k = _check_starts(starts, n_components, dim)
    rng = np.random.default_rng(seed)
    mix = _first_proposal(rng, starts, k, dim)
    ce = _ce_levels(g, rng, mix, k, n, rho, max_levels, refine, covariance == "full", max_rollouts - n, batch)
    mix, used, levels, reached = ce
    s1, s2, wmax, n_is, used = _sample_estimate(
        g, rng, mix, defensive, n_batch, target_rel_error, max_rollouts, used, batch
    )
    mean, var, rel = _moments(s1, s2, n_is)
    p, half = min(mean, 1.0), Z95 * math.sqrt(var)  # a probability: the weights' mean can pass 1
    ess = s1 * s1 / s2 if s2 > 0 else 0.0
    return RareEstimate(
        p,
        (max(0.0, p - half), min(1.0, p + half) if p > 0 else 1.0),
        rel,
        int(used),
        "is",
        {
            **({"uncapped_p": mean} if mean > 1.0 else {}),
            "levels": levels,
            "converged": reached,
            "n_is": n_is,
            "effective_sample_size": ess,
            "max_weight_share": wmax / s1 if s1 > 0 else 0.0,
            "modes": modes(mix),
            "proposal": {"weights": mix.weights.tolist(), "means": mix.means.tolist(), "covs": mix.covs.tolist()},
            "defensive": defensive,
        },
    )


def modes(mix: Mixture) -> dict[str, list]:
    """The mixture's distinct means, the failure modes it found (module docstring), largest weight
    first: ``{"means": (K', dim), "weights": (K',)}``, the weights of components that share a
    mean summed (EM cannot part two components that reach the same mean: their responsibilities
    stay equal)."""
    means, inverse = np.unique(mix.means, axis=0, return_inverse=True)
    weights = np.bincount(inverse.reshape(-1), weights=mix.weights, minlength=len(means))
    order = np.argsort(-weights, kind="stable")
    return {"means": means[order].tolist(), "weights": weights[order].tolist()}


def _check_proposal_args(covariance, rho, defensive) -> tuple[float, float]:
    """``covariance``, ``rho`` and ``defensive`` of :func:`cross_entropy_is`, checked."""
    if covariance not in ("unit", "full"):
        raise errors.InputError(f"covariance: expected unit or full, got {covariance!r}", "covariance")
    rho = errors.number("rho", rho, positive=True, below=1)
    if not 0 <= errors.number("defensive", defensive) < 1:
        raise errors.InputError(f"defensive: expected in [0, 1), got {defensive:g}", "defensive")
    return rho, defensive


def _check_starts(starts, n_components, dim) -> tuple[np.ndarray | None, int]:
    """``starts`` as ``(m, dim)`` points (or None) and the mixture's component count ``K``."""
    if starts is not None:
        starts = np.atleast_2d(np.asarray(errors.numbers("starts", starts), dtype=float))
        if starts.shape[1] != dim:
            raise errors.InputError(f"starts: expected points of dimension {dim}, got shape {starts.shape}", "starts")
        if len(starts) < 1:
            raise errors.InputError("starts: expected at least one point", "starts")
    k = n_components if n_components is not None else (len(starts) if starts is not None else 2)
    k = errors.integer("n_components", min(k, 8) if n_components is None else k, low=1, high=64)
    return starts, k


def _first_proposal(rng, starts: np.ndarray | None, k: int, dim: int) -> Mixture:
    """``N(0, I)``, or unit-covariance components centred on ``starts`` (``k`` k-means++ seeds among
    them where there are more than ``k``, each point weighted by its density under the input law
    ``N(0, I)``: the seeds are the likelier failure points of each part of the region. Unweighted,
    a part could get only a start far out in its tail, whose draws the cross-entropy weights
    ``φ / q`` count as nothing, and the fit would leave that part out)."""
    if starts is None:
        return Mixture(np.ones(1), np.zeros((1, dim)), np.eye(dim)[None])
    r2 = np.sum(starts * starts, axis=1)
    likely = np.exp(-0.5 * (r2 - r2.min()))  # φ(u) / φ(the likeliest start)
    sel = starts if len(starts) <= k else _kmeanspp(rng, starts, likely, k)
    return Mixture(np.full(len(sel), 1 / len(sel)), sel, np.repeat(np.eye(dim)[None], len(sel), axis=0))


def _ce_levels(g, rng, mix, k, n, rho, max_levels, refine, full, level_rollouts, batch):
    """The cross-entropy levels (module docstring; the fit uses no defensive share: it would pull
    the fit back to 0), within ``level_rollouts`` (the budget less the estimate's reserved draws):
    ``(mixture, rollouts, level records, converged)``."""
    dim = mix.means.shape[1]
    used, levels, reached, refined = 0, [], False, 0
    for _ in range(max_levels):
        if used + n > level_rollouts:
            break
        u = sample_proposal(rng, n, mix, 0.0)
        m = evaluate(g, u, batch)
        used += n
        # the nearest margin where interpolating between two infinite ones gives NaN
        q = float(np.quantile(m, rho, method="nearest" if np.isinf(m).any() else "linear"))
        gamma = q if q > 0 else 0.0
        elite = m <= gamma
        if elite.sum() < 2 * dim:
            levels.append({"threshold": gamma, "elite": int(elite.sum())})
            break
        logw = _std_logpdf(u[elite]) - proposal_logpdf(u[elite], mix, 0.0)
        w = np.exp(logw - logw.max())
        mix = fit_mixture(u[elite], w, _initial(rng, u[elite], w, k, mix), full=full)
        ess = float(w.sum() ** 2 / np.sum(w * w))
        levels.append({"threshold": gamma, "elite": int(elite.sum()), "ess": ess, "components": len(mix.weights)})
        refined += gamma == 0.0
        if refined > refine:
            reached = True
            break
    return mix, used, levels, reached


def _moments(s1: float, s2: float, n_is: int) -> tuple[float, float, float]:
    """``(p̂, Var p̂, δ)`` from the sums of the weights and of their squares over ``n_is`` draws
    (``Var p̂`` and ``δ`` infinite for fewer than 2 draws: one draw has no spread to measure)."""
    p = s1 / n_is if n_is > 0 else 0.0
    if n_is < 2:
        return p, math.inf, math.inf
    var = max(s2 / n_is - p * p, 0.0) / n_is
    return p, var, (math.sqrt(var) / p if p > 0 else math.inf)


def _sample_estimate(g, rng, mix, defensive, n_batch, target, max_rollouts, used, batch):
    """Importance sampling from the defensive mixture in batches of ``n_batch`` until ``δ <= target``
    or the budget is spent: ``(Σ w, Σ w², max w, draws, rollouts in all)``."""
    s1 = s2 = wmax = 0.0
    n_is = 0
    while True:
        size = min(n_batch, max_rollouts - used)
        if size <= 0:
            break
        u = sample_proposal(rng, size, mix, defensive)
        m = evaluate(g, u, batch)
        used += size
        n_is += size
        wi = np.where(m <= 0, np.exp(_std_logpdf(u) - proposal_logpdf(u, mix, defensive)), 0.0)
        s1 += float(wi.sum())
        s2 += float((wi * wi).sum())
        wmax = max(wmax, float(wi.max()))
        if _moments(s1, s2, n_is)[2] <= target:
            break
    return s1, s2, wmax, n_is, used
