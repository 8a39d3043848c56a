"""The checks of the motion streams (``imu.yaw_rate``, ``imu.ax``, ``imu.yaw``, ``speed``)
against the reference kinematics (:mod:`posbench.scenarios.consistency_reference`: the truth
when the drive has one, else the fixes). Every reason names the reference it used ("vs truth
heading rate", "vs GPS course rate", ...). Units: rad/s, m/s^2, rad (ENU), m/s."""

from __future__ import annotations

from typing import Any

import numpy as np

from posbench.scenarios.consistency_model import (
    FAIL,
    NA,
    PASS,
    TOLERANCES,
    WARN,
    Check,
    Tolerances,
    na,
)
from posbench.scenarios.consistency_reference import Reference
from posbench.scenarios.consistency_stats import best_lag, pairs, scale_verdict, slope_corr
from posbench.scenarios.drive import Drive
from posbench.scenarios.grid import bin_mean, gaussian_kernel, smooth
from posbench.scenarios.imu_frames import circular_offset


def no_reference(drive: Drive, tol: Tolerances) -> str:
    """Why there are no reference kinematics: too few fixes, or too few stating a usable
    accuracy (and no truth)."""
    acc = drive.gps.accuracy
    if acc is not None and len(drive.gps) >= 4:
        return f"too few fixes stating <= {tol.max_fix_accuracy_m:g} m accuracy (no reference)"
    return "too few GPS fixes"


def _on_grid(t: np.ndarray, v: np.ndarray, ref: Reference, tol: Tolerances) -> np.ndarray:
    """A stream binned onto the reference's grid and smoothed like it."""
    return smooth(bin_mean(t, v, ref.t), gaussian_kernel(tol.smooth_s, 1.0 / tol.grid_hz))


def _too_little(s: str, secs: float, ref: Reference, heading: bool, tol: Tolerances) -> Check:
    """n/a for too few usable samples, saying which gate left them out."""
    if heading:
        return na(
            s,
            f"too little motion ({secs:.0f} s rolling above {tol.rolling_mps:g} m/s)",
            moving_s=secs,
        )
    rate = s == "imu.yaw_rate"
    gate = ref.rate_gate_mps if rate else ref.course_gate_mps
    what = f"the {ref.source} {'course rate' if rate else 'course'}"
    noise = f"position noise {ref.noise_m:.2f} m"
    if not np.isfinite(gate):
        why = f"{what} is noise at the speeds driven ({noise}): no usable reference"
    elif gate > tol.moving_mps:
        why = (
            f"too little usable motion: {secs:.0f} s above {gate:.1f} m/s, the speed below "
            f"which {what} is noise ({noise})"
        )
    else:
        why = f"too little motion ({secs:.0f} s above {gate:.1f} m/s)"
    return na(s, why, moving_s=secs, gate_mps=gate)


def check_yaw_rate(drive: Drive, kin: Reference | None, tol: Tolerances = TOLERANCES) -> Check:
    """``imu.yaw_rate`` [rad/s] against the reference's heading rate (truth yaw) or course
    rate (positions, above its noise gate): sign, scale (reduced major axis slope),
    correlation and time offset (cross-correlation)."""
    s = "imu.yaw_rate"
    imu = drive.imu
    if imu is None or imu.yaw_rate is None or not np.any(np.isfinite(imu.yaw_rate)):
        return na(s, "no yaw rate in the data")
    if kin is None:
        return na(s, no_reference(drive, tol))
    ref_all, name = kin.rate()
    gyro = _on_grid(imu.t, imu.yaw_rate, kin, tol)
    w = np.where(np.isfinite(ref_all), gyro, np.nan)
    ref, _ = pairs(ref_all, w)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        if kin.heading_rate is None and kin.course_rate_sign is not None:
            if found := _sign_only(s, kin, gyro, name, tol):
                return found
        return _too_little(s, secs, kin, kin.heading_rate is not None, tol)
    if float(np.std(ref)) < tol.min_turn_rad_s:
        return na(s, f"too little turning ({name} sd {np.std(ref):.3f} rad/s)", moving_s=secs)
    slope, corr, icpt = slope_corr(ref_all, w)
    # the lag of a sign-flipped gyro is that of its negation (else the peak sits at an edge)
    sign = -1.0 if slope < 0 else 1.0
    lag, peak = best_lag(ref_all, sign * w, 1.0 / tol.grid_hz, tol.max_lag_s)
    fig = {
        "sign": float(np.sign(slope)),
        "scale": slope,
        "corr": corr,
        "lag_s": lag,
        "lag_corr": peak,
        "bias_rad_s": icpt,
        "moving_s": secs,
    }
    return (
        _contradiction(s, slope, corr, name, fig, tol)
        or _weak_agreement(s, corr, lag, peak, name, name, fig, tol)
        or Check(s, PASS, f"scale {slope:.2f}, corr {corr:.2f}, lag {lag:+.2f} s vs {name}", fig)
    )


def _sign_only(
    s: str, kin: Reference, gyro: np.ndarray, name: str, tol: Tolerances
) -> Check | None:
    """The gyro's sign against a course rate too noisy for its scale (noise up to
    :attr:`Tolerances.sign_noise_ratio` x its signal): fail on a clear negative
    correlation, pass on a clear positive one (scale not judged); None when unclear, too
    few samples or no such course rate (``kin.course_rate_sign`` None)."""
    ref_all = kin.course_rate_sign
    if ref_all is None:
        return None
    ref, val = pairs(ref_all, gyro)
    secs = ref.size / tol.grid_hz
    # both must turn: the gyro's sd is blind to its sign, so it biases no verdict
    if secs < tol.min_samples_s or min(np.std(ref), np.std(val)) < tol.min_turn_rad_s:
        return None
    _, corr, _ = slope_corr(ref_all, gyro)
    fig = {
        "sign": float(np.sign(corr)),
        "corr": corr,
        "moving_s": secs,
        "gate_mps": kin.sign_gate_mps,
    }
    why = (
        f"(correlation {corr:.2f} with {name} above {kin.sign_gate_mps:.1f} m/s; scale not "
        f"judged: its noise, from {kin.noise_m:.2f} m of position noise, is too large)"
    )
    if corr <= -tol.corr_fail:
        return Check(s, FAIL, f"sign -1 {why}", fig)
    if corr >= tol.corr_fail:
        return Check(s, PASS, f"sign +1 {why}", fig)
    return None


def check_ax(drive: Drive, kin: Reference | None, tol: Tolerances = TOLERANCES) -> Check:
    """``imu.ax`` [m/s^2] against d(speed)/dt of the truth speed (with a truth), else of the
    speed stream when there is one, else of the GPS speed, while rolling: scale,
    correlation, bias (gravity left in shows as a large one)."""
    s = "imu.ax"
    imu = drive.imu
    if imu is None or not np.any(np.isfinite(imu.ax)):
        return na(s, "no IMU")
    if kin is None:
        return na(s, no_reference(drive, tol))
    dt = 1.0 / tol.grid_hz
    if kin.source == "GPS" and drive.speed is not None and len(drive.speed) > 3:
        ref_all = np.gradient(_on_grid(drive.speed.t, drive.speed.v, kin, tol), dt)
        source = "speed stream"
    else:
        ref_all, source = kin.dvdt, f"{kin.source} speed"
    ax = _on_grid(imu.t, imu.ax, kin, tol)
    # while rolling: at a standstill a position-derived speed is noise
    ref_u = np.where(kin.rolling, ref_all, np.nan)
    ax_u = np.where(kin.rolling, ax, np.nan)
    ref, val = pairs(ref_u, ax_u)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return na(s, f"too little motion ({secs:.0f} s rolling)", rolling_s=secs)
    bias = float(np.mean(val - ref))
    fig = {"bias_mps2": bias, "rolling_s": secs}
    name = f"d(speed)/dt of the {source}"
    if abs(bias) > tol.bias_fail_mps2:
        return Check(s, FAIL, f"bias {bias:+.2f} m/s^2 vs {name} (gravity left in?)", fig)
    if float(np.std(ref)) < tol.min_accel_mps2:
        v_ = WARN if abs(bias) > tol.bias_warn_mps2 else NA
        return Check(
            s,
            v_,
            f"too little speed change ({name} sd {np.std(ref):.2f} m/s^2)"
            + (f"; bias {bias:+.2f} m/s^2" if v_ == WARN else ""),
            fig,
        )
    slope, corr, _ = slope_corr(ref_u, ax_u)
    lag, peak = best_lag(ref_u, ax_u, dt, tol.max_lag_s)
    fig.update(scale=slope, corr=corr, lag_s=lag, lag_corr=peak)
    if found := _contradiction(s, slope, corr, name, fig, tol):
        return found
    if abs(bias) > tol.bias_warn_mps2:
        return Check(s, WARN, f"bias {bias:+.2f} m/s^2 vs {name}", fig)
    return _weak_agreement(s, corr, lag, peak, name, name, fig, tol) or Check(
        s, PASS, f"scale {slope:.2f}, corr {corr:.2f}, bias {bias:+.2f} m/s^2 vs {name}", fig
    )


def _contradiction(
    s: str, slope: float, corr: float, ref: str, fig: dict[str, Any], tol: Tolerances
) -> Check | None:
    """The verdict of a stream against its reference ``ref`` when its sign, correlation or
    scale contradicts it (fail, or a scale warning); None when they agree."""
    why = f"(correlation {corr:.2f} with {ref})"
    if abs(corr) >= tol.corr_fail and slope < 0:
        return Check(s, FAIL, f"sign -1 {why}", fig)
    if corr < tol.corr_fail:
        return Check(s, FAIL, f"correlation {corr:.2f} with {ref}", fig)
    v = scale_verdict(slope, tol.scale_warn, tol.scale_fail)
    return Check(s, v, f"scale {slope:.2f} {why}", fig) if v != PASS else None


def _weak_agreement(
    s: str,
    corr: float,
    lag: float,
    peak: float,
    ref: str,
    lag_ref: str,
    fig: dict[str, Any],
    tol: Tolerances,
) -> Check | None:
    """A warning for a weak correlation with ``ref`` or a time offset against ``lag_ref``
    (judged only where the cross-correlation peak is clear); None otherwise."""
    if corr < tol.corr_warn:
        return Check(s, WARN, f"correlation {corr:.2f} with {ref}", fig)
    if abs(lag) > tol.lag_warn_s and peak >= tol.lag_min_corr:
        return Check(s, WARN, f"time offset {lag:+.2f} s against {lag_ref}", fig)
    return None


def check_yaw(drive: Drive, kin: Reference | None, tol: Tolerances = TOLERANCES) -> Check:
    """``imu.yaw`` [rad, ENU] against the reference's heading (truth yaw, while rolling) or
    course (positions, above its noise gate): circular mean offset and spread [deg]."""
    s = "imu.yaw"
    imu = drive.imu
    if imu is None or imu.yaw is None or not np.any(np.isfinite(imu.yaw)):
        return na(s, "no yaw in the data")
    if kin is None:
        return na(s, no_reference(drive, tol))
    ref_all, name = kin.direction()
    c = _on_grid(imu.t, np.cos(imu.yaw), kin, tol)
    sn = _on_grid(imu.t, np.sin(imu.yaw), kin, tol)
    ref, val = pairs(ref_all, np.where(np.isfinite(ref_all), np.arctan2(sn, c), np.nan))
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return _too_little(s, secs, kin, kin.heading is not None, tol)
    off, spread = circular_offset(val - ref)
    od, sd = float(np.degrees(off)), float(np.degrees(spread))
    fig = {"offset_deg": od, "spread_deg": sd, "moving_s": secs}
    if abs(od) > tol.yaw_offset_fail_deg:
        return Check(s, FAIL, f"offset {od:+.1f} deg from {name} (spread {sd:.1f} deg)", fig)
    if abs(od) > tol.yaw_offset_warn_deg:
        return Check(s, WARN, f"offset {od:+.1f} deg from {name}", fig)
    if sd > tol.yaw_spread_warn_deg:
        return Check(s, WARN, f"spread {sd:.1f} deg about {name}", fig)
    return Check(s, PASS, f"offset {od:+.1f} deg, spread {sd:.1f} deg vs {name}", fig)


def check_speed(drive: Drive, kin: Reference | None, tol: Tolerances = TOLERANCES) -> Check:
    """``speed`` [m/s] against the reference speed: the truth's speed (rolling, with a
    ``v`` column; else above the course gate) or the GPS speed (above the course gate):
    scale (ratio of the means) and correlation."""
    s = "speed"
    sp = drive.speed
    if sp is None or len(sp) < 4:
        return na(s, "no speed stream")
    if kin is None:
        return na(s, no_reference(drive, tol))
    column = kin.source == "truth" and drive.truth is not None and drive.truth.v is not None
    use = kin.rolling if column else kin.moving
    v = np.where(use, _on_grid(sp.t, sp.v, kin, tol), np.nan)
    ref, val = pairs(kin.speed, v)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        gate = tol.rolling_mps if column else kin.course_gate_mps
        return na(s, f"too little motion ({secs:.0f} s above {gate:.1f} m/s)", moving_s=secs)
    scale = float(val.sum() / ref.sum())
    corr = slope_corr(ref, val)[1] if np.std(ref) > 0.1 else float("nan")
    fig = {"scale": scale, "corr": corr, "moving_s": secs}
    name = f"{kin.source} speed"
    v_ = scale_verdict(scale, tol.speed_scale_warn, tol.speed_scale_fail)
    if v_ != PASS:
        return Check(s, v_, f"scale {scale:.3f} against {name}", fig)
    return Check(s, PASS, f"scale {scale:.3f} vs {name}", fig)
