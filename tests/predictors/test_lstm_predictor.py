"""LstmPredictor (bundled model) and AuthorsLstmPredictor: streaming behaviour."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from posbench.predictors.lstm.predictor import LstmPredictor, bundled_model
from posbench.scenarios.errors import DataError

V = 10.0
W = 0.1  # rad/s: a gentle left curve, radius 100 m


def _truth(t: float) -> tuple[float, float]:
    r = V / W
    return r * math.sin(W * t), r - r * math.cos(W * t)


def _feed(
    p: LstmPredictor,
    t0: float,
    t1: float,
    fixes: bool = True,
    imu_ay: float = V * W,
    rng: np.random.Generator | None = None,
) -> None:
    """IMU at 50 Hz and (optionally) fixes every 0.2 s, in time order, on the curve."""
    ti = np.round(np.arange(t0, t1, 0.02), 6)
    for t in ti:
        p.observe_imu(float(t) + 0.001, 0.0, imu_ay, W * float(t), W)
        if fixes and abs((t / 0.2) - round(t / 0.2)) < 1e-6:
            x, y = _truth(float(t))
            if rng is not None:
                x, y = x + rng.normal(0, 0.02), y + rng.normal(0, 0.02)
            p.observe_gps(float(t), x, y)


def test_runtime_does_not_import_torch() -> None:
    code = (
        "import sys; import posbench.predictors.lstm.predictor, posbench.predictors.lstm.authors; "
        "p = posbench.predictors.lstm.predictor.LstmPredictor(); p.observe_gps(0.0, 0.0, 0.0); "
        "print('torch' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert out.stdout.strip() == "False"


def test_bundled_model_is_small_and_described() -> None:
    path = bundled_model()
    assert path.is_file() and path.stat().st_size < 2_000_000
    p = LstmPredictor()
    assert p.frame == "heading"
    assert "kitti" not in str(p.info["command"]).lower()
    assert p.info["data"]["val_drives"]


def test_predicts_along_a_curve() -> None:
    p = LstmPredictor()
    assert p.position_at(0.0) == (pytest.approx(math.nan, nan_ok=True),) * 2
    _feed(p, 0.0, 10.0, rng=np.random.default_rng(0))
    assert p.steps > 30
    for dt in (0.05, 0.1, 0.15, 0.2):
        t = 9.8 + dt
        err = math.dist(p.position_at(t), _truth(t))
        assert err < 0.15, (dt, err)


def test_startup_before_two_seconds_extrapolates_a_line() -> None:
    p = LstmPredictor()
    p.observe_gps(0.0, 0.0, 0.0)
    assert p.position_at(0.1) == (0.0, 0.0)
    p.observe_gps(0.2, 2.0, 0.0)
    p.observe_gps(0.4, 4.0, 0.0)
    x, y = p.position_at(0.5)
    assert x == pytest.approx(5.0) and y == pytest.approx(0.0, abs=1e-9)
    assert p.steps == 0


def test_dropout_feedback_loop_bridges_with_real_imu() -> None:
    preds = {}
    for ay in (V * W, -V * W):
        p = LstmPredictor()
        _feed(p, 0.0, 6.01)  # last fix at 6.0
        last_steps = p.steps
        track = []
        t = 6.0
        _feed_t = 6.02
        while t < 9.0:
            t = round(t + 0.05, 6)
            while _feed_t <= t:  # the real IMU keeps arriving; no fixes
                p.observe_imu(
                    _feed_t + 0.001,
                    0.0,
                    ay,
                    W * _feed_t if ay > 0 else W * 6.0 - W * (_feed_t - 6.0),
                    W if ay > 0 else -W,
                )
                _feed_t = round(_feed_t + 0.02, 6)
            track.append(p.position_at(t))
        track = np.array(track)
        assert np.isfinite(track).all()
        # one feedback step per 0.2 s after the prediction horizon (6.2 s)
        assert p.bridge_steps == pytest.approx((9.0 - 6.2) / 0.2, abs=1)
        assert p.steps - last_steps == p.bridge_steps
        # smooth: 0.05 s increments near v * 0.05 = 0.5 m, no jumps
        step = np.linalg.norm(np.diff(track, axis=0), axis=1)
        assert step.max() < 0.8 and step.min() > 0.2
        preds[ay] = track
    # after 3 s without fixes it stays closer to the curving truth than a straight-line
    # (constant velocity) extrapolation from the last fix, off by r (1 - cos(0.3)) = 4.5 m
    cv_err = V / W * (1 - math.cos(W * 3.0))
    assert math.dist(preds[V * W][-1], _truth(9.0)) < cv_err
    # the IMU is used: curving right instead of left changes the bridged track
    assert np.linalg.norm(preds[V * W][-1] - preds[-V * W][-1]) > 0.1


def test_standstill_holds_position() -> None:
    p = LstmPredictor()
    _feed(p, 0.0, 5.01)
    p.observe_speed(5.01, 0.0)
    held = p.position_at(5.05)
    assert p.position_at(5.5) == held
    assert p.position_at(9.0) == held
    p.observe_speed(9.01, 5.0)
    assert p.position_at(9.05) != held


def test_lbfgs_fit_option_agrees_with_closed_form() -> None:
    a, b = LstmPredictor(), LstmPredictor(fit="lbfgs")
    rng = np.random.default_rng(3)
    _feed(a, 0.0, 4.01, rng=rng)
    _feed(b, 0.0, 4.01, rng=np.random.default_rng(3))
    assert math.dist(a.position_at(4.1), b.position_at(4.1)) < 1e-3


def test_bad_model_path_is_a_data_error(tmp_path) -> None:
    with pytest.raises(DataError):
        LstmPredictor(str(tmp_path / "missing.onnx"))


def test_authors_needs_a_model() -> None:
    from posbench.predictors.lstm.authors import AuthorsLstmPredictor

    with pytest.raises(DataError, match="--model PATH"):
        AuthorsLstmPredictor()


@pytest.mark.shared
def test_authors_model_on_aslan_windows(authors_models_dir, aslan_dir) -> None:
    from posbench.predictors.lstm.authors import AuthorsLstmPredictor
    from posbench.predictors.lstm.resample import centred_cubic_batch
    from posbench.scenarios.loaders import load

    drive = load(aslan_dir / "aslan-20220409114513.pickle")[0]
    g, imu = drive.gps, drive.imu
    xy = np.stack([g.x, g.y], 1)
    for name in ("gps_interpolation_model2.onnx", "gps_interpolation_model3.onnx"):
        p = AuthorsLstmPredictor(str(authors_models_dir / name))
        j = 0
        errs = []
        for i in range(200):
            while j < len(imu) and imu.t[j] <= g.t[i]:
                p.observe_imu(imu.t[j], imu.ax[j], imu.ay[j], imu.yaw[j], math.nan)
                j += 1
            p.observe_gps(g.t[i], g.x[i], g.y[i])
            if p.steps and i > 50:
                ref, ok = centred_cubic_batch(g.t, xy, np.array([g.t[i] + 0.2]))
                if ok[0]:
                    errs.append(math.dist(p.position_at(g.t[i] + 0.2), ref[0]))
        errs = np.array(errs)
        assert errs.size > 100 and np.isfinite(errs).all()
        assert np.median(errs) < 1.0 and np.percentile(errs, 90) < 2.0, (name, np.median(errs))


def test_standstill_hold_follows_the_newest_fixes() -> None:
    """At standstill (wheel speed 0) the held position is the mean of the newest fixes, so a
    slow creep of the receiver (truth drift) is followed instead of a stale first estimate."""
    p = LstmPredictor()
    rng = np.random.default_rng(0)
    t = 0.0
    for _ in range(40):  # 8 s of driving at 5 m/s, then a stop
        p.observe_imu(t, 0.0, 0.0, 0.0, 0.0)
        p.observe_speed(t, 5.0)
        p.observe_gps(t, 5.0 * t, 0.0)
        t += 0.2
    x_stop = 5.0 * (t - 0.2)
    for k in range(100):  # 20 s at standstill while the fixes creep 0.5 m north
        creep = 0.5 * k / 99
        p.observe_speed(t, 0.0)
        p.observe_gps(t, x_stop + rng.normal(0, 0.02), creep + rng.normal(0, 0.02))
        x, y = p.position_at(t + 0.2)
        t += 0.2
    assert abs(x - x_stop) < 0.05
    assert abs(y - 0.5) < 0.05  # the mean of the newest 5 fixes lags the creep by ~1 cm
