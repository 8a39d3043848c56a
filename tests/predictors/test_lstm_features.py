"""Features: shapes, frames, acceleration rotation, the single-window fast path; windows."""

from __future__ import annotations

import numpy as np
import pytest

from posbench.predictors.lstm.features import (
    compute_features,
    displacement_to_world,
    features_one,
    rotate,
    vehicle_to_world,
)
from posbench.predictors.lstm.windows import drive_windows, future_from_output
from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, ImuStream, TruthStream


def _window(seed: int = 0) -> tuple:
    rng = np.random.default_rng(seed)
    pos = np.cumsum(rng.normal(0, 1, (8, 2)), axis=0) + [100.0, -50.0]
    ax, ay = rng.normal(0, 1, 8), rng.normal(0, 1, 8)
    yaw = np.cumsum(rng.normal(0, 0.1, 8)) + 3.0
    return pos, ax, ay, yaw, 0.7


def test_acceleration_rotation_hand_case() -> None:
    # yaw 90 deg (heading north): forward acceleration points north, leftward points west
    wx, wy = vehicle_to_world(np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.pi / 2)
    np.testing.assert_allclose(wx, [0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(wy, [1.0, 0.0], atol=1e-12)
    # 30 deg: world ax = cos*ax - sin*ay, world ay = sin*ax + cos*ay
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    np.testing.assert_allclose(vehicle_to_world(2.0, 1.0, np.pi / 6), (c * 2 - s, s * 2 + c))


def test_world_frame_layout() -> None:
    pos, ax, ay, yaw, psi = _window()
    f = compute_features(pos, ax, ay, yaw, psi, "world")
    assert f.shape == (8, 6)
    np.testing.assert_allclose(f[0, :2], 0.0)
    np.testing.assert_allclose(f[1:, :2], np.diff(pos, axis=0))
    wx, wy = vehicle_to_world(ax, ay, yaw)
    np.testing.assert_allclose(f[:, 2], wx)
    np.testing.assert_allclose(f[:, 3], wy)
    assert np.all(np.abs(f[:, 4]) <= np.pi)
    np.testing.assert_allclose(f[:, 5], np.arange(8) * 0.2)


def test_heading_frame_is_rotation_invariant() -> None:
    pos, ax, ay, yaw, psi = _window(1)
    f = compute_features(pos, ax, ay, yaw, psi, "heading")
    assert f[-1, 4] == 0.0
    # rotate the whole scene by 1.1 rad (and shift it): heading-frame features do not change
    a = 1.1
    px, py = rotate(pos[:, 0], pos[:, 1], a)
    g = compute_features(np.stack([px + 7, py - 3], 1), ax, ay, yaw + a, psi + a, "heading")
    np.testing.assert_allclose(f, g, atol=1e-9)
    # the last sample's forward motion is along +x of the heading frame
    straight = np.stack([np.arange(8.0) * np.cos(psi), np.arange(8.0) * np.sin(psi)], 1)
    h = compute_features(straight, ax, ay, yaw, psi, "heading")
    np.testing.assert_allclose(h[1:, :2], [[1.0, 0.0]] * 7, atol=1e-12)
    np.testing.assert_allclose(
        displacement_to_world(np.array([1.0, 0.0]), psi), [np.cos(psi), np.sin(psi)]
    )


@pytest.mark.parametrize("frame", ["heading", "world"])
def test_fast_path_equals_general(frame: str) -> None:
    pos, ax, ay, yaw, psi = _window(2)
    out = np.empty((8, 6))
    np.testing.assert_allclose(
        features_one(pos, ax, ay, yaw, psi, frame, out),
        compute_features(pos, ax, ay, yaw, psi, frame),
        atol=1e-12,
    )
    batch = compute_features(
        np.stack([pos, pos + 1]),
        np.stack([ax, ax]),
        np.stack([ay, ay]),
        np.stack([yaw, yaw]),
        np.array([psi, psi]),
        frame,
    )
    np.testing.assert_allclose(batch[1], compute_features(pos + 1, ax, ay, yaw, psi, frame))


@pytest.mark.parametrize("frame", ["heading", "world"])
def test_fix_offset_row_in_both_paths(frame: str) -> None:
    """A fix_offset model's row 0: the newest fix minus the newest grid point, in the frame of
    dx, dy (rotated by -psi in the heading frame); rows 1-7 unchanged."""
    pos, ax, ay, yaw, psi = _window(3)
    fix = pos[-1] + np.array([0.03, -0.02])
    one = features_one(pos, ax, ay, yaw, psi, frame, np.empty((8, 6)), (fix[0], fix[1]))
    gen = compute_features(pos, ax, ay, yaw, psi, frame, fix_xy=fix)
    plain = compute_features(pos, ax, ay, yaw, psi, frame)
    np.testing.assert_allclose(one, gen, atol=1e-12)
    np.testing.assert_allclose(gen[1:], plain[1:], atol=1e-12)
    ang = -psi if frame == "heading" else 0.0
    want = [0.03 * np.cos(ang) + 0.02 * np.sin(ang), 0.03 * np.sin(ang) - 0.02 * np.cos(ang)]
    np.testing.assert_allclose(gen[0, :2], want, atol=1e-12)


def _circle_drive(with_truth: bool = True) -> Drive:
    """Constant speed 10 m/s on a 50 m radius circle, fixes at irregular 0.1-0.3 s."""
    rng = np.random.default_rng(0)
    tt = np.arange(0.0, 30.0, 0.01)
    w = 10.0 / 50.0
    x, y = 50 * np.sin(w * tt), 50 - 50 * np.cos(w * tt)
    tf = np.cumsum(rng.uniform(0.1, 0.3, 140))
    tf = tf[tf < 29.0]
    gps = GpsStream(tf, 50 * np.sin(w * tf), 50 - 50 * np.cos(w * tf))
    ti = tt[::2]
    imu = ImuStream(ti, np.zeros_like(ti), np.full_like(ti, 10.0 * w), yaw=w * ti)
    truth = TruthStream(tt, x, y) if with_truth else None
    return Drive(DriveMeta("circle", "test", "test"), gps, imu, truth=truth)


@pytest.mark.parametrize("with_truth", [True, False])
def test_windows_on_a_circle(with_truth: bool) -> None:
    d = _circle_drive(with_truth)
    ws = drive_windows(d)
    assert len(ws) > 50
    assert ws.X.shape == (len(ws), 8, 6) and ws.Y.shape == (len(ws), 8, 6)
    assert np.isfinite(ws.X).all() and np.isfinite(ws.Y).all()
    # a perfect predictor (the targets) lands on the reference point
    fut = future_from_output(ws, ws.Y[:, -1, :2])
    np.testing.assert_allclose(fut, ws.truth_future, atol=1e-9)
    # heading frame: forward displacement ~ 10 m/s * 0.2 s, lateral acceleration ~ v^2/r = 2
    np.testing.assert_allclose(np.hypot(ws.X[:, 1:, 0], ws.X[:, 1:, 1]), 2.0, atol=0.01)
    np.testing.assert_allclose(ws.X[:, -1, 0], 2.0, atol=0.01)
    assert np.all(ws.X[:, 1:-1, 1] < 0)  # earlier steps came from the right of the heading
    np.testing.assert_allclose(ws.X[:, -1, 3], 2.0, atol=0.05)
    # the cubic baseline is good on a smooth circle
    assert np.linalg.norm(ws.cubic_pred - ws.truth_future, axis=1).max() < 0.05
