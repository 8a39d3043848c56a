"""Consistency of a drive's streams with each other, from the data alone, before any figure.

Every stream is compared with what the GPS fixes themselves imply (and the GPS with the
truth when there is one), on a common grid of :attr:`Tolerances.grid_hz`:

========================  =====================================================  ===========
stream                    check                                                  figures
========================  =====================================================  ===========
``imu.yaw_rate``          gyro yaw rate vs the rate of the GPS course (moving)   sign, scale,
                                                                                 corr, lag_s
``imu.ax``                longitudinal acceleration vs d(speed)/dt (the speed    scale, corr,
                          stream's, else the GPS speed's)                        bias_mps2
``imu.yaw``               IMU yaw vs GPS course (moving): circular mean offset   offset_deg,
                          and spread                                             spread_deg
``speed``                 wheel/CAN speed vs GPS speed (moving)                  scale, corr
``gps``                   scatter of the fixes about their neighbours vs the     scatter_m,
                          accuracy the source states                             stated_m
``truth``                 GPS vs truth: offset, 2-D similarity fit (scale,       offset_m,
                          rotation) and the residual RMS                         scale, ...
========================  =====================================================  ===========

Each check gives a :class:`Check` with a verdict ``pass`` / ``warn`` / ``fail`` / ``n/a``
and a reason naming the figure that decided it. Every tolerance is in :class:`Tolerances`
(units and the physics behind each value). Frames: positions in the drive's local metres,
yaw and course ENU radians (0 = east, counter-clockwise), vehicle x forward. Signs: ``lag_s``
> 0 means the IMU stream is late (its stamps trail the GPS's by that many seconds).

GPS-derived kinematics: fixes are linearly interpolated onto the grid (not across gaps
longer than :attr:`Tolerances.max_fix_gap_s`) and smoothed with a Gaussian of
:attr:`Tolerances.smooth_s`; velocity by central differences. The other stream is averaged
into the same grid cells and smoothed with the same kernel, so smoothing changes neither
a scale nor a lag. Course and its rate are used only while the GPS speed is above
:attr:`Tolerances.moving_mps` (a course from metre-noise fixes at walking pace is noise).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from posbench.scenarios.align import similarity_2d
from posbench.scenarios.drive import Drive
from posbench.scenarios.grid import bin_mean, gaussian_kernel, interp_gapped, smooth
from posbench.scenarios.imu_frames import circular_offset

PASS, WARN, FAIL, NA = "pass", "warn", "fail", "n/a"
VERDICTS = (PASS, WARN, FAIL, NA)
STREAMS = ("imu.yaw_rate", "imu.ax", "imu.yaw", "speed", "gps", "truth")
_RANK = {NA: 0, PASS: 1, WARN: 2, FAIL: 3}


@dataclass(frozen=True)
class Tolerances:
    """Every threshold of the check, with its unit and why (one place; see the README).

    Grid and gating:
        grid_hz: common grid [Hz]; 10 Hz resolves vehicle dynamics (yaw, speed change
            over >= 0.5 s) and is the fastest GPS rate in the shared data.
        smooth_s: sigma [s] of the Gaussian applied to both sides of a comparison; 0.5 s
            turns metre-scale fix noise into usable velocity, course and their rates
            without touching turns (2-10 s) more than the IMU side, which gets the same.
        max_fix_gap_s: no GPS kinematics across a gap between fixes longer than this [s].
        moving_mps: GPS speed [m/s] above which its course is trusted: at 3 m/s, 1 m of
            fix noise smoothed over ~1 s is a course error of a few degrees.
        min_samples_s: at least this much usable, moving data [s] for a verdict.
        min_turn_rad_s: standard deviation of the GPS course rate [rad/s] needed to judge
            a gyro (a straight highway has none: sign and scale are then unknowable).
        min_accel_mps2: standard deviation of d(speed)/dt [m/s^2] needed to judge ax.
        max_lag_s: cross-correlation searched within +- this [s].
        min_extent_m: RMS distance of the fixes from their centroid [m] needed to fit a
            scale and rotation between GPS and truth.

    Verdicts (warn / fail):
        corr_warn, corr_fail: correlation with the GPS-derived signal below which the
            stream is doubtful / unrelated to the motion (sign is judged only if
            |corr| >= corr_fail).
        scale_warn, scale_fail: |log(scale)| above log(1 + x): x = 0.25 / 1.0 for a
            gyro or accelerometer (a least-squares slope against a noisy GPS-derived
            signal reads low by the noise share, so 25 % is a real error; x2 a unit or
            axis mix-up).
        speed_scale_warn, speed_scale_fail: the same for wheel speed vs GPS speed:
            tyre wear and pressure give 1-3 %, so 5 % is suspicious and 15 % wrong
            (a wheel speed in km/h read as m/s is 260 %).
        bias_warn_mps2, bias_fail_mps2: |mean(ax - dv/dt)| [m/s^2]. A road's slope puts
            g sin(grade) into an accelerometer: a whole drive averaging 4 deg of climb
            gives 0.7, and no drivable route averages 9 deg (1.5); gravity left in by a
            tilted or sideways mount gives 1.5-9.8.
        lag_warn_s: |lag| [s] above which time stamps of the stream are suspect (0.2 s is
            one prediction horizon).
        lag_min_corr: the lag is judged only where the cross-correlation peak reaches
            this (a broad, low peak places its maximum anywhere within +-0.5 s).
        max_fix_accuracy_m: fixes stating a worse accuracy [m] are no reference for the
            other streams (5 m over the 0.5 s smoothing is metres per second of noise);
            a source whose median is worse gets a ``gps`` warning.
        yaw_offset_warn_deg, yaw_offset_fail_deg: |circular mean(yaw - course)| [deg]:
            side slip and magnetic declination stay below 10 deg; 30 deg is a yaw in
            another frame (magnetic north far from here, or relative to power-on).
        yaw_spread_warn_deg: circular standard deviation [deg] of yaw - course while
            moving above which the yaw does not follow the course.
        gps_truth_offset_warn_m, gps_truth_offset_fail_m: |mean(gps - truth)| [m]:
            consumer receivers sit within 1-3 m of the truth; 10 m is another frame
            or datum.
        gps_truth_rms_warn_m, gps_truth_rms_fail_m: RMS of gps - truth after the best
            similarity fit [m]: the noise the truth sees in the GPS.
        rot_warn_deg, rot_fail_deg: rotation [deg] of the fit (frames should agree).
        truth_scale_warn, truth_scale_fail: |scale - 1| of the fit (1 %: a local
            projection error over a few km; 5 %: a different projection).
        scatter_ratio_warn, scatter_ratio_fail: fix scatter / stated median accuracy:
            the source understates its own error 3x / 10x (what it says cannot be the
            noise it has).
    """

    grid_hz: float = 10.0
    smooth_s: float = 0.5
    max_fix_gap_s: float = 1.0
    moving_mps: float = 3.0
    min_samples_s: float = 10.0
    min_turn_rad_s: float = 0.03
    min_accel_mps2: float = 0.15
    max_lag_s: float = 1.0
    min_extent_m: float = 30.0

    corr_warn: float = 0.7
    corr_fail: float = 0.3
    scale_warn: float = 0.25
    scale_fail: float = 1.0
    speed_scale_warn: float = 0.05
    speed_scale_fail: float = 0.15
    bias_warn_mps2: float = 0.7
    bias_fail_mps2: float = 1.5
    lag_warn_s: float = 0.2
    lag_min_corr: float = 0.9
    max_fix_accuracy_m: float = 5.0
    yaw_offset_warn_deg: float = 10.0
    yaw_offset_fail_deg: float = 30.0
    yaw_spread_warn_deg: float = 15.0
    gps_truth_offset_warn_m: float = 3.0
    gps_truth_offset_fail_m: float = 10.0
    gps_truth_rms_warn_m: float = 3.0
    gps_truth_rms_fail_m: float = 10.0
    rot_warn_deg: float = 1.0
    rot_fail_deg: float = 5.0
    truth_scale_warn: float = 0.01
    truth_scale_fail: float = 0.05
    scatter_ratio_warn: float = 3.0
    scatter_ratio_fail: float = 10.0


TOLERANCES = Tolerances()


@dataclass
class Check:
    """One stream's verdict: ``figures`` (named numbers, units in the names), the
    ``verdict`` and ``reason`` (the figure that decided it, or why it is n/a)."""

    stream: str
    verdict: str
    reason: str = ""
    figures: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """As plain JSON values (a non-finite figure as None)."""
        d = asdict(self)
        d["figures"] = {k: (float(v) if np.isfinite(v) else None) for k, v in self.figures.items()}
        return d


@dataclass
class Consistency:
    """All checks of one drive, by stream (:data:`STREAMS` order)."""

    drive: str
    checks: dict[str, Check]

    def failures(self) -> list[Check]:
        return [c for c in self.checks.values() if c.verdict == FAIL]

    def warnings(self) -> list[Check]:
        return [c for c in self.checks.values() if c.verdict == WARN]

    def to_dict(self) -> dict[str, Any]:
        return {s: c.to_dict() for s, c in self.checks.items()}


def worst(verdicts: list[str]) -> str:
    """The worst of several verdicts (fail > warn > pass > n/a)."""
    return max(verdicts, key=_RANK.__getitem__) if verdicts else NA


@dataclass(frozen=True)
class GpsKinematics:
    """What the fixes imply on the grid ``t`` [s]: smoothed speed [m/s], its rate dv/dt
    [m/s^2], course [rad, ENU] and course rate [rad/s]; ``moving`` where speed is above
    the gate (and the course and its rate are usable there)."""

    t: np.ndarray
    speed: np.ndarray
    dvdt: np.ndarray
    course: np.ndarray
    course_rate: np.ndarray
    moving: np.ndarray


def gps_kinematics(drive: Drive, tol: Tolerances = TOLERANCES) -> GpsKinematics | None:
    """GPS-derived speed, acceleration, course and course rate on the common grid, or None
    when there are too few fixes."""
    g = drive.gps
    if g.accuracy is not None:
        g = g.take(~(g.accuracy > tol.max_fix_accuracy_m))
    if len(g) < 4:
        return None
    dt = 1.0 / tol.grid_hz
    grid = np.arange(g.t[0], g.t[-1] + dt / 2, dt)
    if grid.size < 8:
        return None
    k = gaussian_kernel(tol.smooth_s, dt)
    x = smooth(interp_gapped(g.t, g.x, grid, tol.max_fix_gap_s), k)
    y = smooth(interp_gapped(g.t, g.y, grid, tol.max_fix_gap_s), k)
    vx, vy = np.gradient(x, dt), np.gradient(y, dt)
    speed = np.hypot(vx, vy)
    dvdt = np.gradient(speed, dt)
    course = np.arctan2(vy, vx)
    dc = np.angle(np.exp(1j * (course[2:] - course[:-2]))) / (2 * dt)
    rate = np.concatenate([[np.nan], dc, [np.nan]])
    with np.errstate(invalid="ignore"):
        fast = speed > tol.moving_mps
    moving = fast & np.roll(fast, 1) & np.roll(fast, -1)
    moving[[0, -1]] = False
    rate[~moving] = np.nan
    course = np.where(moving, course, np.nan)
    return GpsKinematics(grid, speed, dvdt, course, rate, moving)


def _pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ok = np.isfinite(a) & np.isfinite(b)
    return a[ok], b[ok]


def slope_corr(ref: np.ndarray, val: np.ndarray) -> tuple[float, float, float]:
    """Scale of ``val`` against ``ref``, their correlation and the offset ``val - scale *
    ref`` at the mean, over samples finite in both.

    The scale is the geometric-mean (reduced major axis) least-squares slope
    sign(r) sd(val) / sd(ref): both sides are noisy (a GPS-derived rate is the noisier),
    and the ordinary slope of val on ref would read low by r^2 (0.7 at r = 0.84) with a
    perfect sensor. It lies between the slopes of val on ref and of ref on val."""
    r, v = _pairs(ref, val)
    if r.size < 3:
        return float("nan"), float("nan"), float("nan")
    rc, vc = r - r.mean(), v - v.mean()
    sxx, syy, sxy = float(rc @ rc), float(vc @ vc), float(rc @ vc)
    if sxx <= 0 or syy <= 0:
        return float("nan"), float("nan"), float("nan")
    corr = sxy / np.sqrt(sxx * syy)
    slope = float(np.sign(corr) * np.sqrt(syy / sxx))
    return slope, corr, float(v.mean() - slope * r.mean())


def best_lag(ref: np.ndarray, val: np.ndarray, dt: float, max_lag_s: float) -> tuple[float, float]:
    """Lag [s] of ``val`` behind ``ref`` by normalised cross-correlation within
    +-``max_lag_s`` (parabolic refinement of the peak), and the peak correlation."""
    n = int(round(max_lag_s / dt))
    lags = np.arange(-n, n + 1)
    cc = np.full(lags.size, np.nan)
    for i, k in enumerate(lags):
        a = ref[: ref.size - k] if k >= 0 else ref[-k:]
        b = val[k:] if k >= 0 else val[: val.size + k]
        cc[i] = slope_corr(a, b)[1]
    if not np.any(np.isfinite(cc)):
        return float("nan"), float("nan")
    j = int(np.nanargmax(cc))
    frac = 0.0
    if 0 < j < lags.size - 1 and np.all(np.isfinite(cc[j - 1:j + 2])):
        den = cc[j - 1] - 2 * cc[j] + cc[j + 1]
        if den < 0:
            frac = 0.5 * (cc[j - 1] - cc[j + 1]) / den
    return float((lags[j] + frac) * dt), float(cc[j])


def _scale_verdict(scale: float, warn: float, fail: float) -> str:
    e = abs(np.log(scale)) if scale > 0 else np.inf
    return FAIL if e > np.log1p(fail) else WARN if e > np.log1p(warn) else PASS


def _na(stream: str, reason: str, **figures: float) -> Check:
    return Check(stream, NA, reason, dict(figures))


def _no_reference(drive: Drive, tol: Tolerances) -> str:
    """Why there are no GPS kinematics: too few fixes, or too few stating a usable accuracy."""
    acc = drive.gps.accuracy
    if acc is not None and len(drive.gps) >= 4:
        return f"too few fixes stating <= {tol.max_fix_accuracy_m:g} m accuracy (no reference)"
    return "too few GPS fixes"


# ---------------------------------------------------------------- the checks

def check_yaw_rate(drive: Drive, kin: GpsKinematics | None, tol: Tolerances = TOLERANCES
                   ) -> Check:
    """``imu.yaw_rate`` [rad/s] against the GPS course rate while moving: sign, scale
    (least-squares slope), correlation and time offset (cross-correlation)."""
    s = "imu.yaw_rate"
    imu = drive.imu
    if imu is None or imu.yaw_rate is None or not np.any(np.isfinite(imu.yaw_rate)):
        return _na(s, "no yaw rate in the data")
    if kin is None:
        return _na(s, _no_reference(drive, tol))
    k = gaussian_kernel(tol.smooth_s, 1.0 / tol.grid_hz)
    w = smooth(bin_mean(imu.t, imu.yaw_rate, kin.t), k)
    w_moving = np.where(kin.moving, w, np.nan)
    ref, val = _pairs(kin.course_rate, w_moving)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return _na(s, f"too little motion ({secs:.0f} s above {tol.moving_mps:g} m/s)",
                   moving_s=secs)
    if float(np.std(ref)) < tol.min_turn_rad_s:
        return _na(s, f"too little turning (course rate sd {np.std(ref):.3f} rad/s)",
                   moving_s=secs)
    slope, corr, icpt = slope_corr(kin.course_rate, w_moving)
    # the lag of a sign-flipped gyro is that of its negation (else the peak sits at an edge)
    sign = -1.0 if slope < 0 else 1.0
    lag, peak = best_lag(kin.course_rate, sign * w_moving, 1.0 / tol.grid_hz, tol.max_lag_s)
    fig = {"sign": float(np.sign(slope)), "scale": slope, "corr": corr, "lag_s": lag,
           "lag_corr": peak, "bias_rad_s": icpt, "moving_s": secs}
    ref = "GPS course rate"
    return (_contradiction(s, slope, corr, ref, fig, tol)
            or _weak_agreement(s, corr, lag, peak, ref, ref, fig, tol)
            or Check(s, PASS, f"scale {slope:.2f}, corr {corr:.2f}, lag {lag:+.2f} s", fig))


def check_ax(drive: Drive, kin: GpsKinematics | None, tol: Tolerances = TOLERANCES) -> Check:
    """``imu.ax`` [m/s^2] against d(speed)/dt (the speed stream when there is one, else
    the GPS speed): scale, correlation, bias (gravity left in shows as a large one)."""
    s = "imu.ax"
    imu = drive.imu
    if imu is None or not np.any(np.isfinite(imu.ax)):
        return _na(s, "no IMU")
    if kin is None:
        return _na(s, _no_reference(drive, tol))
    dt = 1.0 / tol.grid_hz
    k = gaussian_kernel(tol.smooth_s, dt)
    if drive.speed is not None and len(drive.speed) > 3:
        v = smooth(bin_mean(drive.speed.t, drive.speed.v, kin.t), k)
        ref_all, source = np.gradient(v, dt), "speed stream"
    else:
        ref_all, source = kin.dvdt, "GPS speed"
    ax = smooth(bin_mean(imu.t, imu.ax, kin.t), k)
    # while rolling (any speed over 1 m/s or standing still is fine for a bias, but
    # the GPS speed at a standstill is noise): use samples where the GPS speed is known
    use = np.isfinite(kin.speed) & (kin.speed > 1.0)
    ref_u, ax_u = np.where(use, ref_all, np.nan), np.where(use, ax, np.nan)
    ref, val = _pairs(ref_u, ax_u)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return _na(s, f"too little motion ({secs:.0f} s rolling)", rolling_s=secs)
    bias = float(np.mean(val - ref))
    fig = {"bias_mps2": bias, "rolling_s": secs}
    if abs(bias) > tol.bias_fail_mps2:
        return Check(s, FAIL, f"bias {bias:+.2f} m/s^2 against d(speed)/dt of the {source} "
                              "(gravity left in?)", fig)
    if float(np.std(ref)) < tol.min_accel_mps2:
        v_ = WARN if abs(bias) > tol.bias_warn_mps2 else NA
        return Check(s, v_, f"too little speed change (dv/dt sd {np.std(ref):.2f} m/s^2)"
                     + (f"; bias {bias:+.2f} m/s^2" if v_ == WARN else ""), fig)
    slope, corr, _ = slope_corr(ref_u, ax_u)
    lag, peak = best_lag(ref_u, ax_u, dt, tol.max_lag_s)
    fig.update(scale=slope, corr=corr, lag_s=lag, lag_corr=peak)
    ref = f"d(speed)/dt of the {source}"
    if found := _contradiction(s, slope, corr, ref, fig, tol):
        return found
    if abs(bias) > tol.bias_warn_mps2:
        return Check(s, WARN, f"bias {bias:+.2f} m/s^2 against d(speed)/dt", fig)
    return (_weak_agreement(s, corr, lag, peak, ref, "d(speed)/dt", fig, tol)
            or Check(s, PASS, f"scale {slope:.2f}, corr {corr:.2f}, bias {bias:+.2f} m/s^2", fig))


def _contradiction(s: str, slope: float, corr: float, ref: str, fig: dict[str, Any],
                   tol: Tolerances) -> Check | None:
    """The verdict of a stream against its GPS-derived reference ``ref`` when its sign,
    correlation or scale contradicts it (fail, or a scale warning); None when they agree."""
    why = f"(correlation {corr:.2f} with {ref})"
    if abs(corr) >= tol.corr_fail and slope < 0:
        return Check(s, FAIL, f"sign -1 {why}", fig)
    if corr < tol.corr_fail:
        return Check(s, FAIL, f"correlation {corr:.2f} with {ref}", fig)
    v = _scale_verdict(slope, tol.scale_warn, tol.scale_fail)
    return Check(s, v, f"scale {slope:.2f} {why}", fig) if v != PASS else None


def _weak_agreement(s: str, corr: float, lag: float, peak: float, ref: str, lag_ref: str,
                    fig: dict[str, Any], tol: Tolerances) -> Check | None:
    """A warning for a weak correlation with ``ref`` or a time offset against ``lag_ref``
    (judged only where the cross-correlation peak is clear); None otherwise."""
    if corr < tol.corr_warn:
        return Check(s, WARN, f"correlation {corr:.2f} with {ref}", fig)
    if abs(lag) > tol.lag_warn_s and peak >= tol.lag_min_corr:
        return Check(s, WARN, f"time offset {lag:+.2f} s against {lag_ref}", fig)
    return None


def check_yaw(drive: Drive, kin: GpsKinematics | None, tol: Tolerances = TOLERANCES) -> Check:
    """``imu.yaw`` [rad, ENU] against the GPS course while moving: circular mean offset
    and spread [deg]."""
    s = "imu.yaw"
    imu = drive.imu
    if imu is None or imu.yaw is None or not np.any(np.isfinite(imu.yaw)):
        return _na(s, "no yaw in the data")
    if kin is None:
        return _na(s, _no_reference(drive, tol))
    k = gaussian_kernel(tol.smooth_s, 1.0 / tol.grid_hz)
    c = smooth(bin_mean(imu.t, np.cos(imu.yaw), kin.t), k)
    sn = smooth(bin_mean(imu.t, np.sin(imu.yaw), kin.t), k)
    yaw = np.where(kin.moving, np.arctan2(sn, c), np.nan)
    ref, val = _pairs(kin.course, yaw)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return _na(s, f"too little motion ({secs:.0f} s above {tol.moving_mps:g} m/s)",
                   moving_s=secs)
    off, spread = circular_offset(val - ref)
    od, sd = float(np.degrees(off)), float(np.degrees(spread))
    fig = {"offset_deg": od, "spread_deg": sd, "moving_s": secs}
    if abs(od) > tol.yaw_offset_fail_deg:
        return Check(s, FAIL, f"offset {od:+.1f} deg from GPS course (spread {sd:.1f} deg)", fig)
    if abs(od) > tol.yaw_offset_warn_deg:
        return Check(s, WARN, f"offset {od:+.1f} deg from GPS course", fig)
    if sd > tol.yaw_spread_warn_deg:
        return Check(s, WARN, f"spread {sd:.1f} deg about GPS course", fig)
    return Check(s, PASS, f"offset {od:+.1f} deg, spread {sd:.1f} deg", fig)


def check_speed(drive: Drive, kin: GpsKinematics | None, tol: Tolerances = TOLERANCES
                ) -> Check:
    """``speed`` [m/s] against GPS speed while moving: scale (ratio of the means) and
    correlation."""
    s = "speed"
    sp = drive.speed
    if sp is None or len(sp) < 4:
        return _na(s, "no speed stream")
    if kin is None:
        return _na(s, _no_reference(drive, tol))
    k = gaussian_kernel(tol.smooth_s, 1.0 / tol.grid_hz)
    v = np.where(kin.moving, smooth(bin_mean(sp.t, sp.v, kin.t), k), np.nan)
    ref, val = _pairs(kin.speed, v)
    secs = ref.size / tol.grid_hz
    if secs < tol.min_samples_s:
        return _na(s, f"too little motion ({secs:.0f} s above {tol.moving_mps:g} m/s)",
                   moving_s=secs)
    scale = float(val.sum() / ref.sum())
    corr = slope_corr(ref, val)[1] if np.std(ref) > 0.1 else float("nan")
    fig = {"scale": scale, "corr": corr, "moving_s": secs}
    v_ = _scale_verdict(scale, tol.speed_scale_warn, tol.speed_scale_fail)
    if v_ != PASS:
        return Check(s, v_, f"scale {scale:.3f} against GPS speed", fig)
    return Check(s, PASS, f"scale {scale:.3f}", fig)


def check_truth(drive: Drive, tol: Tolerances = TOLERANCES) -> Check:
    """GPS fixes against the truth at the same times [m]: mean offset, RMS, and the
    similarity fit truth -> GPS (scale, rotation [deg], residual RMS)."""
    s = "truth"
    tr, g = drive.truth, drive.gps
    if tr is None or len(tr) < 2:
        return _na(s, "no truth")
    if len(g) < 4:
        return _na(s, _no_reference(drive, tol))
    tx = interp_gapped(tr.t, tr.x, g.t, tol.max_fix_gap_s)
    ty = interp_gapped(tr.t, tr.y, g.t, tol.max_fix_gap_s)
    ok = np.isfinite(tx) & np.isfinite(ty)
    if ok.sum() < 4:
        return _na(s, "GPS and truth do not overlap in time")
    src = np.column_stack([tx[ok], ty[ok]])
    dst = np.column_stack([g.x[ok], g.y[ok]])
    d = dst - src
    off = float(np.hypot(*d.mean(0)))
    rms = float(np.sqrt((d ** 2).sum(1).mean()))
    fig = {"offset_m": off, "rms_m": rms, "fixes": float(ok.sum())}
    if rms == 0.0:
        return Check(s, PASS, "GPS fixes are the truth's own samples (one source)", fig)
    extent = float(np.sqrt(((src - src.mean(0)) ** 2).sum(1).mean()))
    if extent >= tol.min_extent_m:
        sc, rot, _, res = similarity_2d(src, dst)
        fig.update(scale=sc, rotation_deg=float(np.degrees(rot)), fit_rms_m=res)
    tests = (("offset", off, tol.gps_truth_offset_warn_m, tol.gps_truth_offset_fail_m, " m"),
             ("RMS", rms, tol.gps_truth_rms_warn_m, tol.gps_truth_rms_fail_m, " m"),
             ("rotation", abs(fig.get("rotation_deg", 0.0)), tol.rot_warn_deg, tol.rot_fail_deg,
              " deg"),
             ("scale error", abs(fig.get("scale", 1.0) - 1), tol.truth_scale_warn,
              tol.truth_scale_fail, ""))
    for verdict, i in ((FAIL, 3), (WARN, 2)):
        for t in tests:
            if t[1] > t[i]:
                return Check(s, verdict, f"GPS vs truth {t[0]} {t[1]:.3g}{t[4]}", fig)
    return Check(s, PASS, f"offset {off:.2f} m, RMS {rms:.2f} m", fig)


def fix_scatter(t: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    """Horizontal white scatter [m] of fixes: each inner fix minus the time-weighted line
    through its two neighbours, scaled to one fix's noise (var of that residual is
    (1 + w^2 + (1 - w)^2) sigma^2 per axis); robust (MAD). Motion over 0.1-0.5 s adds
    at most a*dt^2/8 (~ 1 cm). Slow, correlated GPS errors are not seen."""
    if t.size < 3:
        return float("nan")
    d1, d2 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    w = d2 / (d1 + d2)
    f = np.sqrt(1 + w ** 2 + (1 - w) ** 2)
    ex = (x[1:-1] - (w * x[:-2] + (1 - w) * x[2:])) / f
    ey = (y[1:-1] - (w * y[:-2] + (1 - w) * y[2:])) / f
    sx = 1.4826 * np.median(np.abs(ex - np.median(ex)))
    sy = 1.4826 * np.median(np.abs(ey - np.median(ey)))
    return float(np.hypot(sx, sy))


def check_gps(drive: Drive, tol: Tolerances = TOLERANCES) -> Check:
    """Scatter of the fixes [m] (:func:`fix_scatter`) against the median accuracy the
    source states [m]."""
    s = "gps"
    g = drive.gps
    if len(g) < 4:
        return _na(s, _no_reference(drive, tol))
    scatter = fix_scatter(g.t, g.x, g.y)
    fig = {"scatter_m": scatter, "fixes": float(len(g))}
    acc = None if g.accuracy is None else g.accuracy[np.isfinite(g.accuracy) & (g.accuracy > 0)]
    if acc is None or acc.size == 0:
        return _na(s, f"no stated accuracy (scatter {scatter:.2f} m)", **fig)
    stated = float(np.median(acc))
    ratio = scatter / stated
    fig.update(stated_m=stated, ratio=ratio)
    why = f"scatter {scatter:.2f} m vs stated accuracy {stated:.2f} m"
    if stated > tol.max_fix_accuracy_m:
        return Check(s, WARN, f"median stated accuracy {stated:.1f} m > "
                              f"{tol.max_fix_accuracy_m:g} m: no reference for other streams", fig)
    if ratio > tol.scatter_ratio_fail:
        return Check(s, FAIL, why, fig)
    if ratio > tol.scatter_ratio_warn:
        return Check(s, WARN, why, fig)
    return Check(s, PASS, why, fig)


def check_drive(drive: Drive, tol: Tolerances = TOLERANCES) -> Consistency:
    """Every check of :data:`STREAMS` on one drive (pure: reads the drive only)."""
    kin = gps_kinematics(drive, tol)
    checks = [check_yaw_rate(drive, kin, tol), check_ax(drive, kin, tol),
              check_yaw(drive, kin, tol), check_speed(drive, kin, tol),
              check_gps(drive, tol), check_truth(drive, tol)]
    return Consistency(drive.name, {c.stream: c for c in checks})
