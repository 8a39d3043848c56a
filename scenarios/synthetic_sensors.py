"""The synthetic drives' sensors, simulated from a 100 Hz truth: IMU, CAN speed and GPS
fixes with their dropouts.

- IMU: ax = dv/dt, ay = v * yaw_rate (vehicle frame, x forward, y left) with white noise
  and a constant bias, yaw (ENU, wrapped) and yaw rate with white noise
  (:func:`imu_stream`);
- CAN speed at 50 Hz, 10 ms after the IMU's samples, never negative, exactly 0 at
  standstill (:func:`can_speed_stream`);
- GPS fixes at the paper's irregular intervals, white plus Gauss-Markov noise, lat/lon by
  the inverse ENU projection about :data:`ORIGIN_LAT`, :data:`ORIGIN_LON`, and about one
  1-2 s dropout per 40 s (:func:`gps_stream`).

Times in seconds, positions ENU metres, accelerations m/s^2, angles in radians.
"""

from __future__ import annotations

import numpy as np

from posbench.scenarios.degrade import draw_intervals, enu_to_latlon, gps_noise
from posbench.scenarios.drive import GpsStream, ImuStream, SpeedStream
from posbench.scenarios.dropouts import drop_windows, outage_windows

#: the synthetic drives' ENU origin [deg]
ORIGIN_LAT = 45.8
ORIGIN_LON = 16.0
#: the fixes' white noise [m] per axis, their Gauss-Markov error [m] and its time constant [s]
GPS_WHITE_SD = 0.03
GPS_GM_SD = 0.05
GPS_GM_TAU_S = 30.0


def _hermite(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, tq: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of the truth (positions and velocities) at times tq."""
    k = np.clip(np.searchsorted(t, tq, side="right") - 1, 0, t.size - 2)
    h = t[k + 1] - t[k]
    u = (tq - t[k]) / h
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2

    def f(p: np.ndarray, dp: np.ndarray) -> np.ndarray:
        return h00 * p[k] + h10 * h * dp[k] + h01 * p[k + 1] + h11 * h * dp[k + 1]

    return f(x, vx), f(y, vy)


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles [rad] wrapped to [-pi, pi)."""
    return (a + np.pi) % (2 * np.pi) - np.pi


def imu_stream(
    t: np.ndarray,
    yaw: np.ndarray,
    v: np.ndarray,
    yaw_rate: np.ndarray,
    ax: np.ndarray,
    rng: np.random.Generator,
    step: int = 2,
    accel_sd: float = 0.05,
    bias_sd: float = 0.05,
    yaw_sd: float = 0.005,
    yaw_rate_sd: float = 0.005,
    gyro_bias_sd: float = 0.0,
) -> ImuStream:
    """IMU samples from the 100 Hz truth: every ``step``-th sample (2 = 50 Hz, 1 = 100 Hz).

    ax = dv/dt, ay = v * yaw_rate [m/s^2, vehicle frame x forward, y left] with white noise
    ``accel_sd`` and a constant bias per axis drawn with sigma ``bias_sd``; yaw [rad, ENU,
    wrapped] with white noise ``yaw_sd``; yaw_rate [rad/s] with white noise ``yaw_rate_sd``
    and (if ``gyro_bias_sd`` > 0) a constant bias drawn with that sigma.
    """
    ii = np.arange(0, t.size, step)
    m = ii.size
    bias = rng.normal(0.0, bias_sd, 2)
    fax = ax[ii] + bias[0] + rng.normal(0.0, accel_sd, m)
    fay = v[ii] * yaw_rate[ii] + bias[1] + rng.normal(0.0, accel_sd, m)
    fyaw = wrap_angle(yaw[ii] + rng.normal(0.0, yaw_sd, m))
    fyr = yaw_rate[ii] + rng.normal(0.0, yaw_rate_sd, m)
    if gyro_bias_sd > 0.0:
        fyr = fyr + rng.normal(0.0, gyro_bias_sd)
    return ImuStream(t[ii], fax, fay, fyaw, fyr)


def can_speed_stream(t: np.ndarray, v: np.ndarray, rng: np.random.Generator) -> SpeedStream:
    """CAN speed at 50 Hz from the 100 Hz truth (the odd samples, 10 ms after the IMU's):
    white noise 0.02 m/s, never negative, exactly 0 at standstill."""
    jj = np.arange(1, t.size, 2)
    vc = np.maximum(v[jj] + rng.normal(0.0, 0.02, jj.size), 0.0)
    vc[v[jj] == 0.0] = 0.0
    return SpeedStream(t[jj], vc)


def gps_stream(
    t: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    yaw: np.ndarray,
    v: np.ndarray,
    r_times: np.random.Generator,
    r_gps: np.random.Generator,
    r_drop: np.random.Generator,
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """GPS fixes from the truth (t [s], x/y [m ENU], yaw [rad], v [m/s]) and the dropouts.

    Fix intervals from the paper's distribution clipped to 0.1-0.6 s with ~4 % late fixes
    (0.4-0.6 s); positions by cubic Hermite interpolation of the truth plus white noise
    (:data:`GPS_WHITE_SD`) and a Gauss-Markov error (:data:`GPS_GM_SD`, :data:`GPS_GM_TAU_S`),
    stated accuracy their combined per-axis sigma; one 1-2 s dropout per ~40 s.
    Returns the stream and the outages ``[(t_last_fix, t_next_fix), ...]`` [s].
    """
    span = t[-1] - t[0]
    k = int(span / 0.2 * 1.3) + 16
    d = np.clip(draw_intervals(k, r_times, "aslan"), 0.1, 0.6)
    late = r_times.random(k) < 0.04
    d[late] = r_times.uniform(0.4, 0.6, int(late.sum()))
    tf = t[0] + r_times.random() * 0.2 + np.concatenate([[0.0], np.cumsum(d)])
    tf = tf[tf <= t[-1]]
    gx, gy = _hermite(t, x, y, v * np.cos(yaw), v * np.sin(yaw), tf)
    e = gps_noise(tf, r_gps, GPS_WHITE_SD, GPS_GM_SD, GPS_GM_TAU_S)
    gx, gy = gx + e[:, 0], gy + e[:, 1]
    lat, lon = enu_to_latlon(gx, gy, ORIGIN_LAT, ORIGIN_LON)
    # stated accuracy: the true per-axis 1-sigma of the noise added (an honest receiver)
    acc = np.full(tf.size, float(np.hypot(GPS_WHITE_SD, GPS_GM_SD)))
    gps = GpsStream(tf, gx, gy, lat, lon, acc)
    n_out = max(1, int(round(span / 40.0)))
    win = outage_windows(
        float(tf[0]),
        float(tf[-1]),
        r_drop.uniform(1.0, 2.0, n_out),
        r_drop,
        min_sep_s=10.0,
        repeat=False,
    )
    return drop_windows(gps, win)
