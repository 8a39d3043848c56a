"""Accuracy and latency metrics: pure functions on numpy arrays (metres, microseconds)."""

from posbench.metrics.accuracy import (
    error_cdf,
    euclidean_error,
    speed_bin_labels,
    speed_bin_order,
    summarize,
    summarize_groups,
)
from posbench.metrics.latency import latency_summary

__all__ = [
    "error_cdf",
    "euclidean_error",
    "latency_summary",
    "speed_bin_labels",
    "speed_bin_order",
    "summarize",
    "summarize_groups",
]
