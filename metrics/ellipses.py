"""Geometry of 2-D covariance ellipses: the p-ellipse of many covariances at once.

The p-ellipse of a 2x2 position covariance P (ENU, m^2) is {e : e' P^-1 e <= r^2} with
r^2 = -2 ln(1 - p), the chi-square 2-DoF quantile (:func:`posbench.metrics.calibration.ellipse_r2`;
p = 0.95: r^2 = 5.991). In the eigenbasis of P (eigenvalues l1 >= l2) it is an ellipse with
semi-axes r sqrt(l1) and r sqrt(l2), the major one at angle theta = atan2(2 P_xy,
P_xx - P_yy) / 2 from east, counter-clockwise (towards north).

Covariances come as (N, 3) columns (xx, xy, yy) [m^2], as in the traces. Rows that are not
finite and positive definite give NaN (no ellipse). Pure numpy, closed-form (no per-row
eigen solver).
"""

from __future__ import annotations

import numpy as np

from posbench.metrics.calibration import ellipse_r2

#: segments of a drawn ellipse outline (the outline has one more point: it is closed)
ELLIPSE_SEGMENTS = 24


def ellipse_axes(cov: np.ndarray, p: float = 0.95) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Semi-major and semi-minor axis [m] and orientation [rad] of each p-ellipse.

    Args:
        cov: (N, 3) covariances (xx, xy, yy) [m^2, ENU].
        p: probability mass inside the ellipse (0 < p < 1).

    Returns:
        (major, minor, theta), each (N,): semi-axes [m] (major >= minor > 0) and the major
        axis's angle from east towards north [rad], in (-pi/2, pi/2] (0 for a circle); NaN
        where P is not finite and positive definite.
    """
    c = np.asarray(cov, dtype=float).reshape(-1, 3)
    xx, xy, yy = c[:, 0], c[:, 1], c[:, 2]
    r = float(np.sqrt(ellipse_r2(p)))
    with np.errstate(invalid="ignore", over="ignore"):
        ok = np.isfinite(c).all(axis=1) & (xx > 0) & (xx * yy - xy * xy > 0)
        half_trace = 0.5 * (xx + yy)
        d = np.hypot(0.5 * (xx - yy), xy)
        l1 = half_trace + d
        l2 = (xx * yy - xy * xy) / np.where(ok, l1, 1.0)  # det / l1: no cancellation
        major = np.where(ok, r * np.sqrt(np.where(ok, l1, 0.0)), np.nan)
        minor = np.where(ok, r * np.sqrt(np.where(ok, l2, 0.0)), np.nan)
        theta = np.where(ok, 0.5 * np.arctan2(2.0 * xy, xx - yy), np.nan)
    return major, minor, theta


def ellipse_outlines(
    cov: np.ndarray, p: float = 0.95, segments: int = ELLIPSE_SEGMENTS
) -> np.ndarray:
    """Closed outlines of the p-ellipses, relative to their centres.

    Args:
        cov: (N, 3) covariances (xx, xy, yy) [m^2, ENU].
        p: probability mass inside (0.95: the 95 % ellipse, radius sqrt(5.991)).
        segments: line segments per outline (>= 3).

    Returns:
        (N, segments + 1, 2) offsets [m, ENU] from the ellipse's centre; the last point
        repeats the first (a closed line strip). All NaN for a row whose P is not finite
        and positive definite. Add the centre (the answer) to place them.
    """
    if segments < 3:
        raise ValueError(f"segments must be >= 3, got {segments}")
    major, minor, theta = ellipse_axes(cov, p)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    phi[-1] = 0.0  # exactly closed
    u = major[:, None] * np.cos(phi)[None, :]  # along the major axis
    v = minor[:, None] * np.sin(phi)[None, :]
    ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
    return np.stack([ct * u - st * v, st * u + ct * v], axis=-1)
