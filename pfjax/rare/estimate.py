"""The record every rare-event estimator returns, and plain Monte Carlo (the baseline).

A *limit-state function* ``g`` maps a batch of points of the standard-normal space to margins:
``g(u)`` with ``u`` of shape ``(n, dim)`` (float64) returns ``(n,)`` margins, and a point fails
where ``g(u) <= 0``. The failure probability is

$$
p = P[g(U) \\le 0] = \\int_{g(u) \\le 0} \\varphi_{dim}(u)\\, du,
\\qquad U \\sim N(0, I_{dim}).
$$

Every estimator calls ``g`` on batches of at most ``batch`` points (the simulator compiles one
program per batch shape; :mod:`pfjax.rare.study` pads to a fixed batch) and counts each point it
evaluates as one rollout.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from pfjax import errors

#: Estimator names as studies and the command line spell them.
METHODS = ("is", "subset", "mc")
#: Two-sided normal quantile of the 95 % intervals.
Z95 = 1.959963984540054


class RareEstimate(NamedTuple):
    """A failure probability with its 95 % interval (every estimator of :mod:`pfjax.rare`)."""

    p_fail: float  # estimated failure probability
    ci95: tuple[float, float]  # 95 % interval (lo, hi)
    rel_error: float  # estimated coefficient of variation of p_fail (std / mean; inf when p_fail = 0)
    n_rollouts: int  # evaluations of g (simulated runs)
    method: str  # "mc" | "subset" | "is"
    detail: dict[str, Any]  # method diagnostics (levels, acceptance, proposal modes, ...)

    def __str__(self) -> str:
        lo, hi = self.ci95
        return (
            f"p_fail = {self.p_fail:.3g} (95 % interval {lo:.3g}-{hi:.3g}, rel. error {self.rel_error:.2g}, "
            f"{self.n_rollouts} rollouts, {self.method})"
        )


def lognormal_interval(p: float, rel_error: float) -> tuple[float, float]:
    """The 95 % interval ``p exp(±1.96 s)``, ``s² = ln(1 + δ²)`` for an estimate ``p`` with
    coefficient of variation ``δ`` (a lognormal fitted to its mean and variance: positive, and
    asymmetric as the estimate's distribution is for a product of level probabilities)."""
    if not p > 0 or not math.isfinite(rel_error):
        return 0.0, (1.0 if not p > 0 else math.inf)
    s = math.sqrt(math.log1p(rel_error**2))
    return p * math.exp(-Z95 * s), min(1.0, p * math.exp(Z95 * s))


def check_common(dim, seed, batch) -> tuple[int, int, int]:
    """The arguments every estimator shares, checked as the command line checks them."""
    dim = errors.integer("dim", dim, low=1, high=10_000)
    seed = errors.seed("seed", seed)
    batch = errors.integer("batch", batch, low=1, high=100_000_000)
    return dim, seed, batch


def evaluate_ranked(g: Callable, u: np.ndarray, batch: int) -> tuple[np.ndarray, np.ndarray]:
    """``g`` on ``u`` in blocks of at most ``batch`` points: ``(margins, tie-breaks)``, each ``(n,)``.

    ``g`` returns ``(n,)`` margins, or ``(n, 2)``: the margin and a tie-break, a continuous
    quantity that orders points whose margins are equal (smaller: nearer failure; zeros when ``g``
    gives none). Only :func:`pfjax.rare.subset_simulation` uses the tie-break; failure is
    ``margin <= 0`` whatever it is. A NaN margin counts as a failure, as ``-inf`` (a run whose
    margin is NaN has left the model's domain); ``+inf`` is a margin like any other, no failure;
    non-finite tie-breaks count as ``-inf``."""
    out = [np.asarray(g(u[a : a + batch]), dtype=float) for a in range(0, len(u), batch)]
    out = [x.reshape(len(x), -1) if x.ndim == 2 else x.reshape(-1, 1) for x in out]
    m = np.concatenate(out) if out else np.zeros((0, 1))
    if m.shape not in ((len(u), 1), (len(u), 2)):
        raise errors.InputError(f"g: expected {len(u)} margins for {len(u)} points, got shape {m.shape}", "g")
    t = m[:, 1] if m.shape[1] == 2 else np.zeros(len(u))
    return np.where(np.isnan(m[:, 0]), -np.inf, m[:, 0]), np.where(np.isfinite(t), t, -np.inf)


def evaluate(g: Callable, u: np.ndarray, batch: int) -> np.ndarray:
    """The margins of :func:`evaluate_ranked` alone, shape ``(n,)``."""
    return evaluate_ranked(g, u, batch)[0]


def monte_carlo(g: Callable, dim: int, *, n: int = 100_000, seed: int = 0, batch: int = 4096) -> RareEstimate:
    """Plain Monte Carlo: ``k`` failures in ``n`` independent draws, ``p = k / n`` with the exact
    (Clopper-Pearson) 95 % interval and relative error ``sqrt((1 - p) / (n p))``.

    Args:
        g: limit-state function (module docstring): ``(n, dim)`` points -> ``(n,)`` margins.
        dim: dimension of the standard-normal space.
        n: draws (rollouts).
        seed: seed of the draws (``numpy.random.default_rng``).
        batch: most points per call of ``g``.
    """
    from pfjax.metrics.robustness import clopper_pearson

    dim, seed, batch = check_common(dim, seed, batch)
    n = errors.integer("n", n, low=1, high=10**10)
    rng = np.random.default_rng(seed)
    k = 0
    for a in range(0, n, batch):
        k += int(np.sum(evaluate(g, rng.standard_normal((min(batch, n - a), dim)), batch) <= 0))
    p = k / n
    lo, hi = clopper_pearson(k, n, 0.95)
    rel = math.sqrt((1 - p) / (n * p)) if k else math.inf
    return RareEstimate(p, (float(lo), float(hi)), rel, n, "mc", {"failures": k})
