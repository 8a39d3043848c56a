"""The 2-D constant-acceleration Kalman filter of :mod:`reference_filters.linear_kalman` in plain
floats.

Same maths as ``filterpy.kalman.KalmanFilter`` with ``F``, ``Q`` of the CA model and the
kf's measurements, written for the fixed size: at IMU rate numpy's per-call overhead
(~1 us per 6x6 product, ``inv`` of a 2x2, filterpy's copies of priors and posteriors)
is most of the cost, while the arithmetic is ~200 flops. Exact, not approximate: the
tests reproduce filterpy's mean and covariance to rounding
(tests/predictors/test_filter_fastpath.py).

Layout. The state ``[x, y, vx, vy, ax, ay]`` is kept per axis: ``mx = [x, vx, ax]``,
``my = [y, vy, ay]`` (m, m/s, m/s^2, ENU). ``F = f (x) I2`` with the per-axis
``f = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]`` and ``Q = q (x) I2``, so the covariance
is three 3x3 blocks, each propagated as ``f M f'``: ``A = cov(mx, mx)``, ``B = cov(my, my)``
(symmetric, stored as their six upper entries ``(00, 01, 02, 11, 12, 22)``) and the cross
block ``C = cov(mx, my)`` (row-major, nine entries; non-zero once a wheel-speed update
along a heading has coupled the axes).

Every measurement is scalar (``z = h . state``, variance ``r``): the kf's 2-D ones (fix,
IMU acceleration, zero-velocity update) have ``H`` selecting one component per axis and
``R = r I2``, which equals two sequential scalar updates. A scalar update with
``ph = P h`` and ``s = h' P h + r`` is ``x += ph (z - h'x) / s``, ``P -= ph ph' / s``
(filterpy's Joseph form gives the same matrix up to rounding, since the gain is optimal).
"""

from __future__ import annotations

import numpy as np

from posbench.metrics.ca_model import ca_noise_entries as ca_noise_block
from posbench.metrics.ca_model import ca_predict_block as predict_sym
from posbench.metrics.ca_model import ca_predict_cross as predict_cross
from posbench.predictors.kalman.copying import copy_attrs

#: entries of a symmetric 3x3 block in storage order, by (row, column)
_SYM = ((0, 1, 2), (1, 3, 4), (2, 4, 5))


class CaFilter2D:
    """Mean and covariance of the 2-D constant-acceleration filter (see the module).

    Attributes ``mx``, ``my`` (per-axis means, lists of three floats) and ``A``, ``B``,
    ``C`` (covariance blocks) are the whole state; ``state()`` / ``covariance()`` give
    them in the kf's order ``[x, y, vx, vy, ax, ay]``.
    """

    def __init__(self) -> None:
        self.init(0.0, 0.0, 1.0, 1.0, 1.0)

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = ("mx", "my", "A", "B", "C")

    def __deepcopy__(self, memo: dict) -> CaFilter2D:
        """A copy with its own means (the covariance blocks are immutable tuples)."""
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new.mx, new.my = list(self.mx), list(self.my)
        return new

    def init(self, x: float, y: float, var_p: float, var_v: float, var_a: float) -> None:
        """At rest at (x, y) [m] with diagonal covariance (per axis: var_p [m^2],
        var_v [m^2/s^2], var_a [m^2/s^4])."""
        self.mx = [x, 0.0, 0.0]
        self.my = [y, 0.0, 0.0]
        self.A = self.B = (var_p, 0.0, 0.0, var_v, 0.0, var_a)
        self.C = (0.0,) * 9

    def predict(self, d: float, psd: float) -> None:
        """Advance by d [s] > 0 under white jerk of spectral density psd [m^2/s^5]."""
        h = 0.5 * d * d
        p, v, a = self.mx
        self.mx = [p + d * v + h * a, v + d * a, a]
        p, v, a = self.my
        self.my = [p + d * v + h * a, v + d * a, a]
        q = ca_noise_block(d, psd)
        self.A = predict_sym(self.A, d, h, q)
        self.B = predict_sym(self.B, d, h, q)
        self.C = predict_cross(self.C, d, h)

    def _update(self, px: tuple, py: tuple, s: float, innov: float) -> None:
        """Scalar update given ph = P h split per axis (px, py), s = h'Ph + r, z - h'x."""
        w = 1.0 / s
        g = innov * w
        mx, my = self.mx, self.my
        mx[0] += px[0] * g
        mx[1] += px[1] * g
        mx[2] += px[2] * g
        my[0] += py[0] * g
        my[1] += py[1] * g
        my[2] += py[2] * g
        x0, x1, x2 = px
        y0, y1, y2 = py
        u0, u1, u2 = x0 * w, x1 * w, x2 * w
        v0, v1, v2 = y0 * w, y1 * w, y2 * w
        a00, a01, a02, a11, a12, a22 = self.A
        self.A = (
            a00 - u0 * x0,
            a01 - u0 * x1,
            a02 - u0 * x2,
            a11 - u1 * x1,
            a12 - u1 * x2,
            a22 - u2 * x2,
        )
        b00, b01, b02, b11, b12, b22 = self.B
        self.B = (
            b00 - v0 * y0,
            b01 - v0 * y1,
            b02 - v0 * y2,
            b11 - v1 * y1,
            b12 - v1 * y2,
            b22 - v2 * y2,
        )
        c00, c01, c02, c10, c11, c12, c20, c21, c22 = self.C
        self.C = (
            c00 - u0 * y0,
            c01 - u0 * y1,
            c02 - u0 * y2,
            c10 - u1 * y0,
            c11 - u1 * y1,
            c12 - u1 * y2,
            c20 - u2 * y0,
            c21 - u2 * y1,
            c22 - u2 * y2,
        )

    def update_pair(self, k: int, zx: float, zy: float, r: float) -> None:
        """Measurement of component k (0 position, 1 velocity, 2 acceleration) on both
        axes, (zx, zy), noise r I2: two scalar updates, x then y."""
        A, C = self.A, self.C
        i = _SYM[k]
        px = (A[i[0]], A[i[1]], A[i[2]])
        py = (C[3 * k], C[3 * k + 1], C[3 * k + 2])  # cov(x_k, y_j)
        self._update(px, py, px[k] + r, zx - self.mx[k])
        B, C = self.B, self.C
        i = _SYM[k]
        px = (C[k], C[3 + k], C[6 + k])  # cov(x_j, y_k)
        py = (B[i[0]], B[i[1]], B[i[2]])
        self._update(px, py, py[k] + r, zy - self.my[k])

    def update_speed(self, c: float, s: float, z: float, r: float) -> None:
        """Speed z [m/s] along the unit direction (c, s) in ENU: h'x = c vx + s vy, noise r."""
        A, B, C = self.A, self.B, self.C
        px = (c * A[1] + s * C[1], c * A[3] + s * C[4], c * A[4] + s * C[7])
        py = (c * C[3] + s * B[1], c * C[4] + s * B[3], c * C[5] + s * B[4])
        self._update(px, py, c * px[1] + s * py[1] + r, z - c * self.mx[1] - s * self.my[1])

    # -- views ---------------------------------------------------------------------------
    def state(self) -> list[float]:
        """The mean ``[x, y, vx, vy, ax, ay]`` (m, m/s, m/s^2)."""
        mx, my = self.mx, self.my
        return [mx[0], my[0], mx[1], my[1], mx[2], my[2]]

    def covariance(self) -> np.ndarray:
        """The 6x6 covariance in the order ``[x, y, vx, vy, ax, ay]`` (a new array)."""
        P = np.empty((6, 6))
        for i in range(3):
            for j in range(3):
                P[2 * i, 2 * j] = self.A[_SYM[i][j]]
                P[2 * i + 1, 2 * j + 1] = self.B[_SYM[i][j]]
                P[2 * i, 2 * j + 1] = P[2 * j + 1, 2 * i] = self.C[3 * i + j]
        return P

    def velocity(self) -> tuple[float, float]:
        """(vx, vy) of the mean [m/s]."""
        return self.mx[1], self.my[1]

    def position_block(self) -> tuple[float, float, float]:
        """(var x, cov xy, var y) of the position [m^2]."""
        return self.A[0], self.C[0], self.B[0]

    def acceleration_variances(self) -> tuple[float, float]:
        """(var ax, var ay) [m^2/s^4]."""
        return self.A[5], self.B[5]
