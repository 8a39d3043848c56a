"""Exact quantiles of values that arrive in pieces (one drive at a time), holding little.

Pass one counts each piece's values per bin (:class:`BinCounts`): bins ordered as the values
are (:func:`value_bins`: a float's leading bits, :data:`BINS_PER_OCTAVE` bins an octave, the
same on every run and machine), so the counts of a whole run stay as small as the range of
its values, and adding them is exact in any order of pieces or workers. The counts say which
bins hold the order statistics a quantile reads (:meth:`BinCounts.wanted`); pass two keeps
only the values of those bins (:meth:`BinCounts.keeps`), and :meth:`BinCounts.quantiles` reads
the order statistics off them: exactly what ``np.median`` and ``np.percentile`` (linear
interpolation) give on all the values, to the bit. Pure numpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

#: bins per octave of |value| (a bin is at most 1/64 = 1.6 % of its values wide)
BINS_PER_OCTAVE = 64
_SHIFT = 52 - int(math.log2(BINS_PER_OCTAVE))
_MAGNITUDE = np.int64(0x7FFF_FFFF_FFFF_FFFF)
#: a piece whose values span fewer bins than this is counted densely (else sorted)
_DENSE = 1 << 16


def value_bins(values: np.ndarray) -> np.ndarray:
    """Each finite float's bin (int64), non-decreasing in the value: the float's bits read
    as an integer that orders as the floats do, less its last mantissa bits."""
    bits = np.ascontiguousarray(values, dtype=np.float64).view(np.int64)
    ordered = np.where(bits < 0, bits ^ _MAGNITUDE, bits)
    out: np.ndarray = ordered >> _SHIFT
    return out


def bin_floor(bins: np.ndarray) -> np.ndarray:
    """The smallest float of each bin of :func:`value_bins` (its inverse at a bin's start):
    every value of bin ``b`` lies in ``[bin_floor(b), bin_floor(b + 1))``."""
    ordered = np.asarray(bins, dtype=np.int64) << _SHIFT
    bits = np.where(ordered < 0, ordered ^ _MAGNITUDE, ordered)
    out: np.ndarray = bits.view(np.float64)
    return out


def quantile_ranks(n: int, q: float) -> tuple[int, int, float]:
    """The order statistics (0-based ranks, lower and upper) of ``n`` sorted values that
    ``np.percentile(values, q)`` (linear, ``q`` in [0, 100]) interpolates between, and the
    weight of the upper."""
    virtual = (n - 1) * (q / 100.0)
    if virtual >= n - 1:
        return n - 1, n - 1, 0.0
    lo = math.floor(virtual)
    return lo, lo + 1, virtual - lo


def _lerp(a: float, b: float, t: float) -> float:
    """numpy's linear interpolation between a and b at t (its rounding, to the bit)."""
    d = b - a
    return b - d * (1.0 - t) if t >= 0.5 else a + d * t


def count_bins(bins: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct bins of some values' :func:`value_bins` (ascending) and how many of the
    values each holds."""
    lo = int(bins.min())
    if int(bins.max()) - lo < _DENSE:  # a count per bin of the range: no sort
        dense = np.bincount(bins - lo)
        present = np.flatnonzero(dense)
        return present + lo, dense[present]
    found, counts = np.unique(bins, return_counts=True)
    return found, counts


class BinCounts:
    """How many values fell in each bin (:func:`value_bins`), added piece by piece; then the
    wanted order statistics' bins, and from their values the exact quantiles.

    ``quantiles`` names what is wanted: ``"median"`` (as ``np.median``) or a percentile
    in [0, 100] (as ``np.percentile``, linear)."""

    def __init__(self, quantiles: Sequence[str | float]) -> None:
        self.names = tuple(quantiles)
        self.bins = np.empty(0, dtype=np.int64)
        self.counts = np.empty(0, dtype=np.int64)
        self._wanted: np.ndarray | None = None
        self._kept: list[np.ndarray] = []

    def cdf(self, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
        """The empirical CDF of the values counted (their minimum ``low`` and maximum
        ``high``, known apart) where it is exact from the counts alone: 0 at ``low``, at
        each bin's end (the next bin's :func:`bin_floor`) the fraction of values below it,
        1 at ``high``: a point per bin that holds a value; (values, fractions)."""
        n = self.total
        if n == 0:
            return np.empty(0), np.empty(0)
        ends = bin_floor(self.bins[:-1] + 1)
        below = np.cumsum(self.counts[:-1]) / n
        return np.r_[low, ends, high], np.r_[0.0, below, 1.0]

    @property
    def total(self) -> int:
        """How many values were counted."""
        return int(self.counts.sum())

    def add(self, values: np.ndarray) -> None:
        """Count ``values`` (finite floats; pass one)."""
        if values.size:
            self.add_counts(*count_bins(value_bins(values)))

    def add_counts(self, bins: np.ndarray, counts: np.ndarray) -> None:
        """Add :func:`count_bins`' counts of some values (pass one)."""
        if bins.size == 0:
            return
        at = np.searchsorted(self.bins, bins)
        if at[-1] < self.bins.size and np.array_equal(self.bins[at], bins):
            self.counts[at] += counts  # bins seen before: the usual case after a few pieces
            return
        both = np.concatenate([self.bins, bins])
        bins, where = np.unique(both, return_inverse=True)
        merged = np.bincount(where, np.concatenate([self.counts, counts]).astype(float))
        self.bins, self.counts = bins, merged.astype(np.int64)

    def _ranks(self) -> list[tuple[int, int, float | None]]:
        """Per wanted quantile: lower and upper rank, and the percentile's weight (None: the
        median, the mean of the two middle values)."""
        n = self.total
        out: list[tuple[int, int, float | None]] = []
        for name in self.names:
            if name == "median":
                out.append(((n - 1) // 2, n // 2, None))
            else:
                out.append(quantile_ranks(n, float(name)))
        return out

    def wanted(self) -> np.ndarray:
        """The bins that hold the order statistics the quantiles read (after pass one)."""
        if self._wanted is None:
            ends = np.cumsum(self.counts)
            ranks = [r for lo, hi, _ in self._ranks() for r in (lo, hi)] if self.total else []
            at = np.searchsorted(ends, np.asarray(ranks, dtype=np.int64), side="right")
            self._wanted = np.unique(self.bins[at])
        return self._wanted

    def keep(self, values: np.ndarray, bins: np.ndarray | None = None) -> None:
        """Keep those of ``values`` (the same values as pass one's, piece by piece; ``bins``:
        their :func:`value_bins`, if known) that fall in a wanted bin (pass two)."""
        if values.size == 0:
            return
        mine = values[np.isin(value_bins(values) if bins is None else bins, self.wanted())]
        if mine.size:
            self._kept.append(mine)

    def quantiles(self) -> list[float]:
        """The wanted quantiles (NaN each with no value), from the kept values."""
        if not self.total:
            return [math.nan] * len(self.names)
        kept = np.sort(np.concatenate(self._kept)) if self._kept else np.empty(0)
        wanted = self.wanted()
        starts = np.concatenate([[0], np.cumsum(self.counts)[:-1]])
        # each wanted bin's first rank overall, and its first position among the kept
        first_rank = starts[np.searchsorted(self.bins, wanted)]
        first_kept = np.concatenate([[0], np.cumsum(self.counts[np.isin(self.bins, wanted)])])

        def at(rank: int) -> float:
            j = int(np.searchsorted(first_rank, rank, side="right")) - 1
            return float(kept[first_kept[j] + rank - first_rank[j]])

        out = []
        for lo, hi, t in self._ranks():
            a, b = at(lo), at(hi)
            out.append(a if lo == hi else (a + b) / 2.0 if t is None else _lerp(a, b, t))
        return out
