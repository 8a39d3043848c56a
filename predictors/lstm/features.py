"""The network's 6 input features per grid sample, and the way back to world metres.

Layout ``[batch, 8, 6]`` (time-major; the paper writes it [Nb, 6, 8]), columns
``FEATURES = (dx, dy, ax, ay, yaw, t)``:

- dx, dy [m]: displacement from the previous grid sample (first row 0);
- ax, ay [m/s^2]: IMU acceleration rotated vehicle -> world with the yaw,
  ``R(yaw) = [[cos, -sin], [sin, cos]]`` (world ax = cos*ax - sin*ay, ay = sin*ax + cos*ay);
- yaw [rad];
- t [s]: 0, 0.2, ..., 1.4 (time since the window's first sample).

Row 0's dx, dy have no previous sample and are 0 in the paper's layout. A model whose
model.json sets ``"fix_offset": true`` gets there instead the newest fix minus the newest
grid point [m] (same frame as dx, dy): how far the fix itself lies from the cubic that
resampled it, the one thing the grid cannot show (the fit smooths the newest fix away).

Two frames (``model.json["frame"]``):

- ``"world"``: the paper's layout as written: dx, dy, ax, ay in the local ENU frame,
  yaw the absolute angle wrapped to (-pi, pi].
- ``"heading"`` (default, our documented change): everything expressed in the heading
  frame of the window's newest sample, so the network is rotation invariant and learns
  from little data. dx, dy are rotated by ``-psi_ref`` (``psi_ref`` = heading of the
  fitted GPS curve at the newest fix); ax, ay are rotated to world with each sample's
  yaw and back with the newest sample's yaw (a constant yaw-sensor offset cancels);
  yaw is relative to the newest sample (unwrapped, so no jump at +-pi). The predicted
  displacement is rotated back by ``+psi_ref``. Still 6 features.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors.lstm.resample import DT, N_STEPS

FEATURES = ("dx", "dy", "ax", "ay", "yaw", "t")
N_FEATURES = len(FEATURES)
FRAMES = ("heading", "world")
#: ``"speed"``-form models (:mod:`posbench.predictors.lstm.model`): added to the window's mean grid
#: step length [m] before the displacements are divided by it (standstill-safe)
SPEED_EPS_M = 0.02


def rotate(x: np.ndarray, y: np.ndarray, ang: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Rotate vectors (x, y) counter-clockwise by ``ang`` [rad]: R(ang) @ (x, y)."""
    c, s = np.cos(ang), np.sin(ang)
    return c * x - s * y, s * x + c * y


def vehicle_to_world(
    ax: np.ndarray, ay: np.ndarray, yaw: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle-frame acceleration (x fwd, y left) [m/s^2] -> world (ENU) with yaw [rad]."""
    return rotate(ax, ay, yaw)


def wrap(a: np.ndarray) -> np.ndarray:
    """Angles wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2 * np.pi)


def time_feature(n: int = N_STEPS) -> np.ndarray:
    """0, 0.2, ... [s] for n samples."""
    return np.arange(n) * DT


def compute_features(
    pos: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
    yaw: np.ndarray,
    psi_ref: np.ndarray | float,
    frame: str = "heading",
    anchor: int = N_STEPS - 1,
    out: np.ndarray | None = None,
    fix_xy: np.ndarray | None = None,
) -> np.ndarray:
    """Features (..., n, 6) for grid samples with any leading batch shape.

    Args:
        pos: positions (..., n, 2) [m, ENU].
        ax, ay: vehicle-frame acceleration (..., n) [m/s^2].
        yaw: yaw (..., n) [rad], unwrapped along the last axis.
        psi_ref: (...) heading [rad] of the fitted GPS curve at the anchor (heading frame).
        frame: ``"heading"`` or ``"world"``.
        anchor: index of the newest input sample (the frame's origin); 7 for 8 inputs.
        out: optional preallocated output array.
        fix_xy: (..., 2) newest fix [m, ENU] or None: row 0's dx, dy become the fix minus
            the anchor sample (the ``fix_offset`` layout, see the module doc).
    """
    n = pos.shape[-2]
    if out is None:
        out = np.empty(pos.shape[:-2] + (n, N_FEATURES))
    dxy = np.zeros(pos.shape)
    dxy[..., 1:, :] = pos[..., 1:, :] - pos[..., :-1, :]
    if fix_xy is not None:
        dxy[..., 0, :] = fix_xy - pos[..., anchor, :]
    awx, awy = vehicle_to_world(ax, ay, yaw)
    if frame == "heading":
        ref = np.asarray(psi_ref)[..., None]
        out[..., 0], out[..., 1] = rotate(dxy[..., 0], dxy[..., 1], -ref)
        yaw_a = yaw[..., anchor : anchor + 1]
        out[..., 2], out[..., 3] = rotate(awx, awy, -yaw_a)
        out[..., 4] = yaw - yaw_a
    elif frame == "world":
        out[..., 0], out[..., 1] = dxy[..., 0], dxy[..., 1]
        out[..., 2], out[..., 3] = awx, awy
        out[..., 4] = wrap(yaw)
    else:
        raise ValueError(f"unknown frame {frame!r}; choose one of {FRAMES}")
    out[..., 5] = time_feature(n)
    return out


_T = time_feature()


def features_one(
    pos: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
    yaw: np.ndarray,
    psi_ref: float,
    frame: str,
    out: np.ndarray,
    fix_xy: tuple[float, float] | None = None,
) -> np.ndarray:
    """:func:`compute_features` for one window of 8 samples (the runtime's hot path, ~4x
    fewer numpy calls); writes into ``out`` (8, 6) and returns it. Equal to
    ``compute_features`` (tested)."""
    d0 = pos[1:, 0] - pos[:-1, 0]
    d1 = pos[1:, 1] - pos[:-1, 1]
    o0 = o1 = 0.0
    if fix_xy is not None:
        o0, o1 = fix_xy[0] - float(pos[-1, 0]), fix_xy[1] - float(pos[-1, 1])
    if frame == "heading":
        c, s = math.cos(psi_ref), math.sin(psi_ref)
        out[1:, 0] = c * d0 + s * d1
        out[1:, 1] = c * d1 - s * d0
        out[0, 0], out[0, 1] = c * o0 + s * o1, c * o1 - s * o0
        rel = yaw - yaw[-1]
    elif frame == "world":
        out[1:, 0] = d0
        out[1:, 1] = d1
        out[0, 0], out[0, 1] = o0, o1
        rel = yaw
    else:
        raise ValueError(f"unknown frame {frame!r}; choose one of {FRAMES}")
    cr, sr = np.cos(rel), np.sin(rel)
    out[:, 2] = cr * ax - sr * ay
    out[:, 3] = sr * ax + cr * ay
    out[:, 4] = rel if frame == "heading" else wrap(yaw)
    out[:, 5] = _T
    return out


def displacement_to_world(
    dxy: np.ndarray, psi_ref: np.ndarray | float, frame: str = "heading"
) -> np.ndarray:
    """A predicted displacement (..., 2) in the feature frame -> world metres (..., 2)."""
    if frame == "world":
        return np.asarray(dxy, dtype=float)
    x, y = rotate(dxy[..., 0], dxy[..., 1], psi_ref)
    return np.stack([x, y], axis=-1)


def gps_substitute_imu(
    coef: np.ndarray, scale: float | np.ndarray, s: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stand-ins for a missing IMU from the GPS position cubic(s).

    ``coef`` (..., 4, 2) in s = (t - t_end) / scale, evaluated at scaled times s (..., n).
    Returns vehicle-frame (ax, ay) [m/s^2] from the curve's second derivative and the
    curve's heading [rad, unwrapped] as yaw, each (..., n).
    """
    sc = np.asarray(scale, dtype=float)[..., None]
    c1 = coef[..., 1, None, :]
    c2 = coef[..., 2, None, :]
    c3 = coef[..., 3, None, :]
    ss = s[..., None]
    v = ((3 * c3 * ss + 2 * c2) * ss + c1) / sc[..., None]
    a = (6 * c3 * ss + 2 * c2) / (sc[..., None] ** 2)
    yaw = np.unwrap(np.arctan2(v[..., 1], v[..., 0]), axis=-1)
    axv, ayv = rotate(a[..., 0], a[..., 1], -yaw)
    return axv, ayv, yaw
