"""A named ROS truth (``--topic truth=/name``) as a :class:`TruthStream` in the fixes' frame.

- ``sensor_msgs/NavSatFix`` (a second receiver, e.g. RTK beside a consumer one): projected
  like the fixes, about the same origin with the same projection, so it is in their local
  ENU frame by construction: no fit. Its stated ``position_covariance`` is kept as the
  accuracy (per-axis 1-sigma [m], ``sqrt(mean(cov[0], cov[4]))``, NaN where the covariance
  type is UNKNOWN); fixes with ``status < 0`` are skipped and counted. No yaw, no speed.
- ``geometry_msgs/PoseStamped``, ``geometry_msgs/PoseWithCovarianceStamped``,
  ``nav_msgs/Odometry`` (a ``map``, ``earth``, ENU or any other metric frame: frame names are
  not trusted): brought onto the fixes by a 2-D rigid fit over the drive
  (:mod:`posbench.scenarios.align`); a residual RMS above
  :func:`~posbench.scenarios.align.alignment_limit_m` is refused (DataError). yaw [rad] is the
  orientation's, rotated by the fit; v [m/s] the twist's (Odometry) or None; the accuracy the
  pose covariance's ``sqrt(mean(cov[0], cov[7]))`` where stated.

What was done is in ``meta.extra``: ``truth_frame``, ``truth_alignment`` (rotation [deg],
translation [m], residual RMS and limit [m], or ``fit: none`` for a NavSatFix truth).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.align import alignment_limit_m, umeyama_2d
from posbench.scenarios.cleaning import clean_index, clean_times, take
from posbench.scenarios.drive import GpsStream, TruthStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.imu_frames import wrap
from posbench.scenarios.loaders.ros_msgs import NAVSATFIX, navsat_fields, pose_fields
from posbench.scenarios.projection import to_local


def truth_fields(
    items: list, msgtype: str, topic: str, path: Path, warnings: list[str]
) -> dict[str, Any]:
    """The raw fields of a truth topic (t [ns]; lat/lon [deg] or x/y [m] in its frame)."""
    if msgtype == NAVSATFIX:
        out = navsat_fields(items, topic, path, warnings, role="truth")
        out["frames"] = sorted({str(m.header.frame_id) for _, m in items})
        out["kind"] = "navsat"
        return out
    out = pose_fields(items, msgtype, topic, path)
    out["kind"] = "pose"
    return out


def truth_stream(
    s: dict[str, Any],
    t: np.ndarray,
    gps: GpsStream,
    lat0: float,
    lon0: float,
    projection: str,
    topic: str,
    path: Path,
    extra: dict[str, Any],
    warnings: list[str],
) -> TruthStream:
    """The truth in the fixes' local frame (see the module notes).

    Args:
        s: :func:`truth_fields`' dict; ``t`` its times [s from the drive's start].
        gps: the drive's fixes (local metres about ``lat0``, ``lon0`` [deg] in ``projection``).
    Raises:
        DataError: a pose truth that cannot be aligned or whose residual is over the limit.
    """
    if s["kind"] == "navsat":
        t, c = clean_times(t, {k: s[k] for k in ("lat", "lon", "acc")}, "truth", warnings)
        x, y = to_local(c["lat"], c["lon"], lat0, lon0, projection)
        acc = c["acc"] if np.any(np.isfinite(c["acc"])) else None
        extra["truth_alignment"] = {
            "fit": "none",
            "why": f"NavSatFix projected like the fixes ({projection} about the first fix)",
        }
        return TruthStream(t, x, y, None, None, acc)
    t, idx = clean_index(t, "truth", warnings)  # yaw, v and acc may be None
    local = {k: take(s[k], idx) for k in ("x", "y", "yaw", "v", "acc")}
    aligned = align_truth(t, local, gps, topic, path, extra, warnings)
    return TruthStream(t, aligned["x"], aligned["y"], aligned["yaw"], aligned["v"], aligned["acc"])


def align_truth(
    tt: np.ndarray,
    c: dict[str, Any],
    gps: GpsStream,
    topic: str,
    path: Path,
    extra: dict[str, Any],
    warnings: list[str],
) -> dict[str, Any]:
    """Rotate and shift a truth in a local frame (x, y [m], yaw [rad] at times ``tt`` [s])
    onto the GPS fixes by a 2-D rigid fit over the fixes inside its time span."""
    inside = (gps.t >= tt[0]) & (gps.t <= tt[-1]) if tt.size else np.zeros(len(gps), bool)
    if inside.sum() < 3 or tt.size < 2:
        raise DataError(
            path,
            f"--topic truth={topic}: cannot align it to the GPS: only "
            f"{int(inside.sum())} fixes fall inside its time span",
        )
    src = np.column_stack(
        [np.interp(gps.t[inside], tt, c["x"]), np.interp(gps.t[inside], tt, c["y"])]
    )
    dst = np.column_stack([gps.x[inside], gps.y[inside]])
    rot, tr, rms = umeyama_2d(src, dst)
    acc = gps.accuracy[inside] if gps.accuracy is not None else np.empty(0)
    acc = acc[np.isfinite(acc)]
    med = float(np.median(acc)) if acc.size else None
    limit = alignment_limit_m(med)
    ang = float(np.degrees(np.arctan2(rot[1, 0], rot[0, 0])))
    fit = f"rotation {ang:+.1f} deg, translation ({tr[0]:+.1f}, {tr[1]:+.1f}) m"
    what = f"{fit}, residual RMS {rms:.2f} m over {int(inside.sum())} fixes"
    extra["truth_alignment"] = {
        "fit": "rigid-2d",
        "rotation_deg": round(ang, 3),
        "translation_m": [round(float(tr[0]), 3), round(float(tr[1]), 3)],
        "residual_rms_m": round(rms, 3),
        "limit_m": round(limit, 3),
        "fixes": int(inside.sum()),
    }
    if rms > limit:
        stated = f"3 x median stated GPS accuracy {med:.2f} m, " if med is not None else ""
        raise DataError(
            path,
            f"--topic truth={topic}: residual RMS {rms:.2f} m after aligning it "
            f"to the GPS fixes exceeds the limit {limit:.2f} m (max({stated}"
            f"5 m); {fit}): it drifts or is mis-scaled, so it is no truth",
        )
    warnings.append(
        f"truth: {topic} (frame {extra.get('truth_frame') or '?'}) aligned to the GPS "
        f"ENU frame by a 2-D rigid fit: {what} (limit {limit:.2f} m)"
    )
    xy = np.column_stack([c["x"], c["y"]]) @ rot.T + tr
    out = dict(c)
    out["x"], out["y"] = xy[:, 0], xy[:, 1]
    if c.get("yaw") is not None:
        out["yaw"] = wrap(c["yaw"] + np.radians(ang))
    return out
