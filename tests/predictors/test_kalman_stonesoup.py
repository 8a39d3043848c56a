"""The kf's compiled filter maths against Stone Soup, a reference that is not ours.

The kf rows (:mod:`posbench.predictors.kalman.ca_rows`) are a 2-D constant-acceleration
Kalman filter: the motion model of :mod:`posbench.metrics.ca_model` and one update per
sensor (:func:`~posbench.predictors.kalman.ca_rows.update_pair` for a position fix, an ENU
acceleration or a zero velocity; :func:`~posbench.predictors.kalman.ca_rows.update_speed`
for a speed along a heading). Here one row is stepped through a drive's measurements
beside Stone Soup's ``KalmanPredictor`` / ``KalmanUpdater`` with two
``ConstantAcceleration`` models (state ``[x, vx, ax, y, vy, ay]``) and ``LinearGaussian``
measurement models (H: a selection, or the speed's ``[0, c, 0, 0, s, 0]``), from the
same prior. After every step the means must agree to 1e-9 m (relative 1e-12) and the
covariances to 1e-9 relative. Drives: synthetic ones, and the first 60 s of one drive per
shared data set (aslan, KITTI, comma2k19).

Stone Soup keeps time as ``datetime`` (microseconds), so every time is rounded to the
microsecond for both.
"""

from __future__ import annotations

import datetime
import math

import numpy as np
import pytest
from helpers import missing

from posbench.predictors.kalman import ca_rows
from posbench.scenarios.drive import Drive
from posbench.scenarios.synthetic import generate_drive

try:
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantAcceleration,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater
except ImportError:  # pragma: no cover - the dev extra has it
    STONESOUP = False
else:
    STONESOUP = True

PSD = 0.8  # white-jerk density [m^2/s^5]
R_FIX, R_ACC, R_SPD = 0.25, 0.3**2, 0.1**2  # [m^2], [m^2/s^4], [m^2/s^2]
VV, VA = 4.0, 1.0  # prior velocity [m^2/s^2] and acceleration [m^2/s^4] variances
EPOCH = datetime.datetime(2020, 1, 1)


def along_heading(c: float, s: float, r: float) -> LinearGaussian:
    """A speed along the heading (c, s) of variance r: H = [0, c, 0, 0, s, 0]."""

    class AlongHeading(LinearGaussian):
        def matrix(self, **kwargs: object) -> np.ndarray:
            return np.array([[0.0, c, 0.0, 0.0, s, 0.0]])

    return AlongHeading(ndim_state=6, mapping=(1, 4), noise_covar=np.array([[r]]))


def row_state(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row 0's mean [x, vx, ax, y, vy, ay] and 6x6 covariance (blocks A, B, C)."""
    row = S[0]
    mean = row[:6].copy()
    P = np.zeros((6, 6))
    for o, base in ((ca_rows.A, 0), (ca_rows.B, 3)):
        a = row[o : o + 6]
        block = np.array([[a[0], a[1], a[2]], [a[1], a[3], a[4]], [a[2], a[4], a[5]]])
        P[base : base + 3, base : base + 3] = block
    C = row[ca_rows.C : ca_rows.C + 9].reshape(3, 3)
    P[:3, 3:] = C
    P[3:, :3] = C.T
    return mean, P


def measurements(drive: Drive, duration_s: float) -> list[tuple[float, str, tuple[float, ...]]]:
    """(t [s], kind, values) in time order, t rounded to the microsecond: the fixes; every
    5th IMU sample as an ENU acceleration (rotated by its yaw, else by the course between
    the two newest fixes); every 5th wheel speed as a speed along the same heading."""
    gps = drive.gps
    t0 = float(gps.t[0])
    out: list[tuple[float, str, tuple[float, ...]]] = []
    for t, x, y in zip(gps.t, gps.x, gps.y, strict=True):
        if t - t0 <= duration_s and math.isfinite(x) and math.isfinite(y):
            out.append((float(t), "fix", (float(x), float(y))))
    course = np.arctan2(np.diff(gps.y), np.diff(gps.x))

    def heading(t: float, yaw: float) -> float:
        if math.isfinite(yaw):
            return yaw
        k = int(np.searchsorted(gps.t, t)) - 2
        return float(course[min(max(k, 0), len(course) - 1)])

    if drive.imu is not None:
        imu = drive.imu
        yaws = imu.yaw if imu.yaw is not None else np.full(len(imu.t), np.nan)
        for t, ax, ay, yaw in list(zip(imu.t, imu.ax, imu.ay, yaws, strict=True))[::5]:
            if t0 < t - 1e-3 and t - t0 <= duration_s and math.isfinite(ax) and math.isfinite(ay):
                h = heading(float(t), float(yaw))
                c, s = math.cos(h), math.sin(h)
                out.append((float(t), "acc", (c * ax - s * ay, s * ax + c * ay)))
    if drive.speed is not None:
        for t, v in list(zip(drive.speed.t, drive.speed.v, strict=True))[::5]:
            if t0 < t - 1e-3 and t - t0 <= duration_s and math.isfinite(v):
                h = heading(float(t), math.nan)
                out.append((float(t), "speed", (math.cos(h), math.sin(h), float(v))))
    out = [(round(t * 1e6) / 1e6, kind, v) for t, kind, v in out]
    out.sort(key=lambda m: m[0])
    return out


def assert_kf_maths_match_stone_soup(drive: Drive, duration_s: float) -> int:
    """Step both through ``measurements``; returns how many steps were compared."""
    if not STONESOUP:
        missing("stonesoup cannot be imported (the dev extra has it)")
    events = measurements(drive, duration_s)
    t0, kind, (x0, y0) = events[0]
    assert kind == "fix"
    S = ca_rows.new_rows(1)
    ca_rows.init_rows(S, 1, t0, x0, y0, R_FIX, VV, VA)
    transition = CombinedLinearGaussianTransitionModel(
        [ConstantAcceleration(noise_diff_coeff=PSD), ConstantAcceleration(noise_diff_coeff=PSD)]
    )
    predictor = KalmanPredictor(transition)
    updater = KalmanUpdater(measurement_model=None)
    position = LinearGaussian(ndim_state=6, mapping=(0, 3), noise_covar=R_FIX * np.eye(2))
    accel = LinearGaussian(ndim_state=6, mapping=(2, 5), noise_covar=R_ACC * np.eye(2))
    mean0, P0 = row_state(S)
    state = GaussianState(mean0.reshape(6, 1), P0, timestamp=EPOCH)

    def stamp(t: float) -> datetime.datetime:
        return EPOCH + datetime.timedelta(microseconds=round((t - t0) * 1e6))

    steps = 0
    for t, kind, values in events[1:]:
        ca_rows.predict(S, 0, t, PSD)
        if kind == "fix":
            ca_rows.update_pair(S, 0, 0, values[0], values[1], R_FIX)
            model, z = position, np.array([[values[0]], [values[1]]])
        elif kind == "acc":
            ca_rows.update_pair(S, 0, 2, values[0], values[1], R_ACC)
            model, z = accel, np.array([[values[0]], [values[1]]])
        else:
            c, s, v = values
            ca_rows.update_speed(S, 0, c, s, v, R_SPD)
            model = along_heading(c, s, R_SPD)
            z = np.array([[v]])
        prediction = predictor.predict(state, timestamp=stamp(t))
        detection = Detection(z, timestamp=stamp(t), measurement_model=model)
        state = updater.update(SingleHypothesis(prediction, detection))
        mean, P = row_state(S)
        ref_mean = np.asarray(state.state_vector, dtype=float).ravel()
        ref_P = np.asarray(state.covar, dtype=float)
        np.testing.assert_allclose(mean, ref_mean, rtol=1e-12, atol=1e-9, err_msg=f"{kind} t={t}")
        scale = np.sqrt(np.outer(np.diag(ref_P), np.diag(ref_P)))
        np.testing.assert_allclose(P / scale, ref_P / scale, rtol=0, atol=1e-9, err_msg=kind)
        steps += 1
    return steps


@pytest.mark.parametrize("route", ["mixed", "turns", "stop_and_go"])
def test_kf_maths_match_stone_soup_on_synthetic_drives(route: str) -> None:
    drive = generate_drive(seed=4701, route=route, duration_s=60.0)
    assert assert_kf_maths_match_stone_soup(drive, 60.0) > 300


@pytest.mark.shared
@pytest.mark.parametrize("which", [0, 1, 2], ids=["aslan", "kitti", "comma2k19"])
def test_kf_maths_match_stone_soup_on_shared_segments(
    filter_parity_drives: list[Drive], which: int
) -> None:
    assert assert_kf_maths_match_stone_soup(filter_parity_drives[which], 60.0) > 100
