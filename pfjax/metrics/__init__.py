"""Per-run metrics (running accumulators) and robustness statistics over many runs.

The robustness statistics (:mod:`pfjax.metrics.robustness`, :mod:`pfjax.metrics.margins`;
NumPy/SciPy/pandas on the host) are imported on first use, so a simulation, which needs only the
running metrics, does not pay for importing pandas and SciPy.
"""

from importlib import import_module

from pfjax.metrics.running import METRIC_NAMES, Metrics

#: Statistics this package re-exports, by the module that defines them (imported on first access).
_LAZY = {
    "certify_n": "robustness",
    "clopper_pearson": "robustness",
    "failure_drivers": "robustness",
    "hoeffding_n": "robustness",
    "metric_quantiles": "robustness",
    "paired_interval": "robustness",
    "success_summary": "robustness",
    "supported_statement": "robustness",
    "worst_first": "robustness",
    "zero_failure_n": "robustness",
    "slip_margin": "margins",
}

__all__ = ["METRIC_NAMES", "Metrics", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(import_module(f"pfjax.metrics.{_LAZY[name]}"), name)
    raise AttributeError(f"module 'pfjax.metrics' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
