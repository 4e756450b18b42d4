"""Tuning of controller parameters: a MATLAB-faithful GA and gradient descent through the simulator.

:mod:`pfjax.tuning.ga` is NumPy in / NumPy out around a batched cost; :mod:`pfjax.tuning.gradient`
differentiates :func:`pfjax.sim.simulate_batch`; :mod:`pfjax.tuning.multistart` makes that a
reliable global tuner (screening, successive halving of BFGS chains, restarts, smoothing);
:mod:`pfjax.tuning.check` tells whether given gains are a local minimum; :mod:`pfjax.tuning.cost`
holds the costs all of them use.
"""

from pfjax.tuning.check import CheckResult, check_point
from pfjax.tuning.cost import CostSpec
from pfjax.tuning.ga import GAOptions, GAResult, ga, ga_bits
from pfjax.tuning.multistart import MultistartOptions, multistart_tune

__all__ = [
    "CheckResult",
    "CostSpec",
    "GAOptions",
    "GAResult",
    "MultistartOptions",
    "check_point",
    "ga",
    "ga_bits",
    "multistart_tune",
]
