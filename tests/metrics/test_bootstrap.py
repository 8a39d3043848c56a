"""metrics.bootstrap against cases with known answers: the cluster bootstrap of one query per
drive is the ordinary bootstrap (analytic width), identical predictors differ by exactly 0,
a seed fixes every interval, correlated queries inside drives widen the interval, a single
drive is block-resampled with its block length reported, and the fast quantiles equal a
slow exact reference."""

from __future__ import annotations

import math

import numpy as np
import pytest

from posbench.metrics.block_bootstrap import MIN_BLOCKS, block_length, block_resample, unit_length
from posbench.metrics.bootstrap import DEFINITIONS, paired_summary, summary_ci, summary_cis
from posbench.metrics.cluster_bootstrap import (
    cluster_weights,
    paired_ratio_diff,
    quantile_ci,
    ratio_ci,
    resample_counts,
    resampled_means,
)
from posbench.metrics.resampled_quantiles import resampled_quantiles, resampled_quantiles_many


def _ar1(n: int, phi: float, rng: np.random.Generator) -> np.ndarray:
    x = np.empty(n)
    x[0] = rng.normal()
    eps = rng.normal(size=n) * math.sqrt(1 - phi * phi)
    for i in range(1, n):
        x[i] = phi * x[i - 1] + eps[i]
    return x


# ------------------------------------------------------------ resamples
def test_resample_counts_are_multinomial_rows_and_seeded():
    w = resample_counts(7, 500, seed=3)
    assert w.shape == (500, 7) and w.dtype.kind == "i" and (w >= 0).all()
    assert (w.sum(axis=1) == 7).all()
    np.testing.assert_array_equal(w, resample_counts(7, 500, seed=3))
    assert not np.array_equal(w, resample_counts(7, 500, seed=4))
    # each cluster is drawn once per resample on average
    assert w.mean() == pytest.approx(1.0, abs=0.05)
    np.testing.assert_array_equal(cluster_weights(7, 500, 3), w)
    with pytest.raises(ValueError):
        resample_counts(0)


def test_block_resample_covers_whole_blocks_of_contiguous_queries():
    br = block_resample(1000, 24, n_resamples=300, seed=1)
    unit = unit_length(1000, 24)
    assert br.unit_len == unit and br.block_len % unit == 0
    assert br.block_len == pytest.approx(24, abs=unit)
    np.testing.assert_array_equal(br.units, np.arange(1000) // unit)
    n_units = br.counts.shape[1]
    per_block = br.block_len // unit
    # every resample joins ceil(U / per_block) blocks of per_block units: about n queries
    assert (br.counts.sum(axis=1) == -(-n_units // per_block) * per_block).all()
    assert np.all(br.counts == np.round(br.counts))


# ------------------------------------------------------------- known answers
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_query_per_drive_is_the_ordinary_bootstrap_with_the_analytic_width(seed):
    """i.i.d. normal errors, one query per drive: the cluster bootstrap interval of the
    mean is as wide as 2 * 1.96 * sd / sqrt(n), within 10 %."""
    rng = np.random.default_rng(100 + seed)
    n = 400
    e = rng.normal(3.0, 0.5, n)
    ci = summary_ci(e, np.arange(n), seed=seed)
    analytic = 2 * 1.96 * e.std(ddof=1) / math.sqrt(n)
    width = ci["mean_m"][1] - ci["mean_m"][0]
    assert width == pytest.approx(analytic, rel=0.10)
    assert ci["mean_m"][0] < e.mean() < ci["mean_m"][1]
    assert ci["clusters"] == n and ci["block_len"] is None


def test_identical_predictors_differ_by_exactly_zero():
    rng = np.random.default_rng(5)
    e = rng.gamma(2.0, 0.1, 3000)
    drives = rng.integers(0, 12, 3000)
    r = paired_summary(e, e.copy(), drives)
    assert r["diff_m"] == 0.0 and r["ci95"] == [0.0, 0.0]
    assert r["wins"] == 0 and r["win_share"] == 0.0 and not r["conclusive"]
    assert r["drives"] == 12 and r["queries"] == 3000
    one = paired_summary(e, e.copy(), np.zeros(3000, dtype=int))  # one drive: blocks
    assert one["diff_m"] == 0.0 and one["ci95"] == [0.0, 0.0] and one["block_len"] >= 1
    # from per-drive sums and counts only (what `bench compare` has)
    s = np.bincount(drives, weights=e)
    c = np.bincount(drives)
    d = paired_ratio_diff(s, c, s.copy(), c.copy(), resample_counts(12, 1000, 0))
    assert d == {"diff": 0.0, "lo": 0.0, "hi": 0.0}


def test_paired_difference_sign_and_wins():
    """diff = mean_b - mean_a: b worse by 0.1 on every query -> +0.1, no wins for b."""
    rng = np.random.default_rng(6)
    a = rng.gamma(2.0, 0.1, 2000)
    drives = np.repeat(np.arange(20), 100)
    worse = paired_summary(a, a + 0.1, drives)
    assert worse["diff_m"] == pytest.approx(0.1)
    assert worse["ci95"][0] == pytest.approx(0.1) and worse["ci95"][1] == pytest.approx(0.1)
    assert worse["conclusive"] and worse["wins"] == 0
    better = paired_summary(a, a * 0.5, drives)
    assert better["diff_m"] < 0 and better["ci95"][1] < 0 and better["wins"] == 20
    assert better["win_share"] == 1.0
    # only queries both answered count
    b = a * 0.5
    b[:100] = np.nan  # drive 0 unanswered by b
    part = paired_summary(a, b, drives)
    assert part["queries"] == 1900 and part["drives"] == 19


def test_a_seed_fixes_every_interval():
    rng = np.random.default_rng(7)
    e = rng.gamma(2.0, 0.1, 5000)
    drives = rng.integers(0, 30, 5000)
    assert summary_ci(e, drives, seed=11) == summary_ci(e, drives, seed=11)
    assert summary_ci(e, drives, seed=11) != summary_ci(e, drives, seed=12)
    one = np.zeros(5000, dtype=int)
    assert summary_ci(e, one, seed=11) == summary_ci(e, one, seed=11)


def test_correlated_queries_inside_drives_widen_the_interval():
    """20 drives of 200 queries sharing a strong per-drive offset: resampling drives gives
    a much wider (honest) interval than resampling queries as if independent."""
    rng = np.random.default_rng(8)
    offsets = rng.normal(0.0, 1.0, 20)
    drives = np.repeat(np.arange(20), 200)
    e = 5.0 + offsets[drives] + rng.normal(0.0, 0.1, drives.size)
    clustered = summary_ci(e, drives)
    naive = summary_ci(e, np.arange(e.size))  # every query its own cluster
    for key in ("mean_m", "median_m", "p95_m"):
        w_c = clustered[key][1] - clustered[key][0]
        w_n = naive[key][1] - naive[key][0]
        assert w_c > 3 * w_n, (key, w_c, w_n)
    # the clustered interval is about the spread of 20 drive means
    analytic = 2 * 1.96 * offsets.std(ddof=1) / math.sqrt(20)
    assert clustered["mean_m"][1] - clustered["mean_m"][0] == pytest.approx(analytic, rel=0.25)


def test_one_drive_is_block_resampled_and_reports_its_block_length():
    rng = np.random.default_rng(9)
    n = 3000
    x = 2.0 + _ar1(n, 0.9, rng)  # autocorrelation 0.9^k: below 1/e from lag 10
    ci = summary_ci(x, np.zeros(n, dtype=int))
    assert ci["clusters"] == 1
    assert ci["block_len"] == block_resample(n, block_length(x)).block_len
    assert ci["block_len"] >= 30
    iid = summary_ci(x, np.arange(n))  # as if the queries were independent
    width = ci["mean_m"][1] - ci["mean_m"][0]
    assert width > 2.5 * (iid["mean_m"][1] - iid["mean_m"][0])
    # the long-run sd of an AR(1) mean: sd * sqrt((1 + phi) / (1 - phi)) / sqrt(n)
    analytic = 2 * 1.96 * math.sqrt(1.9 / 0.1) / math.sqrt(n)
    assert width == pytest.approx(analytic, rel=0.3)


def test_block_intervals_cover_the_true_mean_where_query_resampling_does_not():
    """Coverage over 60 AR(1) series (true mean 0): the block bootstrap covers nearly
    95 % (block bootstraps run a little under with strong correlation), resampling single
    queries far less."""
    rng = np.random.default_rng(10)
    hits_block = hits_naive = 0
    reps, n = 60, 1500
    for _ in range(reps):
        x = _ar1(n, 0.9, rng)
        b = summary_ci(x, np.zeros(n, dtype=int))["mean_m"]
        q = summary_ci(x, np.arange(n))["mean_m"]
        hits_block += b[0] <= 0.0 <= b[1]
        hits_naive += q[0] <= 0.0 <= q[1]
    assert hits_block / reps >= 0.85
    assert hits_naive / reps <= 0.6


def test_block_length_rule():
    """Politis-White: short blocks for independent samples, longer the longer a series
    remembers itself, never more than n / MIN_BLOCKS."""
    rng = np.random.default_rng(11)
    assert block_length(rng.normal(size=8000)) <= 4
    assert block_length(np.ones(500)) == 1  # constant: nothing to keep together
    short, long_ = (block_length(_ar1(3000, phi, rng)) for phi in (0.5, 0.9))
    assert 3 <= short < long_ and long_ >= 30
    # the rule's value for an AR(1): (2 G^2 / D)^(1/3) n^(1/3), G = 2 phi / (1 - phi)^2,
    # g(0) = (1 + phi) / (1 - phi) (unit variance): 74 for phi = 0.9, n = 3000
    phi = 0.9
    g, g0 = 2 * phi / (1 - phi) ** 2, (1 + phi) / (1 - phi)
    b = (2 * g * g / (4 / 3 * g0 * g0)) ** (1 / 3) * 3000 ** (1 / 3)
    assert long_ == pytest.approx(b, rel=0.5)
    trend = np.linspace(0.0, 1.0, 500)  # never forgets: close to the cap
    assert 30 <= block_length(trend) <= 500 // MIN_BLOCKS
    assert block_length(np.arange(100.0)) <= 100 // MIN_BLOCKS
    assert block_length(np.array([1.0])) == 1


def test_no_error_gives_nan_intervals():
    ci = summary_ci(np.array([np.nan, np.nan]), np.array([0, 1]))
    assert ci["clusters"] == 0 and all(math.isnan(v) for v in ci["mean_m"] + ci["p95_m"])
    r = paired_summary(np.array([1.0, np.nan]), np.array([np.nan, 2.0]), np.array([0, 1]))
    assert r["queries"] == 0 and r["drives"] == 0 and not r["conclusive"]


# ------------------------------------------------------ quantiles: exactness
def _slow_quantiles(values, units, w, qs):
    """np.percentile of each resample written out value by value."""
    out = np.full((w.shape[0], len(qs)), np.nan)
    for b in range(w.shape[0]):
        rep = np.repeat(values, w[b][units].astype(int))
        if rep.size:
            out[b] = np.percentile(rep, [100 * q for q in qs])
    return out


@pytest.mark.parametrize(
    ("n", "d", "ties"),
    [
        (1, 1, False),
        (7, 3, False),
        (300, 5, True),
        (4000, 40, False),
        (2500, 2500, False),
        (20000, 4, True),
    ],
)
def test_resampled_quantiles_equal_the_slow_exact_reference(n, d, ties):
    rng = np.random.default_rng(n + d)
    v = rng.gamma(2.0, 1.0, n)
    if ties:
        v = np.round(v, 1)
    u = rng.integers(0, d, n)
    w = resample_counts(d, 60, seed=1)
    order = np.argsort(v)
    qs = (0.0, 0.025, 0.5, 0.95, 1.0)
    got = resampled_quantiles(v[order], u[order], w, qs)
    want = _slow_quantiles(v[order], u[order], w, qs)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12, equal_nan=True)


def test_block_quantiles_and_several_series_equal_the_reference():
    rng = np.random.default_rng(12)
    n = 1800
    br = block_resample(n, 15, n_resamples=80, seed=2)
    series = []
    for _ in range(3):
        v = rng.gamma(2.0, 1.0, n)
        o = np.argsort(v)
        series.append((v[o], br.units[o]))
    many = resampled_quantiles_many(series, br.counts, (0.5, 0.95))
    for (v, u), got in zip(series, many, strict=True):
        np.testing.assert_allclose(
            got, _slow_quantiles(v, u, br.counts, (0.5, 0.95)), rtol=1e-12, atol=1e-12
        )


def test_quantile_intervals_are_percentiles_of_the_exact_resampled_quantiles():
    rng = np.random.default_rng(13)
    v = np.sort(rng.gamma(2.0, 1.0, 500))
    u = rng.integers(0, 10, 500)
    w = resample_counts(10, 400, seed=0)
    ((lo, hi),) = quantile_ci(v, u, w, (0.5,))
    ref = np.quantile(_slow_quantiles(v, u, w, (0.5,))[:, 0], [0.025, 0.975])
    assert (lo, hi) == pytest.approx(tuple(ref))


def test_means_are_pooled_per_resample():
    sums = np.array([10.0, 2.0, 30.0])
    counts = np.array([10, 1, 10])
    w = np.array([[1, 1, 1], [3, 0, 0], [0, 2, 1]])
    np.testing.assert_allclose(resampled_means(sums, counts, w), [42 / 21, 1.0, (4 + 30) / 12])
    assert ratio_ci(sums, counts, np.ones((5, 3))) == pytest.approx((2.0, 2.0))


def test_summary_cis_resample_the_series_of_one_drive_alike():
    """Several predictors on one drive: those with the same queries answered share the
    longest block length among them; each alone is what summary_ci gives; with several
    drives every series is exactly its summary_ci."""
    rng = np.random.default_rng(14)
    t = np.arange(900) * 0.05
    errors = [rng.gamma(2.0, 0.1, 900), 1.0 + _ar1(900, 0.9, rng), rng.gamma(2.0, 0.1, 900)]
    errors[2][::7] = np.nan  # missing answers: another set of queries, its own blocks
    one = np.zeros(900, dtype=int)
    together = summary_cis(errors, one, t)
    alone = [summary_ci(e, one, t) for e in errors]
    assert together[0]["block_len"] == together[1]["block_len"] == alone[1]["block_len"]
    assert alone[0]["block_len"] < alone[1]["block_len"]
    assert together[1] == alone[1] and together[2] == alone[2]
    drives = rng.integers(0, 9, 900)
    assert summary_cis(errors, drives, t) == [summary_ci(e, drives, t) for e in errors]


def test_definitions_name_the_figures_of_the_report():
    assert {"95 % CI", "block bootstrap", "paired difference", "wins", "conclusive"} <= set(
        DEFINITIONS
    )


def test_autocovariance_in_blocks_equals_the_whole_and_stays_small():
    """A long series' autocovariance block by block: the same sums as one FFT of the whole
    (to rounding), and no allocation of the order of the whole FFT (issue 46: an 8 h drive
    died in a MemoryError here)."""
    import tracemalloc

    from posbench.metrics.autocovariance import autocovariance as _autocovariance

    rng = np.random.default_rng(5)
    n, lag = 1 << 20, 900
    x = np.cumsum(rng.normal(size=n)) * 0.01 + rng.normal(size=n)
    whole = _autocovariance(x, lag, block=n)
    tracemalloc.start()
    blocked = _autocovariance(x, lag, block=1 << 14)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    np.testing.assert_allclose(blocked, whole, rtol=0, atol=1e-12 * whole[0])
    # the centred copy of the series (8 n bytes) and a few block-sized FFTs; the whole FFT
    # alone would take 4 x 16 n bytes
    assert peak < 8 * n + 64 * (1 << 16) * 16, peak
