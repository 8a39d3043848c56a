"""The ``kf`` bank's IMU sample as one compiled call (numba; :mod:`posbench.predictors._kernels`).

At 50-100 Hz the IMU is most of a kf's work, and most of that was the calls between its
parts, each from Python: the course trackers' gyro inputs and headings, the rows' predict
and acceleration update (:func:`~posbench.predictors.kalman.ca_rows.imu_rows`), the bias
estimators' IMU side. :func:`imu_sample` makes the same calls, in the same order and on the
same state arrays, inside one compiled call: the answers are the same to the bit.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel
from posbench.predictors.kalman.accel_bias import BX, BY
from posbench.predictors.kalman.accel_bias import observe_imu as bias_imu
from posbench.predictors.kalman.ca_rows import imu_rows
from posbench.predictors.kalman.course_heading import heading_at, observe_rate


@kernel
def course_heading(
    st: np.ndarray, t: float, rate_psd: float, hold_psd: float, sigma_max: float
) -> float:
    """A course tracker's heading [rad] at t (its state array ``st`` and options), NaN while
    its standard deviation [rad] is not below ``sigma_max``: the rule of the IMU sample here
    and of the bank's wheel-speed update (``KalmanBank._course_heading``)."""
    h, h_sd = heading_at(st, t, rate_psd, hold_psd)
    return h if h_sd < sigma_max else math.nan


@kernel
def imu_sample(
    S: np.ndarray,
    RP: np.ndarray,
    CF: np.ndarray,
    n: int,
    shadows: bool,
    t: float,
    ax: float,
    ay: float,
    yaw: float,
    yaw_rate: float,
    course: bool,
    courses: tuple,
    rate_psd: float,
    hold_psd: float,
    sigma_max: float,
    bias: bool,
    biases: tuple,
) -> None:
    """One IMU sample (vehicle-frame ax, ay [m/s^2], yaw [rad], yaw rate [rad/s]) at t [s]
    for a ready bank of ``n`` members (and as many shadows where ``shadows``): the course
    trackers' gyro input (``courses``: the members' and the shadows' state arrays, where
    ``course``; ``rate_psd``, ``hold_psd`` their options), their headings where the IMU
    states no yaw, the rows' predict and update, and the bias estimators' IMU side
    (``biases``: their state arrays, where ``bias``) with the heading the rows used."""
    if course:
        observe_rate(courses[0], t, yaw_rate, rate_psd, hold_psd)
        if shadows:
            observe_rate(courses[1], t, yaw_rate, rate_psd, hold_psd)
    hm = hs = math.nan
    if course and not math.isfinite(yaw):
        hm = course_heading(courses[0], t, rate_psd, hold_psd, sigma_max)
        if shadows:
            hs = course_heading(courses[1], t, rate_psd, hold_psd, sigma_max)
    bm, bs = biases
    bxm = bym = bxs = bys = 0.0
    if bias:
        bxm, bym = bm[BX], bm[BY]
        if shadows:
            bxs, bys = bs[BX], bs[BY]
    hi = 2 * n if shadows else n
    h_m, h_s = imu_rows(
        S, RP, CF, hi, n, t, ax, ay, yaw, yaw_rate, (hm, hs), ((bxm, bym), (bxs, bys))
    )
    if bias:
        bias_imu(bm, t, ax, ay, h_m)
        if shadows:
            bias_imu(bs, t, ax, ay, h_s)
