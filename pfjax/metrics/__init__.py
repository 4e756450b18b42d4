"""Per-run metrics (running accumulators) and, later, aggregate statistics."""

from pfjax.metrics.running import METRIC_NAMES, Metrics

__all__ = ["METRIC_NAMES", "Metrics"]
