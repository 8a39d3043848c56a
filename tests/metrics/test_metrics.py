"""Metrics against hand-computed values."""

import numpy as np
import pytest

from posbench.metrics import (
    euclidean_error,
    latency_summary,
    speed_bin_labels,
    summarize,
    summarize_groups,
)


def test_euclidean_error_345():
    pred = np.array([[3.0, 4.0], [0.0, 0.0], [1.0, 1.0]])
    ref = np.array([[0.0, 0.0], [0.0, 0.0], [np.nan, 1.0]])
    e = euclidean_error(pred, ref)
    assert e[0] == 5.0 and e[1] == 0.0 and np.isnan(e[2])


def test_summarize_hand_values():
    s = summarize(np.array([1.0, 2.0, 3.0, 4.0, np.nan]))
    assert s["count"] == 4 and s["missing"] == 1
    assert s["mean_m"] == pytest.approx(2.5)
    assert s["median_m"] == pytest.approx(2.5)
    assert s["rmse_m"] == pytest.approx(np.sqrt(30 / 4))
    assert s["p95_m"] == pytest.approx(3.85)  # linear interpolation: 3 + 0.85 * (4 - 3)
    assert s["max_m"] == 4.0


def test_summarize_empty_is_nan_not_zero():
    s = summarize(np.array([np.nan]))
    assert s["count"] == 0 and s["missing"] == 1 and np.isnan(s["mean_m"])


def test_groups_and_order():
    g = summarize_groups(
        np.array([1.0, 3.0, 10.0]), np.array(["a", "a", "b"]), order=["b", "a", "c"]
    )
    assert list(g) == ["b", "a", "c"]
    assert g["a"]["mean_m"] == 2.0 and g["b"]["count"] == 1 and g["c"]["count"] == 0


def test_speed_bins():
    lab = speed_bin_labels(np.array([0.1, 4.9, 5.0, 35.0, np.nan]))
    assert lab.tolist() == ["<0.5 m/s", "0.5-5 m/s", "5-10 m/s", ">=30 m/s", "unknown"]
    # one string object per bin, shared by its rows (a long run's rows cost 8 bytes each)
    many = speed_bin_labels(np.full(1000, 7.0))
    assert many.dtype == object and len({id(v) for v in many}) == 1


def test_latency_summary_us():
    s = latency_summary(np.arange(1, 101) * 1000)  # 1..100 us
    assert s["count"] == 100 and s["max"] == 100.0
    assert s["p50"] == pytest.approx(50.5) and s["p99"] == pytest.approx(99.01)


@pytest.mark.parametrize("seed", range(4))
def test_latency_summary_one_drive_at_a_time_is_the_whole(seed):
    """Read per drive, twice, never joined: count, percentiles and max to the bit, the mean
    to rounding; no drive at all as an empty one."""
    from posbench.metrics.latency import streamed_latency_summary

    rng = np.random.default_rng(seed)
    drives = [rng.lognormal(9, 1, int(rng.integers(0, 400))).astype(np.int64) for _ in range(9)]
    got = streamed_latency_summary(lambda: iter(drives))
    want = latency_summary(np.concatenate(drives))
    assert got == {**want, "mean": pytest.approx(want["mean"], rel=1e-12)}
    empty = streamed_latency_summary(lambda: iter([]))
    assert empty["count"] == 0 and np.isnan(empty["p50"])


def test_outage_ids_and_scores():
    from posbench.metrics.outages import error_vs_since_fix, outage_ids, outage_scores

    t = np.array([0.0, 1.0, 1.5, 2.0, 3.0, 10.5, 11.0, 12.0])
    ids = outage_ids(t, [(0.9, 2.5), (10.0, 11.5)])
    assert ids.tolist() == [-1, 0, 0, 0, -1, 1, 1, -1]
    err = np.array([9, 0.5, 1.0, 3.0, 9, 1.0, 1.5, 9])
    s = outage_scores(err, t, ids)
    assert s["outages"] == 2
    assert s["ade_mean_m"] == pytest.approx((1.5 + 1.25) / 2)
    assert s["fde_mean_m"] == pytest.approx((3.0 + 1.5) / 2)
    assert s["miss_rate"] == pytest.approx(0.5)
    c = error_vs_since_fix(np.array([1.0, 2.0, 3.0]), np.array([0.2, 0.98, 1.2]))
    assert c["0.2s"]["count"] == 1 and c["1s"]["mean_m"] == 2.0 and c["5s"]["count"] == 0
