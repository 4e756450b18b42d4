"""Reliability of an importance-sampling estimate: a second opinion from subset simulation and the
concentration of its weights.

A cross-entropy proposal that never put mass on one part of the failure region returns an
estimate short by that part's probability with an interval that knows nothing of it: the draws
that would reveal the miss (the defensive share's, :mod:`pfjax.rare.importance`) are too few to
land there. Two signs of such a miss are checked.

**Disagreement with subset simulation**, which needs no proposal and follows every part of the
failure region (:mod:`pfjax.rare.subset`). With estimates ``p_a``, ``p_b`` and relative errors
``δ_a``, ``δ_b``, on the log scale (``s² = ln(1 + δ²)``, the spread of a lognormal with that
coefficient of variation)

$$
z = \\frac{|\\ln p_a - \\ln p_b|}{\\sqrt{s_a^2 + s_b^2}},
$$

and the two disagree beyond their 95 % intervals where ``z > 1.96`` (a failed two-sided test of
equal means at the 5 % level; one estimate zero and the other not is a disagreement).

**Concentrated weights.** The largest single importance weight's share of the estimate,
``max_k w_k / Σ_k w_k`` over the failing draws (``detail["max_weight_share"]``): about
``1 / n_fail`` for a proposal that covers the failure region, near 1 where one defensive draw
landed in a part the mixture missed (its weight ``φ / q`` up to ``1 / α``, against ``≈ p`` for the
others). Above :data:`MAX_WEIGHT_SHARE` the estimate rests on that one draw.
"""

from __future__ import annotations

import math

from pfjax.rare.estimate import Z95, RareEstimate

#: Largest share of an importance-sampling estimate one draw may carry before it is flagged.
MAX_WEIGHT_SHARE = 0.1


def log_z(a: RareEstimate, b: RareEstimate) -> float:
    """``z`` of the module docstring: the log-scale distance of two estimates in their joint
    standard errors (inf where exactly one is zero, 0 where both are)."""
    if not (a.p_fail > 0 and b.p_fail > 0):
        return 0.0 if a.p_fail == b.p_fail else math.inf
    s2 = sum(math.log1p(r.rel_error**2) if math.isfinite(r.rel_error) else math.inf for r in (a, b))
    diff = abs(math.log(a.p_fail / b.p_fail))
    return diff / math.sqrt(s2) if s2 > 0 else (math.inf if diff > 0 else 0.0)


def _likely_cause(est: RareEstimate, other: RareEstimate) -> str:
    """What a disagreement points to: importance sampling below the second opinion suggests a part
    of the failure region its proposal missed; above it, a level of the second estimator that fell
    short (or a chance flag: about one in twenty checks at the 5 % level)."""
    if est.p_fail < other.p_fail:
        return "the proposal may miss part of the failure region"
    return (
        f"importance sampling is the higher estimate, so no part of the region is missed; {other.method} may fall short"
    )


def reliability(est: RareEstimate, other: RareEstimate | None = None) -> dict:
    """The checks of the module docstring on the importance-sampling estimate ``est`` (and
    ``other``, an independent estimate of the same probability, where given).

    Returns:
        ``{"status", "warning", "max_weight_share", "z", "other"}``: ``status`` ``"ok"``,
        ``"disagree"`` (``z > 1.96``) or ``"concentrated"`` (largest weight's share above
        :data:`MAX_WEIGHT_SHARE`), ``warning`` a sentence saying which (None when ``ok``); ``z``
        and ``other`` (the second estimate's ``p_fail``, ``ci95``, ``rel_error``,
        ``n_rollouts``, ``method``) None without ``other``.
    """
    share = float(est.detail.get("max_weight_share", 0.0))
    z = None if other is None else log_z(est, other)
    status, warning = "ok", None
    if z is not None and z > Z95:
        status = "disagree"
        warning = (
            f"importance sampling ({est.p_fail:.3g}) and {other.method} ({other.p_fail:.3g}) disagree beyond "  # type: ignore[union-attr]
            f"their 95 % intervals (z = {z:.2f}): " + _likely_cause(est, other)  # type: ignore[arg-type]
        )
    elif share > MAX_WEIGHT_SHARE:
        status = "concentrated"
        warning = (
            f"one draw carries {100 * share:.0f} % of the importance-sampling estimate: "
            "the proposal may miss part of the failure region"
        )
    summary = None
    if other is not None:
        summary = {k: v for k, v in other._asdict().items() if k != "detail"}
    return {"status": status, "warning": warning, "max_weight_share": share, "z": z, "other": summary}
