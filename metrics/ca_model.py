"""The constant-acceleration (CA) motion model, written once: its transition and its
white-jerk process noise, per axis.

Per axis the state is ``[p, v, a]`` (m, m/s, m/s^2); over dt [s]
``f = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]`` and white jerk of spectral density
``psd`` [m^2/s^5] adds ``Q = psd [[dt^5/20, dt^4/8, dt^3/6], [dt^4/8, dt^3/3, dt^2/2],
[dt^3/6, dt^2/2, dt]]`` (the standard discretised Wiener-jerk Q). A 2-D CA filter is
this per axis (``F = f (x) I2``, ``Q = q (x) I2``).

Scalar arithmetic only, so one function serves every user: Python floats (the bound row
here, the kf's ``covariance_at``), numpy arrays elementwise (:func:`ca_noise_matrix`,
the gradient tuning) and compiled kernels, which compile these same functions
(:mod:`posbench.predictors.kalman.ca_rows`). Symmetric 3x3 blocks are their six upper
entries ``(00, 01, 02, 11, 12, 22)``; a general block its nine entries, row-major.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def ca_noise_entries(d: Any, psd: Any) -> tuple[Any, ...]:
    """The six upper entries of the per-axis white-jerk Q over ``d`` [s] at density
    ``psd`` [m^2/s^5] (floats, or arrays elementwise)."""
    d2 = d * d
    d3 = d2 * d
    return (
        psd * (d3 * d2 / 20.0),
        psd * (d2 * d2 / 8.0),
        psd * (d3 / 6.0),
        psd * (d3 / 3.0),
        psd * (d2 / 2.0),
        psd * d,
    )


def ca_predict_block(m: tuple[Any, ...], d: float, h: float, q: tuple[Any, ...]) -> tuple[Any, ...]:
    """``f M f' + Q`` of a symmetric block M (six upper entries) over dt = ``d`` [s]
    (``h`` = d^2/2), Q's block ``q`` (six upper entries, :func:`ca_noise_entries`)."""
    m00, m01, m02, m11, m12, m22 = m
    g00 = m00 + d * m01 + h * m02
    g01 = m01 + d * m11 + h * m12
    g02 = m02 + d * m12 + h * m22
    g11 = m11 + d * m12
    g12 = m12 + d * m22
    return (
        g00 + d * g01 + h * g02 + q[0],
        g01 + d * g02 + q[1],
        g02 + q[2],
        g11 + d * g12 + q[3],
        g12 + q[4],
        m22 + q[5],
    )


def ca_predict_cross(c: tuple[Any, ...], d: float, h: float) -> tuple[Any, ...]:
    """``f C f'`` of a general block C (nine entries, row-major: the covariance between
    the two axes, which takes no process noise) over dt = ``d`` [s], ``h`` = d^2/2."""
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = c
    g00 = c00 + d * c10 + h * c20
    g01 = c01 + d * c11 + h * c21
    g02 = c02 + d * c12 + h * c22
    g10 = c10 + d * c20
    g11 = c11 + d * c21
    g12 = c12 + d * c22
    return (
        g00 + d * g01 + h * g02,
        g01 + d * g02,
        g02,
        g10 + d * g11 + h * g12,
        g11 + d * g12,
        g12,
        c20 + d * c21 + h * c22,
        c21 + d * c22,
        c22,
    )


#: the six upper entries' places in a 3x3 block, and their mirrors
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def ca_transition_matrix(dt: np.ndarray | float) -> np.ndarray:
    """``f(dt)`` (..., 3, 3) per axis, for dt [s] of any shape."""
    d = np.asarray(dt, dtype=float)
    f = np.zeros((*d.shape, 3, 3))
    f[..., 0, 0] = f[..., 1, 1] = f[..., 2, 2] = 1.0
    f[..., 0, 1] = f[..., 1, 2] = d
    f[..., 0, 2] = 0.5 * d * d
    return f


def ca_noise_matrix(dt: np.ndarray | float, psd: float) -> np.ndarray:
    """``Q(dt)`` (..., 3, 3) per axis [m^2, m^2/s, ...] of white jerk of density ``psd``
    [m^2/s^5], for dt [s] of any shape (:func:`ca_noise_entries` as a matrix)."""
    d = np.asarray(dt, dtype=float)
    out = np.empty((*d.shape, 3, 3))
    for (i, j), v in zip(_UPPER, ca_noise_entries(d, psd), strict=True):
        out[..., i, j] = out[..., j, i] = v
    return out
