"""Least-squares cubics x(t), y(t) through a short window of fixes, for ``poly``'s fix step.

The same fit as :func:`posbench.predictors.cubic.fit_cubic` (linear least squares, degree 3) solved
through its 4x4 normal equations with an unrolled LDL' factorisation in plain floats:
``np.linalg.lstsq`` (an SVD, ~15 us of call overhead) is most of the cost of a fix step,
while the arithmetic is ~100 flops. Conditioning: time is centred and scaled to
s in [-1, 1] (s = (t - t_mid) / half_span) and values are taken relative to the newest fix,
so the normal equations lose ~3 digits, not the 8 they would on raw ENU metres and seconds:
the fitted curve equals lstsq's to ~1e-11 m over a 2 s window, up to ~1e-10 m extrapolated
2 s past it (tests/predictors/test_filter_fastpath.py). Rank-deficient windows (fewer than four
distinct times) return None: the caller falls back to lstsq's minimum-norm solution.
"""

from __future__ import annotations

import numpy as np

#: a pivot of the normal equations below this fraction of its diagonal entry marks a
#: (numerically) rank-deficient window
PIVOT_RTOL = 1e-10

Cubic = tuple[float, float, float, float]


def fit_cubic_xy(t: np.ndarray, xy: np.ndarray) -> tuple[Cubic, Cubic, float, float] | None:
    """Cubics through the fixes at times ``t`` [s] (n,), n >= 4, ascending, with positions
    ``xy`` [m] given as rows (2, n): x then y (e.g. :meth:`FixBuffer.xy_rows_from`).

    Returns ``(cx, cy, t_ref, inv_scale)``: x(t) = cx[0] + cx[1] s + cx[2] s^2 + cx[3] s^3
    with s = (t - t_ref) * inv_scale (likewise y), or None when the window is rank deficient.
    """
    n = t.shape[0]
    t0, t1 = float(t[0]), float(t[-1])
    t_ref = 0.5 * (t0 + t1)
    half = 0.5 * (t1 - t0)
    if not half > 0.0:
        return None
    inv = 1.0 / half
    # rows 0-3: 1, s, s^2, s^3; rows 4-5: x, y relative to the newest fix. One product
    # gives the normal matrix G = V V' (rows 0-3) and the right-hand sides V r (rows 4-5).
    M = np.empty((6, n))
    M[0] = 1.0
    s = M[1]
    np.multiply(t - t_ref, inv, out=s)
    np.multiply(s, s, out=M[2])
    np.multiply(M[2], s, out=M[3])
    np.subtract(xy, xy[:, -1:], out=M[4:])
    x0, y0 = float(xy[0, -1]), float(xy[1, -1])
    (
        (g00, g01, g02, g03),
        (_, g11, g12, g13),
        (_, _, g22, g23),
        (_, _, _, g33),
        (bx0, bx1, bx2, bx3),
        (by0, by1, by2, by3),
    ) = (M @ M[:4].T).tolist()
    # G = L D L' (L unit lower triangular); e_ij = l_ij d_j
    d0 = g00
    l10, l20, l30 = g01 / d0, g02 / d0, g03 / d0
    d1 = g11 - l10 * g01
    if not d1 > PIVOT_RTOL * g11:
        return None
    e21 = g12 - l20 * g01
    e31 = g13 - l30 * g01
    l21, l31 = e21 / d1, e31 / d1
    d2 = g22 - l20 * g02 - l21 * e21
    if not d2 > PIVOT_RTOL * g22:
        return None
    e32 = g23 - l30 * g02 - l31 * e21
    l32 = e32 / d2
    d3 = g33 - l30 * g03 - l31 * e31 - l32 * e32
    if not d3 > PIVOT_RTOL * g33:
        return None

    def solve(b0: float, b1: float, b2: float, b3: float) -> Cubic:
        y1 = b1 - l10 * b0
        y2 = b2 - l20 * b0 - l21 * y1
        y3 = b3 - l30 * b0 - l31 * y1 - l32 * y2
        c3 = y3 / d3
        c2 = y2 / d2 - l32 * c3
        c1 = y1 / d1 - l21 * c2 - l31 * c3
        c0 = b0 / d0 - l10 * c1 - l20 * c2 - l30 * c3
        return c0, c1, c2, c3

    cx = solve(bx0, bx1, bx2, bx3)
    cy = solve(by0, by1, by2, by3)
    return (cx[0] + x0, cx[1], cx[2], cx[3]), (cy[0] + y0, cy[1], cy[2], cy[3]), t_ref, inv
