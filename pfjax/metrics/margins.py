"""The slip margin of a controller: the largest slip amplitude at which its success rate stays
``>= 1 - eps``, read off a batched sweep with Clopper-Pearson bounds
(:func:`pfjax.metrics.robustness.clopper_pearson`). NumPy/SciPy, never under jit."""

from __future__ import annotations

import math

import numpy as np

from pfjax.metrics.robustness import check_open_unit, clopper_pearson

__all__ = ["slip_margin"]


def _sweep(amplitudes, successes, trials) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sweep's amplitudes, success and run counts as flat arrays sorted by amplitude; raises
    ValueError on mismatched lengths, negative or repeated amplitudes, or counts out of range."""
    a = np.asarray(amplitudes, dtype=float).reshape(-1)
    k = np.asarray(successes).reshape(-1)
    n = np.asarray(trials).reshape(-1)
    if not a.size == k.size == n.size or a.size == 0:
        raise ValueError(
            f"amplitudes, successes and trials need the same non-zero length, got {a.size}, {k.size}, {n.size}"
        )
    if not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ValueError(f"amplitudes must be finite and >= 0, got {a}")
    if np.any(n < 1) or np.any(k < 0) or np.any(k > n):
        raise ValueError(f"need 0 <= successes <= trials and trials >= 1, got k={k}, n={n}")
    order = np.argsort(a, kind="stable")
    a, k, n = a[order], k[order].astype(int), n[order].astype(int)
    if np.any(np.diff(a) == 0):
        raise ValueError(f"amplitudes must be distinct, got {a}")
    return a, k, n


def _last_safe_index(passes: np.ndarray) -> int:
    """Index of the last amplitude such that it and every smaller one pass; -1 if the first fails."""
    fails = np.flatnonzero(~passes)
    return (passes.size if fails.size == 0 else int(fails[0])) - 1


def slip_margin(
    amplitudes: np.ndarray, successes: np.ndarray, trials: np.ndarray, eps: float = 0.05, conf: float = 0.95
) -> dict:
    """Largest slip amplitude at which the success rate stays ``>= 1 - eps``, from a batched sweep.

    At amplitudes ``a_1 < ... < a_m`` (deg) the sweep observed ``k_j`` successes in ``n_j`` runs.
    For a per-amplitude rate ``r_j`` the margin is::

        a* = a_J,   J = max{ j : r_i >= 1 - eps for every i <= j }

    i.e. the first amplitude that fails ends the safe range even if a larger one passes again
    (noise or a genuinely non-monotone curve: the margin promises safety at every amplitude
    below it). It is evaluated three times:

    * ``margin`` with ``r_j = p_hat_j = k_j / n_j`` (point estimate);
    * ``margin_lo`` with the Clopper-Pearson lower bound of ``p_j`` at ``conf`` (conservative);
    * ``margin_hi`` with its upper bound (optimistic).

    Because ``lo_j <= p_hat_j <= hi_j``, ``margin_lo <= margin <= margin_hi`` always.

    Edge cases: if the smallest amplitude already fails, the margin is ``0`` and no tested
    amplitude is known to be safe (amplitudes are magnitudes, ``a_1 >= 0``); ``0`` alone cannot
    tell this from a sweep that passes at ``a_1 = 0`` and fails beyond, so each reading has its flag:
    ``fails_at_smallest`` (the point estimate), ``fails_at_smallest_lo`` and ``fails_at_smallest_hi``
    (the bounds): no margin in that reading. If every amplitude passes,
    the margin is the largest amplitude tested and ``censored`` is True: the true margin is at
    least that (right-censored).

    The grid itself limits the answer: the point-estimate crossing lies between ``margin`` and
    the next amplitude tested, and ``resolution`` is that gap (``a_{J+1} - a_J``, with
    ``a_0 = 0``); when censored, the last grid step ``a_m - a_{m-1}`` (NaN for a single
    amplitude).

    Args:
        amplitudes: ``(m,)`` distinct slip amplitudes, deg, ``>= 0`` (sorted here if not).
        successes: ``(m,)`` success counts ``k_j``.
        trials: ``(m,)`` run counts ``n_j >= 1``.
        eps: tolerated failure rate in (0, 1).
        conf: two-sided confidence of the per-amplitude intervals.

    Returns:
        ``{"margin", "margin_lo", "margin_hi", "fails_at_smallest", "fails_at_smallest_lo",
        "fails_at_smallest_hi", "resolution", "censored", "eps", "table"}`` with ``table`` one dict
        ``{"amplitude", "n", "k", "rate", "lo", "hi"}`` per amplitude, ascending.
    """
    eps = check_open_unit("eps", eps)
    a, k, n = _sweep(amplitudes, successes, trials)
    rate = k / n
    lo, hi = np.array([clopper_pearson(kj, nj, conf) for kj, nj in zip(k, n)]).T
    grid = np.concatenate([[0.0], a])  # a_0 = 0: the margin when the smallest amplitude fails

    def margin_of(r):
        return float(grid[_last_safe_index(r >= 1.0 - eps) + 1])

    def fails_first(r) -> bool:  # no margin in this reading: the smallest amplitude already fails
        return bool(r[0] < 1.0 - eps)

    j = _last_safe_index(rate >= 1.0 - eps)
    censored = j == a.size - 1
    if censored:
        resolution = float(a[-1] - a[-2]) if a.size > 1 else math.nan
    else:
        resolution = float(grid[j + 2] - grid[j + 1])
    table = [
        {
            "amplitude": float(a[i]),
            "n": int(n[i]),
            "k": int(k[i]),
            "rate": float(rate[i]),
            "lo": float(lo[i]),
            "hi": float(hi[i]),
        }
        for i in range(a.size)
    ]
    return {
        "margin": margin_of(rate),
        "margin_lo": margin_of(lo),
        "margin_hi": margin_of(hi),
        "fails_at_smallest": fails_first(rate),
        "fails_at_smallest_lo": fails_first(lo),
        "fails_at_smallest_hi": fails_first(hi),
        "resolution": resolution,
        "censored": bool(censored),
        "eps": eps,
        "table": table,
    }
