"""Tuning of controller parameters: a MATLAB-faithful GA and gradient descent through the simulator.

:mod:`pfjax.tuning.ga` is NumPy in / NumPy out around a batched cost; :mod:`pfjax.tuning.gradient`
differentiates :func:`pfjax.sim.simulate_batch`; :mod:`pfjax.tuning.cost` holds the costs both use.
"""

from pfjax.tuning.ga import GAOptions, GAResult, ga, ga_bits

__all__ = ["GAOptions", "GAResult", "ga", "ga_bits"]
