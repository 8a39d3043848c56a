"""The fused ``lstm`` step's arithmetic as compiled calls (numba): the two cubic fits, the
network's input and the current-position cubic, each one call instead of ~10 numpy calls
of ~1-3 us each (:mod:`posbench.predictors.lstm.fused` holds the buffers and the order).

Frames and units as in :mod:`posbench.predictors.lstm.fused`: positions [m] in the drive's
local ENU frame, IMU acceleration [m/s^2] in the vehicle frame, yaw [rad], times [s]
relative to the newest fix. Coefficient rows are in the order (s^2, s^3, 1, s) that
:func:`posbench.predictors.lstm.fused._eval_rows` evaluates.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel

#: the natural-order coefficient (1, s, s^2, s^3) stored in each row of a block's solution
_ORDER = (2, 3, 0, 1)


@kernel
def _fit_block(rows: np.ndarray, t_end: float, n_vals: int, x: np.ndarray) -> None:
    """Least-squares cubic of each value column of ``rows`` (n >= 4, 1 + n_vals): t [s],
    values, in s = t - t_end; the (4, 3) coefficients in rows (s^2, s^3, 1, s) into ``x``
    (value columns past ``n_vals`` are 0). Normal equations from power sums, solved by
    Gaussian elimination with partial pivoting."""
    sums = np.zeros(7)
    m = np.zeros((4, 7))  # [normal matrix | right-hand sides]
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = 0.0
    for i in range(rows.shape[0]):
        s = rows[i, 0] - t_end
        q2 = s * s
        q3 = q2 * s
        s0 += 1.0
        s1 += s
        s2 += q2
        s3 += q3
        s4 += q2 * q2
        s5 += q2 * q3
        s6 += q3 * q3
        for v in range(n_vals):
            y = rows[i, 1 + v]
            m[0, 4 + v] += y
            m[1, 4 + v] += s * y
            m[2, 4 + v] += q2 * y
            m[3, 4 + v] += q3 * y
    sums[0], sums[1], sums[2], sums[3] = s0, s1, s2, s3
    sums[4], sums[5], sums[6] = s4, s5, s6
    for r in range(4):
        for c in range(4):
            m[r, c] = sums[r + c]
    for col in range(4):
        piv = col
        for r in range(col + 1, 4):
            if abs(m[r, col]) > abs(m[piv, col]):
                piv = r
        if piv != col:
            for c in range(7):
                m[col, c], m[piv, c] = m[piv, c], m[col, c]
        for r in range(col + 1, 4):
            f = m[r, col] / m[col, col]
            for c in range(col, 7):
                m[r, c] -= f * m[col, c]
    for v in range(3):
        if v >= n_vals:
            for r in range(4):
                x[_ORDER[r], v] = 0.0
            continue
        for r in range(3, -1, -1):
            acc = m[r, 4 + v]
            for c in range(r + 1, 4):
                acc -= m[r, c] * x[_ORDER[c], v]
            x[_ORDER[r], v] = acc / m[r, r]


@kernel
def fit_cubics(
    fix: np.ndarray,
    imu: np.ndarray,
    t_end: float,
    yaw_ok: bool,
    rows_eval: np.ndarray,
    x: np.ndarray,
    e: np.ndarray,
) -> None:
    """Both cubics of the window and their values: ``fix`` (n >= 4, 3) rows t, x, y;
    ``imu`` (m, 4) rows t, ax, ay, yaw (m = 0: none; else m >= 4; yaw fitted as 0 unless
    ``yaw_ok``). Coefficients into ``x[0]``, ``x[1]`` (4, 3); ``e[k] = rows_eval @ x[k]``
    (``e[1]`` untouched without IMU)."""
    _fit_block(fix, t_end, 2, x[0])
    blocks = 1
    if imu.shape[0] > 0:
        _fit_block(imu, t_end, 3 if yaw_ok else 2, x[1])
        blocks = 2
    for k in range(blocks):
        for r in range(rows_eval.shape[0]):
            for v in range(3):
                acc = 0.0
                for c in range(4):
                    acc += rows_eval[r, c] * x[k, c, v]
                e[k, r, v] = acc


@kernel
def window_features(
    e: np.ndarray,
    psi: float,
    fix_x: float,
    fix_y: float,
    heading: bool,
    fix_offset: bool,
    scales: np.ndarray,
    x64: np.ndarray,
    z: np.ndarray,
) -> float:
    """The network's window (8, 6) into ``x64`` (float64; column 5, the time, is left as
    set) and ``z`` (float32) from the grid values ``e`` (:func:`fit_cubics`), the heading
    ``psi`` [rad] and the newest fix (``fix_x``, ``fix_y``) [m]; :meth:`FusedStep.features`
    documents the maths. ``scales``: empty for a full graph's input, or the core's
    (``speed_eps_m``, ``res_std`` x, y): then rows 1-7 of the displacements are divided
    by the window's speed scale s [m] (returned; 1.0 without a core), row 0 by
    ``res_std``, and ``log s`` is written to ``z[:, 6]``."""
    core = scales.shape[0] > 0
    s = 1.0
    if core:
        acc = 0.0
        for r in range(9, 16):
            acc += math.hypot(e[0, r, 0], e[0, r, 1])
        s = acc / 7.0 + scales[0]
    k = 1.0 / s if core else 1.0
    ox = fix_x - e[0, 7, 0]
    oy = fix_y - e[0, 7, 1]
    if heading:
        c = math.cos(psi)
        sn = -math.sin(psi)
        rc, rs = c * k, sn * k
        for r in range(1, 8):
            dx, dy = e[0, 8 + r, 0], e[0, 8 + r, 1]
            x64[r, 0] = dx * rc - dy * rs
            x64[r, 1] = dx * rs + dy * rc
        ox, oy = ox * c - oy * sn, ox * sn + oy * c
        for j in range(8):
            x64[j, 4] = e[1, 16 + j, 2]
    else:
        for r in range(1, 8):
            x64[r, 0] = e[0, 8 + r, 0] * k
            x64[r, 1] = e[0, 8 + r, 1] * k
        for j in range(8):
            x64[j, 4] = math.pi - (math.pi - e[1, j, 2]) % (2.0 * math.pi)
    if fix_offset:
        x64[0, 0] = ox / scales[1] if core else ox
        x64[0, 1] = oy / scales[2] if core else oy
    for j in range(8):
        rel = e[1, 16 + j, 2] if heading else e[1, j, 2]
        c = math.cos(rel)
        sn = math.sin(rel)
        ax, ay = e[1, j, 0], e[1, j, 1]
        x64[j, 2] = ax * c - ay * sn
        x64[j, 3] = ax * sn + ay * c
    for j in range(8):
        for v in range(6):
            z[j, v] = x64[j, v]
    if core:
        ls = math.log(s)
        for j in range(8):
            z[j, 6] = ls
    return s


@kernel
def finish_step(
    e: np.ndarray,
    d0: float,
    d1: float,
    psi: float,
    heading: bool,
    pinv_t: np.ndarray,
    cf: np.ndarray,
) -> bool:
    """The prediction (row 8 of ``e[0]``) from the network's displacement (d0, d1) [m,
    model frame] and the current-position cubic ``cf`` (2, 4) through the 8 grid points
    and it (``pinv_t`` (9, 4)); False (nothing written) if the prediction is not finite."""
    if heading:
        c = math.cos(psi)
        s = math.sin(psi)
        d0, d1 = c * d0 - s * d1, s * d0 + c * d1
    px = e[0, 7, 0] + d0
    py = e[0, 7, 1] + d1
    if not (math.isfinite(px) and math.isfinite(py)):
        return False
    e[0, 8, 0] = px
    e[0, 8, 1] = py
    for v in range(2):
        for j in range(4):
            acc = 0.0
            for i in range(9):
                acc += e[0, i, v] * pinv_t[i, j]
            cf[v, j] = acc
    return True
