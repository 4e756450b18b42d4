"""Per-run metrics (running accumulators) and robustness statistics over many runs.

The robustness statistics (:mod:`pfjax.metrics.robustness`, NumPy/SciPy/pandas on the host) are
imported on first use, so a simulation, which needs only the running metrics, does not pay for
importing pandas and SciPy.
"""

from importlib import import_module

from pfjax.metrics.running import METRIC_NAMES, Metrics

#: Names this package re-exports from :mod:`pfjax.metrics.robustness` (imported on first access).
_ROBUSTNESS = (
    "clopper_pearson",
    "failure_drivers",
    "hoeffding_n",
    "metric_quantiles",
    "slip_margin",
    "success_summary",
    "supported_statement",
    "zero_failure_n",
)

__all__ = ["METRIC_NAMES", "Metrics", *_ROBUSTNESS]


def __getattr__(name: str):
    if name in _ROBUSTNESS:
        return getattr(import_module("pfjax.metrics.robustness"), name)
    raise AttributeError(f"module 'pfjax.metrics' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
