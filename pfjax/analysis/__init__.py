"""Analyses on top of the models: equilibria and local stability (docs/reproductions/path-following.md §7)."""

from pfjax.analysis.stability import (
    Equilibrium,
    PIQuasiEquilibrium,
    closed_loop_field,
    converged_to,
    equilibrium,
    pi_quasi_equilibrium,
    source_linearisation,
    stability_map,
)

__all__ = [
    "Equilibrium",
    "PIQuasiEquilibrium",
    "closed_loop_field",
    "converged_to",
    "equilibrium",
    "pi_quasi_equilibrium",
    "source_linearisation",
    "stability_map",
]
