"""Sample autocovariances of a long series in memory that does not grow with its length
(the block bootstrap's block length, :func:`posbench.metrics.block_bootstrap.block_length`)."""

from __future__ import annotations

import numpy as np

#: the longest series [samples] whose autocovariance is one FFT of the whole; a longer one is
#: taken block by block (:func:`autocovariance`), so that memory does not grow with a drive
AUTOCOVARIANCE_BLOCK = 1 << 18


def autocovariance(x: np.ndarray, max_lag: int, block: int = AUTOCOVARIANCE_BLOCK) -> np.ndarray:
    """Sample autocovariances (divisor n) of ``x`` at lags 0 .. max_lag, through the FFT: of
    the whole series up to ``block`` samples, else block by block (each block of ``block``
    samples correlated with itself and the ``max_lag`` samples after it, the products summed:
    the same sums, in memory of the order of ``block + max_lag`` whatever the length)."""
    n = x.size
    d = x - x.mean()
    if n <= block:
        size = 1 << (2 * n - 1).bit_length()
        f = np.fft.rfft(d, size)
        return np.fft.irfft(f * np.conj(f), size)[: max_lag + 1] / n
    out = np.zeros(max_lag + 1)
    size = 1 << (2 * (block + max_lag) - 1).bit_length()
    for start in range(0, n, block):
        head = d[start : start + block]  # the lags' first factors
        tail = d[start : start + block + max_lag]  # their partners, up to max_lag later
        c = np.fft.irfft(np.conj(np.fft.rfft(head, size)) * np.fft.rfft(tail, size), size)
        out += c[: max_lag + 1]
    return out / n
