"""Two-pass quantiles: counted per bin in pieces, then read off the kept values of the
wanted bins, they are numpy's median and percentile to the bit, whatever the pieces."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from posbench.metrics.two_pass_quantiles import BinCounts, value_bins

WANTED = ("median", 95, 50, 5, 0, 100)


def _two_pass(pieces: list[np.ndarray]) -> list[float]:
    counts = BinCounts(WANTED)
    for p in pieces:
        counts.add(p)
    for p in pieces:
        counts.keep(p)
    return counts.quantiles()


def _numpy(v: np.ndarray) -> list[float]:
    return [float(np.median(v))] + [float(np.percentile(v, q)) for q in WANTED[1:]]


@settings(max_examples=300, deadline=None)
@given(
    values=st.lists(st.floats(-1e300, 1e300, allow_nan=False, width=64), min_size=1, max_size=300),
    cuts=st.lists(st.integers(0, 300), max_size=5),
)
def test_numpy_figures_to_the_bit_however_cut(values, cuts):
    v = np.array(values)
    pieces = np.split(v, sorted(c for c in cuts if c <= v.size))
    assert _two_pass(pieces) == _numpy(v)


@pytest.mark.parametrize("seed", range(5))
def test_ties_zeros_and_spans_of_many_octaves(seed):
    rng = np.random.default_rng(seed)
    v = np.concatenate(
        [
            np.round(rng.exponential(1.0, 500), 2),  # ties
            np.zeros(50),
            -np.zeros(20),
            rng.lognormal(0.0, 8.0, 200),  # beyond the dense count's range
        ]
    )
    rng.shuffle(v)
    assert _two_pass(np.array_split(v, 7)) == _numpy(v)


def test_keeps_only_the_wanted_bins():
    rng = np.random.default_rng(0)
    v = rng.lognormal(0.0, 1.0, 100_000)
    counts = BinCounts(("median", 95))
    counts.add(v)
    counts.keep(v)
    kept = sum(k.size for k in counts._kept)
    assert kept < v.size / 50  # a few bins' values, not the whole
    assert counts.quantiles() == [float(np.median(v)), float(np.percentile(v, 95))]


def test_no_values_gives_nan_and_bins_follow_the_values():
    assert all(np.isnan(BinCounts(("median", 95)).quantiles()))
    v = np.sort(np.random.default_rng(1).normal(0.0, 1e3, 1000))
    assert np.all(np.diff(value_bins(v)) >= 0)


@pytest.mark.parametrize("seed", range(3))
def test_the_cdf_from_counts_is_exact_at_each_point(seed):
    """At each point of BinCounts.cdf, the fraction of the values below it (1 at the
    maximum, 0 at the minimum), however the values were cut; a point per bin."""
    rng = np.random.default_rng(seed)
    values = np.concatenate([rng.lognormal(-2, 1.5, 5000), [0.0, 0.0]])
    counts = BinCounts(())
    for piece in np.array_split(values, 7):
        counts.add(piece)
    x, f = counts.cdf(float(values.min()), float(values.max()))
    below = np.searchsorted(np.sort(values), x[1:-1], side="left") / values.size
    np.testing.assert_array_equal(f[1:-1], below)
    assert (x[0], f[0], x[-1], f[-1]) == (values.min(), 0.0, values.max(), 1.0)
    assert np.all(np.diff(x) > 0) and x.size == counts.bins.size + 1
