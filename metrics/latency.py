"""Latency statistics: pure functions on per-call durations.

Durations come in integer nanoseconds (``time.perf_counter_ns`` deltas) and
are reported in microseconds as percentiles, never a single timing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

import numpy as np

from posbench.metrics.two_pass_quantiles import BinCounts

#: what each latency figure means (the report's glossary collects these)
DEFINITIONS = {
    "step p50 / p99": "median / 99th percentile [us] of the time one fix step takes "
    "(observe_gps plus the future query), perf_counter_ns, one process.",
    "query p50": "median [us] of one between-fix position_at call (a now query).",
}


_PERCENTILES = (50.0, 90.0, 99.0)


def latency_summary(durations_ns: np.ndarray) -> dict[str, float | int]:
    """count, p50, p90, p99, max and mean [us] of call durations given in ns."""
    d = np.asarray(durations_ns, dtype=float) / 1e3
    if d.size == 0:
        return {
            "count": 0,
            "p50": float("nan"),
            "p90": float("nan"),
            "p99": float("nan"),
            "max": float("nan"),
            "mean": float("nan"),
        }
    p50, p90, p99 = np.percentile(d, _PERCENTILES)
    return {
        "count": int(d.size),
        "p50": float(p50),
        "p90": float(p90),
        "p99": float(p99),
        "max": float(d.max()),
        "mean": float(d.mean()),
    }


def streamed_latency_summary(
    pieces: Callable[[], Iterable[np.ndarray]],
) -> dict[str, float | int]:
    """:func:`latency_summary` of the durations [ns] of every array ``pieces()`` yields (e.g.
    one per drive), read twice and never joined: count, percentiles and max exactly as on
    the arrays joined (:class:`~posbench.metrics.two_pass_quantiles.BinCounts`), the mean
    to rounding. What is held: the durations' bin counts and those of a few bins."""
    bins = BinCounts(_PERCENTILES)
    count, sums, top = 0, [], -math.inf
    for piece in pieces():
        d = np.asarray(piece, dtype=float) / 1e3
        if d.size:
            bins.add(d)
            count += int(d.size)
            sums.append(float(d.sum()))
            top = max(top, float(d.max()))
    if count == 0:
        return latency_summary(np.empty(0))
    for piece in pieces():
        bins.keep(np.asarray(piece, dtype=float) / 1e3)
    p50, p90, p99 = bins.quantiles()
    return {
        "count": count,
        "p50": p50,
        "p90": p90,
        "p99": p99,
        "max": top,
        "mean": math.fsum(sums) / count,
    }
