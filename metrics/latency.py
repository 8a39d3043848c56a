"""Latency statistics: pure functions on per-call durations.

Durations come in integer nanoseconds (``time.perf_counter_ns`` deltas) and
are reported in microseconds as percentiles, never a single timing.
"""

from __future__ import annotations

import numpy as np

#: what each latency figure means (the report's glossary collects these)
DEFINITIONS = {
    "step p50 / p99": "median / 99th percentile [us] of the time one fix step takes "
    "(observe_gps plus the future query), perf_counter_ns, one process.",
    "query p50": "median [us] of one between-fix position_at call (a now query).",
}


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
    p50, p90, p99 = np.percentile(d, [50, 90, 99])
    return {
        "count": int(d.size),
        "p50": float(p50),
        "p90": float(p90),
        "p99": float(p99),
        "max": float(d.max()),
        "mean": float(d.mean()),
    }
