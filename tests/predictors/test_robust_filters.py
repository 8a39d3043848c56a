"""The filters hold on raw sensors: fed a biased, noisy, tilted and late IMU that states no
yaw, or riding a walking-speed platform with sparse noisy fixes, ``kf`` and ``ekf`` stay at
least as good as constant velocity, and the kf's bias estimate finds the accelerometer's
bias. Drives are synthetic with a known truth (issue 27's cases, not tuned to any data)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from reference_filters.linear_kalman import LinearKalman

from posbench.config import RunConfig
from posbench.replay.runner import run
from posbench.scenarios.degrade import enu_to_latlon, gps_noise
from posbench.scenarios.drive import Drive, GpsStream, ImuStream, TruthStream
from posbench.scenarios.synthetic import generate_drive
from posbench.scenarios.synthetic_motion import simulate, stop, straight, turn
from posbench.scenarios.synthetic_sensors import ORIGIN_LAT, ORIGIN_LON

BIAS = (0.45, -0.25)  # accelerometer bias, vehicle frame [m/s^2] (~2.6 deg of pitch)


def raw_imu(
    drive: Drive,
    seed: int,
    *,
    bias=BIAS,
    noise_sd: float = 0.4,
    mount_deg: float = 4.0,
    late_s: float = 0.08,
    gyro_bias: float = 0.01,
) -> ImuStream:
    """The drive's IMU as a raw consumer unit gives it: true vehicle-frame acceleration
    rotated by a mount misalignment, plus a constant bias and white noise, stamped
    ``late_s`` late, no yaw, a gyro with a bias; from the truth at 100 Hz."""
    rng = np.random.default_rng(seed)
    tr = drive.truth
    t = tr.t
    v = tr.v
    yaw = np.unwrap(tr.yaw)
    ax = np.gradient(v, t)
    yaw_rate = np.gradient(yaw, t)
    ay = v * yaw_rate
    c, s = math.cos(math.radians(mount_deg)), math.sin(math.radians(mount_deg))
    mx = c * ax - s * ay + bias[0] + rng.normal(0.0, noise_sd, t.size)
    my = s * ax + c * ay + bias[1] + rng.normal(0.0, noise_sd, t.size)
    wr = yaw_rate + gyro_bias + rng.normal(0.0, 0.01, t.size)
    return ImuStream(t + late_s, mx, my, None, wr)


def future_means(drives: list[Drive], predictors=("cv", "kf", "ekf")) -> dict[str, float]:
    cfg = RunConfig(predictors=predictors, gps_profile="native")
    runs = run(drives, cfg, workers=1)
    import pandas as pd

    t = pd.concat([r.traces for r in runs], ignore_index=True)
    t = t[(t.kind == "future") & np.isfinite(t.error_m)]
    return {p: float(t.loc[t.predictor == p, "error_m"].mean()) for p in predictors}


@pytest.mark.slow
def test_raw_tilted_late_imu_does_not_make_the_filters_lose_to_cv():
    drives = []
    for seed, route in ((1101, "mixed"), (1102, "turns")):
        d = generate_drive(seed=seed, route=route)
        drives.append(replace(d, imu=raw_imu(d, seed), speed=None))
    m = future_means(drives)
    assert m["kf"] <= m["cv"], m
    assert m["ekf"] <= m["cv"], m


def walking_drive(seed: int) -> Drive:
    """A ground robot at <= 1 m/s: straights, turns and a stop; fixes at 2.5 Hz with 0.3 m
    white + 0.3 m correlated noise (stating 0.45 m); a levelled consumer IMU with no yaw."""
    rng = np.random.default_rng(seed)
    segs = [
        straight(15.0, 1.0),
        turn(90.0, 3.0, 0.8),
        straight(10.0, 1.0),
        stop(5.0),
        straight(8.0, 0.6),
        turn(-120.0, 4.0, 0.8),
        straight(15.0, 1.0),
    ]
    sim = simulate(segs, yaw0=0.3)
    truth = TruthStream(sim.t, sim.x, sim.y, sim.yaw, sim.v)
    tf = np.arange(sim.t[0] + 0.1, sim.t[-1], 0.4)
    gx = np.interp(tf, sim.t, sim.x)
    gy = np.interp(tf, sim.t, sim.y)
    e = gps_noise(tf, rng, 0.3, 0.3, 20.0)
    gx, gy = gx + e[:, 0], gy + e[:, 1]
    lat, lon = enu_to_latlon(gx, gy, ORIGIN_LAT, ORIGIN_LON)
    gps = GpsStream(tf, gx, gy, lat, lon, np.full(tf.size, math.hypot(0.3, 0.3)))
    d = generate_drive(seed=seed, route="mixed")
    drive = Drive(
        meta=replace(d.meta, name=f"walking-s{seed}", source=f"test:walking:{seed}"),
        gps=gps,
        imu=None,
        speed=None,
        truth=truth,
    )
    return replace(
        drive,
        imu=raw_imu(
            drive, seed, bias=(0.1, -0.05), noise_sd=0.2, mount_deg=0.0, late_s=0.0, gyro_bias=0.005
        ),
    )


@pytest.mark.slow
def test_walking_speed_platform_filters_do_not_lose_to_cv():
    m = future_means([walking_drive(1201), walking_drive(1202)])
    assert m["kf"] <= m["cv"], m
    assert m["ekf"] <= m["cv"], m


def test_kf_recovers_the_accelerometer_bias():
    d = generate_drive(seed=1103, route="mixed")
    imu = raw_imu(d, 1103, mount_deg=0.0, late_s=0.0)
    kf = LinearKalman(
        jerk_psd=4.0,
        heading_from_fixes=True,
        accel_bias_tau_s=30.0,
        imu_gate=13.8,
        imu_noise_tau_s=5.0,
        use_speed=False,
    )
    events = sorted(
        [(t, 0, i) for i, t in enumerate(d.gps.t)] + [(t, 1, i) for i, t in enumerate(imu.t)]
    )
    for t, kind, i in events:
        if kind == 0:
            kf.observe_gps(t, d.gps.x[i], d.gps.y[i], d.gps.accuracy[i])
        else:
            kf.observe_imu(t, imu.ax[i], imu.ay[i], math.nan, imu.yaw_rate[i])
    bx, by = kf.accel_bias
    assert bx == pytest.approx(BIAS[0], abs=0.1)
    assert by == pytest.approx(BIAS[1], abs=0.1)


def test_a_speed_without_heading_leaves_answers_on_the_predicted_mean():
    """A wheel speed the filter cannot place (no heading yet: fixes 2 m apart in 3 m noise)
    still predicts the filter to its time; its answers must start from that mean, not from
    the mean of the previous observation."""
    kf = LinearKalman(gps_sigma=3.0, heading_from_fixes=True, use_imu=False)
    kf.observe_gps(0.0, 0.0, 0.0)
    kf.observe_gps(0.2, 2.0, 0.0)
    kf.observe_speed(0.3, 10.0)
    t, mean, _ = kf.state()
    assert t == 0.3
    assert kf.position_at(0.3) == pytest.approx((mean[0], mean[1]), abs=1e-12)
