"""2-D rigid alignment of a local-frame track to the GPS's ENU frame (pure numpy).

A truth named by the user (``--topic truth=/name``) in a local frame (``odom``, ``map``, ...:
REP 105 frames are metric but not ENU-aligned, and their origin is not the GPS's first fix)
is brought into the drive's ENU frame by a rotation + translation (no scale) fitted over the
whole drive: Umeyama's least-squares solution, as ``evo``'s ``--align``.

The one tolerance (:func:`alignment_limit_m`): the fit's residual RMS must not exceed
``max(ALIGN_ACC_FACTOR * median stated GPS accuracy, ALIGN_MIN_LIMIT_M)``; GPS fix noise alone
gives a residual of about sqrt(2) x the per-axis accuracy, so a larger residual means the
"truth" has scale error or drift (wheel odometry) and cannot be scored against.
"""

from __future__ import annotations

import math

import numpy as np

#: residual RMS limit = max(ALIGN_ACC_FACTOR * median stated accuracy [m], ALIGN_MIN_LIMIT_M)
ALIGN_ACC_FACTOR = 3.0
ALIGN_MIN_LIMIT_M = 5.0


def _umeyama(
    src: np.ndarray, dst: np.ndarray, with_scale: bool
) -> tuple[float, np.ndarray, np.ndarray, float]:
    """Umeyama's least-squares fit dst ~ s R src + t: (s, R, t, residual RMS [m])."""
    src = np.asarray(src, dtype=float).reshape(-1, 2)
    dst = np.asarray(dst, dtype=float).reshape(-1, 2)
    ok = np.all(np.isfinite(src), axis=1) & np.all(np.isfinite(dst), axis=1)
    src, dst = src[ok], dst[ok]
    if src.shape[0] < 2:
        raise ValueError("need at least 2 matched points to align")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    u, d, vt = np.linalg.svd(b.T @ a / src.shape[0])
    sgn = np.array([1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])  # no reflection
    r = u @ np.diag(sgn) @ vt
    var = float((a * a).sum() / src.shape[0])
    scale = (float((d * sgn).sum() / var) if var > 0 else float("nan")) if with_scale else 1.0
    t = mu_d - scale * (r @ mu_s)
    res = dst - (scale * (src @ r.T) + t)
    return scale, r, t, float(np.sqrt(np.mean(np.sum(res * res, axis=1))))


def umeyama_2d(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Rotation R (2, 2) and translation t (2,) minimising sum |R src_i + t - dst_i|^2.

    Args:
        src, dst: (N, 2) matched points [m], N >= 2 (rows with a NaN are ignored).
    Returns:
        (R, t, residual RMS [m]). R is a proper rotation (det +1, reflection excluded).
    Raises:
        ValueError: fewer than 2 finite pairs.
    """
    _, r, t, rms = _umeyama(src, dst, with_scale=False)
    return r, t, rms


def similarity_2d(src: np.ndarray, dst: np.ndarray) -> tuple[float, float, np.ndarray, float]:
    """Umeyama's least-squares similarity dst ~ s R src + t for (N, 2) point sets: the
    scale s, rotation [rad, counter-clockwise], translation t [m] and residual RMS [m].

    Raises:
        ValueError: fewer than 2 finite pairs.
    """
    scale, r, t, rms = _umeyama(src, dst, with_scale=True)
    return scale, float(np.arctan2(r[1, 0], r[0, 0])), t, rms


def alignment_limit_m(median_accuracy_m: float | None) -> float:
    """The largest acceptable residual RMS [m] of a truth-to-GPS fit (see module doc)."""
    if median_accuracy_m is None or not math.isfinite(median_accuracy_m):
        return ALIGN_MIN_LIMIT_M
    return max(ALIGN_ACC_FACTOR * median_accuracy_m, ALIGN_MIN_LIMIT_M)
