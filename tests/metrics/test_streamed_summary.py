"""A StreamedSummary fed one drive at a time gives what summarize and summary_ci give on every
drive's errors joined: counts, quantiles, maxima and intervals to the bit, means and RMSE to
rounding; with fewer intervals asked, the mean's alone (as summary_ci(quantiles=False)) or
none."""

from __future__ import annotations

import math

import numpy as np
import pytest

from posbench.metrics.accuracy import summarize
from posbench.metrics.bootstrap import summary_ci
from posbench.metrics.streamed_summary import StreamedSummary


def _drives(seed: int, n: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        e = rng.gamma(2.0, 0.1, int(rng.integers(0, 60)))
        e[rng.random(e.size) < 0.05] = np.nan
        out.append(e)
    return out


def _equal(got: float, want: float) -> bool:
    return (math.isnan(got) and math.isnan(want)) or got == want


@pytest.mark.parametrize("intervals", ["all", "mean", "none"])
@pytest.mark.parametrize(("seed", "n"), [(0, 1), (1, 7), (2, 30)])
def test_one_drive_at_a_time_is_the_whole(intervals, seed, n):
    drives = _drives(seed, n)
    s = StreamedSummary(300, 5, 0.9, intervals)
    for e in drives:
        s.add(e)
    s.wanted()
    for e in drives:
        s.keep(e)
    got = s.summary()
    errors = np.concatenate(drives)
    clusters = np.concatenate([np.full(e.size, i) for i, e in enumerate(drives)])
    whole = summarize(errors)
    for key in ("count", "missing", "median_m", "p95_m", "max_m"):
        assert _equal(got[key], whole[key]), key
    for key in ("mean_m", "rmse_m"):
        assert got[key] == pytest.approx(whole[key], rel=1e-12, nan_ok=True)
    if intervals == "none":
        assert "ci" not in got
        return
    ci = summary_ci(errors, clusters, None, 300, 5, 0.9, quantiles=intervals == "all")
    assert got["ci"]["clusters"] == ci["clusters"]
    assert got["ci"]["mean_m"] == pytest.approx(ci["mean_m"], rel=1e-12, nan_ok=True)
    for key in ("median_m", "p95_m"):
        assert all(_equal(a, b) for a, b in zip(got["ci"][key], ci[key], strict=True)), key
    if intervals == "mean":
        assert all(math.isnan(x) for x in got["ci"]["median_m"])
