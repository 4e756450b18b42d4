"""Small failure probabilities (1e-4 ... 1e-8 and below) with intervals, over a batched
limit-state function on the standard-normal space (failure where ``g(u) <= 0``).

    monte_carlo(g, dim, n=...)                     # exact Clopper-Pearson interval
    subset_simulation(g, dim, target_rel_error=0.1) # no proposal; several failure regions
    cross_entropy_is(g, dim, starts=...)            # CE-fitted Gaussian-mixture proposal

Each returns a :class:`RareEstimate` (``p_fail``, ``ci95``, ``rel_error``, ``n_rollouts``,
``method``). :mod:`pfjax.rare.transform` maps a study's uncertain inputs to the standard-normal
space, :mod:`pfjax.rare.study` builds a study controller's limit-state function from them, and
:mod:`pfjax.rare.starts` maps the gradient falsifier's failure points there to start the proposal.
"""

from pfjax.rare.estimate import METHODS, RareEstimate, lognormal_interval, monte_carlo
from pfjax.rare.importance import Mixture, cross_entropy_is
from pfjax.rare.subset import subset_simulation

__all__ = [
    "METHODS",
    "Mixture",
    "RareEstimate",
    "cross_entropy_is",
    "lognormal_interval",
    "monte_carlo",
    "subset_simulation",
]
