"""The circular block bootstrap of one series in time order (a single drive's queries).

:func:`block_length` picks the block length [samples] from the series' autocorrelation
(Politis & White 2004, corrected 2009); :func:`block_resample` expresses the block bootstrap
as a cluster bootstrap over units of contiguous samples, so that its multiplicities plug into
the interval functions of :mod:`posbench.metrics.cluster_bootstrap` as clusters do. Seeded
and deterministic; pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posbench.metrics.autocovariance import autocovariance as _autocovariance
from posbench.metrics.cluster_bootstrap import DEFAULT_RESAMPLES

#: at most this many units in a block bootstrap (longer series get longer units)
MAX_UNITS = 1024
#: a resample joins at least this many blocks (a block is at most 1/MIN_BLOCKS of the series)
MIN_BLOCKS = 10


def block_length(x: np.ndarray) -> int:
    """Block length [samples] for the circular block bootstrap of a series in time order.

    The automatic rule of Politis & White (2004) with the correction of Patton, Politis &
    White (2009): b = (2 G^2 / D)^(1/3) n^(1/3), D = 4/3 g(0)^2, with g(0) (the long-run
    variance) and G = sum |k| gamma(k) estimated from the sample autocovariances gamma(k)
    under a flat-top window of 2m lags, m the first lag after which Kn = max(5,
    log10 n) autocorrelations in a row are insignificant (|rho| < 2 sqrt(log10 n / n)).
    It grows with how long the series remembers itself (about 75 samples for an AR(1) of
    coefficient 0.9 and n = 3000; 1-3 for independent samples). Rounded, at least 1, at
    most min(3 sqrt(n), n / :data:`MIN_BLOCKS`) so that a resample joins at least
    :data:`MIN_BLOCKS` blocks.
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.size
    cap = max(1, min(math.ceil(3.0 * math.sqrt(n)), n // MIN_BLOCKS))
    if n < 3:
        return 1
    kn = max(5, int(math.log10(n)))
    m_max = min(n - 1, math.ceil(math.sqrt(n)) + kn)
    acv = _autocovariance(x, m_max)
    if not acv[0] > 0:
        return 1  # a constant series: nothing to keep together
    small = np.abs(acv[1:] / acv[0]) < 2.0 * math.sqrt(math.log10(n) / n)  # lags 1 .. m_max
    runs = np.convolve(small.astype(np.int64), np.ones(kn, dtype=np.int64), "valid")
    first = np.flatnonzero(runs == kn)
    m = min(2 * max(int(first[0]), 1), m_max) if first.size else m_max
    k = np.arange(1, m + 1)
    t = k / m
    lam = np.where(t <= 0.5, 1.0, 2.0 * (1.0 - t))
    g0 = acv[0] + 2.0 * float(np.sum(lam * acv[1 : m + 1]))
    g = 2.0 * float(np.sum(lam * k * acv[1 : m + 1]))
    if not g0 > 0 or g == 0:
        return 1
    b = (2.0 * g * g / (4.0 / 3.0 * g0 * g0)) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    return int(max(1, min(round(b), cap)))


@dataclass(frozen=True)
class BlockResample:
    """A circular block bootstrap of one series of n samples, expressed as a cluster
    bootstrap over units of contiguous samples.

    Attributes:
        units: (n,) unit index of each sample (sample i is in unit i // unit_len).
        counts: (B, U) float64 multiplicity of each unit in each resample.
        block_len: samples per resampled block (a multiple of ``unit_len``).
        unit_len: samples per unit.
    """

    units: np.ndarray
    counts: np.ndarray
    block_len: int
    unit_len: int


@lru_cache(maxsize=16)
def _block_counts(n_units: int, per_block: int, n_resamples: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    n_blocks = -(-n_units // per_block)
    starts = rng.integers(0, n_units, size=(n_resamples, n_blocks))
    starts += (np.arange(n_resamples) * n_units)[:, None]
    c = np.bincount(starts.ravel(), minlength=n_resamples * n_units).reshape(n_resamples, n_units)
    # a block starting at unit s covers s .. s+per_block-1 (circularly): the weight of
    # unit u is the number of starts in u-per_block+1 .. u, a circular moving sum
    m = min(per_block, n_units)
    if m <= 4:  # a few shifted additions along the flat array, wrapped rows corrected
        w = c.astype(np.float32)
        flat_w, flat_c = w.ravel(), c.ravel()
        for j in range(1, m):
            flat_w[j:] += flat_c[:-j]
            w[1:, :j] -= c[:-1, n_units - j :]
            w[:, :j] += c[:, n_units - j :]
    else:  # a cumulative sum over the row with its last m-1 units in front
        ext = np.zeros((n_resamples, n_units + m), dtype=np.int32)
        ext[:, 1:m] = c[:, n_units - m + 1 :]
        ext[:, m:] = c
        np.cumsum(ext, axis=1, out=ext)
        w = (ext[:, m:] - ext[:, :n_units]).astype(np.float32)
    w.flags.writeable = False
    return w


#: a block spans about this many units (block starts lie on a grid of one unit)
UNITS_PER_BLOCK = 4


def unit_length(n: int, block_len: int = 1) -> int:
    """Samples per unit in :func:`block_resample` of a series of ``n`` in blocks of
    ``block_len``: a quarter block (:data:`UNITS_PER_BLOCK`), but at least half of n^(1/3)
    (finer grids cost time and change little) and long enough for at most
    :data:`MAX_UNITS` units."""
    return int(
        max(1, round(n ** (1.0 / 3.0) / 2.0), -(-block_len // UNITS_PER_BLOCK), -(-n // MAX_UNITS))
    )


def block_resample(
    n: int, block_len: int, n_resamples: int = DEFAULT_RESAMPLES, seed: int = 0
) -> BlockResample:
    """Circular block bootstrap of a series of ``n`` samples in time order.

    The series is cut into units of :func:`unit_length` contiguous samples; a block is
    ``per_block`` = round(block_len / unit_len) consecutive units (at least one; wrapping
    around the end), its start drawn uniformly among the units; each resample joins
    ceil(U / per_block) blocks, about n samples. Block starts are thus on a grid of one
    unit (a circular block bootstrap whose starts are every unit_len-th sample). The
    multiplicities per unit plug into :func:`posbench.metrics.cluster_bootstrap.ratio_ci` and
    :func:`posbench.metrics.resampled_quantiles.resampled_quantiles` as
    clusters do. The block length actually used (per_block * unit_len) is returned.
    """
    if n < 1 or block_len < 1:
        raise ValueError(f"need n >= 1 and block_len >= 1, got {n}, {block_len}")
    unit_len = unit_length(n, block_len)
    n_units = -(-n // unit_len)
    per_block = min(n_units, max(1, round(min(block_len, n) / unit_len)))
    counts = _block_counts(n_units, per_block, int(n_resamples), int(seed))
    return BlockResample(np.arange(n) // unit_len, counts, per_block * unit_len, unit_len)
