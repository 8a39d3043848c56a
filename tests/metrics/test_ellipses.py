"""The geometry of the drawn 95 % ellipses (metrics/ellipses.py): axes, orientation, and
outlines that lie on the chi-square boundary of their covariance."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from posbench.metrics.calibration import mahalanobis_sq
from posbench.metrics.ellipses import ELLIPSE_SEGMENTS, ellipse_axes, ellipse_outlines

R95 = math.sqrt(chi2.ppf(0.95, 2))  # 2.4477 = sqrt(5.991)


def _rotated(sig_major: float, sig_minor: float, theta: float) -> np.ndarray:
    """(xx, xy, yy) of R diag(a^2, b^2) R' (R: rotation by theta from east towards north)."""
    c, s = math.cos(theta), math.sin(theta)
    rot = np.array([[c, -s], [s, c]])
    p = rot @ np.diag([sig_major**2, sig_minor**2]) @ rot.T
    return np.array([p[0, 0], p[0, 1], p[1, 1]])


def test_axis_aligned_and_rotated_axes():
    cov = np.array(
        [
            [4.0, 0.0, 1.0],  # 2 m east, 1 m north
            [1.0, 0.0, 4.0],  # major axis north
            _rotated(3.0, 0.5, math.radians(30)),
            _rotated(3.0, 0.5, math.radians(-60)),
            [0.25, 0.0, 0.25],
        ]
    )  # a circle of sigma 0.5 m
    major, minor, theta = ellipse_axes(cov)
    np.testing.assert_allclose(major, R95 * np.array([2.0, 2.0, 3.0, 3.0, 0.5]), rtol=1e-12)
    np.testing.assert_allclose(minor, R95 * np.array([1.0, 1.0, 0.5, 0.5, 0.5]), rtol=1e-12)
    np.testing.assert_allclose(
        theta, [0.0, math.pi / 2, math.radians(30), math.radians(-60), 0.0], atol=1e-12
    )
    assert R95**2 == pytest.approx(5.991, abs=5e-4)
    # another probability: the 50 % ellipse, r^2 = -2 ln 0.5
    major50, _, _ = ellipse_axes(cov[:1], p=0.5)
    assert major50[0] == pytest.approx(2.0 * math.sqrt(chi2.ppf(0.5, 2)), rel=1e-12)


def test_outlines_lie_on_the_95_percent_boundary():
    rng = np.random.default_rng(1)
    n = 200
    a, b = rng.uniform(0.01, 5.0, n), rng.uniform(0.01, 5.0, n)
    th = rng.uniform(-math.pi, math.pi, n)
    cov = np.array([_rotated(x, y, t) for x, y, t in zip(a, b, th, strict=True)])
    pts = ellipse_outlines(cov)
    assert pts.shape == (n, ELLIPSE_SEGMENTS + 1, 2)
    np.testing.assert_array_equal(pts[:, 0], pts[:, -1])  # closed
    d2 = mahalanobis_sq(pts.reshape(-1, 2), np.repeat(cov, ELLIPSE_SEGMENTS + 1, axis=0))
    np.testing.assert_allclose(d2, chi2.ppf(0.95, 2), rtol=1e-9)
    # the farthest outline point is the end of the major axis, along theta (or opposite)
    major, minor, theta = ellipse_axes(cov)
    far = np.linalg.norm(pts, axis=-1).max(axis=1)
    np.testing.assert_allclose(far, R95 * np.maximum(a, b), rtol=1e-12)
    tip = pts[:, 0]  # phi = 0: the major axis end
    np.testing.assert_allclose(np.linalg.norm(tip, axis=1), major, rtol=1e-12)
    cross = tip[:, 0] * np.sin(theta) - tip[:, 1] * np.cos(theta)
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    # the polygon's area tends to the ellipse's, pi r^2 sqrt(det P) (the sharpness formula)
    x, y = pts[..., 0], pts[..., 1]
    area = 0.5 * np.abs((x[:, :-1] * y[:, 1:] - x[:, 1:] * y[:, :-1]).sum(axis=1))
    want = math.pi * R95**2 * np.sqrt(cov[:, 0] * cov[:, 2] - cov[:, 1] ** 2)
    poly = ELLIPSE_SEGMENTS / (2 * math.pi) * math.sin(2 * math.pi / ELLIPSE_SEGMENTS)
    np.testing.assert_allclose(area, want * poly, rtol=1e-9)


def test_invalid_covariances_give_no_ellipse():
    cov = np.array(
        [
            [np.nan, np.nan, np.nan],  # no covariance reported
            [1.0, 2.0, 1.0],  # not positive definite
            [-1.0, 0.0, -1.0],
            [1.0, 0.0, np.inf],
            [1.0, 0.0, 1.0],
        ]
    )
    major, minor, theta = ellipse_axes(cov)
    assert np.isnan(major[:4]).all() and np.isnan(minor[:4]).all() and np.isnan(theta[:4]).all()
    pts = ellipse_outlines(cov, segments=8)
    assert pts.shape == (5, 9, 2)
    assert np.isnan(pts[:4]).all() and np.isfinite(pts[4]).all()
    assert ellipse_outlines(np.empty((0, 3))).shape == (0, ELLIPSE_SEGMENTS + 1, 2)
    with pytest.raises(ValueError, match="segments"):
        ellipse_outlines(cov, segments=2)
