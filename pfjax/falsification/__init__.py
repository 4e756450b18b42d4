"""Worst-case search (falsification): gradient ascent through the simulator over bounded,
band-limited slip profiles and initial conditions, against random sampling at the same budget.

:mod:`pfjax.falsification.space` defines the search set and its parameterisation;
:mod:`pfjax.falsification.search` the two searches and the worst trajectory.
"""

from pfjax.falsification.search import OBJECTIVES, FalsifierResult, falsify, random_search, worst_trajectory
from pfjax.falsification.space import IC_KEYS, RawParams, SearchSpace, frequencies, search_space, slip_from_raw

__all__ = [
    "IC_KEYS",
    "OBJECTIVES",
    "FalsifierResult",
    "RawParams",
    "SearchSpace",
    "falsify",
    "frequencies",
    "random_search",
    "search_space",
    "slip_from_raw",
    "worst_trajectory",
]
