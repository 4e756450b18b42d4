"""Per-run metrics (running accumulators) and robustness statistics over many runs."""

from pfjax.metrics.margins import slip_margin
from pfjax.metrics.robustness import (
    clopper_pearson,
    failure_drivers,
    hoeffding_n,
    metric_quantiles,
    success_summary,
    supported_statement,
    zero_failure_n,
)
from pfjax.metrics.running import METRIC_NAMES, Metrics

__all__ = [
    "METRIC_NAMES",
    "Metrics",
    "clopper_pearson",
    "failure_drivers",
    "hoeffding_n",
    "metric_quantiles",
    "slip_margin",
    "success_summary",
    "supported_statement",
    "zero_failure_n",
]
