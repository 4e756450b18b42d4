"""Analyses on top of the models: equilibria and local stability (docs/reproductions/path-following.md §7)."""

from pfjax.analysis.stability import (
    Equilibrium,
    closed_loop_field,
    converged_to,
    equilibrium,
    source_linearisation,
    stability_map,
)

__all__ = ["Equilibrium", "closed_loop_field", "converged_to", "equilibrium", "source_linearisation", "stability_map"]
