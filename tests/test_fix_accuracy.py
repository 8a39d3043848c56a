"""Fix accuracy in: ``GpsStream.accuracy`` (per-axis 1-sigma [m]) from every source, the
degradation profiles' stated sigma, and its way into ``Predictor.observe_gps(sigma=)``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_loader_rosbag import _Msgs, _ns, _trajectory, _write_bag

from scenarios import loaders
from scenarios.degrade import (
    CONSUMER_UNDERSTATEMENT,
    degrade_gps,
    interpolate_truth,
    stated_sigma_m,
    true_sigma_m,
)
from scenarios.drive import TruthStream

KITTI_SMALL = "2011_09_26/2011_09_26_drive_0001_sync"
COMMA_SEG = "b0c9d2329ad1606b_2018-08-02--08-34-47/40"


# --------------------------------------------------------------------------- real files

@pytest.mark.shared
def test_kitti_pos_accuracy_parsed(kitti_dir: Path) -> None:
    """KITTI OXTS ``pos_accuracy`` (column 24 of 30) becomes gps.accuracy unchanged [m]."""
    folder = kitti_dir / KITTI_SMALL
    (d,) = loaders.load(folder)
    names = [ln.split(":")[0] for ln in (folder / "oxts/dataformat.txt").read_text().splitlines()
             if ln.strip()]
    col = names.index("pos_accuracy")
    files = sorted((folder / "oxts/data").glob("*.txt"))
    raw = np.array([float(f.read_text().split()[col]) for f in files])
    assert d.gps.accuracy is not None and d.gps.accuracy.shape == d.gps.t.shape
    np.testing.assert_array_equal(d.gps.accuracy, raw)
    # an RTK-corrected OXTS solution: centimetre to decimetre level, all stated
    assert np.all(np.isfinite(d.gps.accuracy)) and np.all(d.gps.accuracy > 0)
    assert 0.005 < float(np.median(d.gps.accuracy)) < 1.0
    np.testing.assert_array_equal(d.truth.accuracy, d.gps.accuracy)


@pytest.mark.shared
def test_comma2k19_layout_has_no_fix_accuracy(comma_dir: Path) -> None:
    """comma2k19's u-blox fixes carry no accuracy: ``live_gnss_ublox`` has exactly the six
    columns lat, lon, speed, utc_ms, alt, bearing (checked on the real file), so the
    loader states none (None), never an invented one."""
    seg = comma_dir / COMMA_SEG
    with open(seg / "processed_log/GNSS/live_gnss_ublox/value", "rb") as fh:
        v = np.load(fh, allow_pickle=False)
    assert v.ndim == 2 and v.shape[1] == 6
    assert np.all(np.abs(v[:, 0] - 37.7) < 0.1) and np.all(np.abs(v[:, 1] + 122.5) < 0.1)
    assert np.all((v[:, 2] > 7.0) & (v[:, 2] < 21.0))  # speed [m/s], not an accuracy
    (d,) = loaders.load(comma_dir)
    assert d.gps.accuracy is None


# --------------------------------------------------------------------------- ROS NavSatFix

def _fix_bag(tmp_path: Path, cov_type: int, var_e: float, var_n: float) -> Path:
    tr = _trajectory()
    m = _Msgs(False)
    msgs = []
    for i, t in enumerate(tr["tg"]):
        fix = m.navsatfix(_ns(t), float(tr["lat"][i]), float(tr["lon"][i]), cov_type=cov_type)
        cov = np.zeros(9)
        cov[0], cov[4], cov[8] = var_e, var_n, 25.0
        fix.position_covariance = cov
        msgs.append(("/fix", "sensor_msgs/msg/NavSatFix", _ns(t) + 1_000_000, fix))
    return _write_bag(tmp_path / f"fix{cov_type}", "mcap", msgs)


@pytest.mark.parametrize("cov_type", [1, 2, 3])  # APPROXIMATED, DIAGONAL_KNOWN, KNOWN
def test_navsatfix_covariance_to_per_axis_sigma(tmp_path: Path, cov_type: int) -> None:
    """sigma = sqrt of the mean of the east and north variances (the up variance ignored)."""
    (d,) = loaders.load(_fix_bag(tmp_path, cov_type, var_e=1.0, var_n=9.0))
    np.testing.assert_allclose(d.gps.accuracy, math.sqrt(5.0))


def test_navsatfix_unknown_covariance_is_none(tmp_path: Path) -> None:
    (d,) = loaders.load(_fix_bag(tmp_path, 0, var_e=1.0, var_n=9.0))  # COVARIANCE_TYPE_UNKNOWN
    assert d.gps.accuracy is None


# --------------------------------------------------------------------------- CSV column

def test_csv_accuracy_column(tmp_path: Path) -> None:
    p = tmp_path / "drive.csv"
    rows = ["stream,t,x,y,accuracy"]
    rows += [f"gps,{0.2 * i:.1f},{2.0 * i},0.0,{0.5 if i % 2 else 'nan'}" for i in range(20)]
    p.write_text("\n".join(rows) + "\n")
    (d,) = loaders.load(p)
    acc = d.gps.accuracy
    assert acc is not None
    np.testing.assert_array_equal(acc[1::2], 0.5)
    assert np.all(np.isnan(acc[0::2]))


# --------------------------------------------------------------------------- degradation

def _truth(duration: float = 600.0) -> TruthStream:
    t = np.arange(0.0, duration, 0.01)
    return TruthStream(t, 10.0 * t, 50.0 * np.sin(t / 10.0))


def test_profiles_state_their_sigma() -> None:
    tr = _truth()
    assert degrade_gps(tr, "none", seed=3).accuracy is None
    assert stated_sigma_m("none") is None
    for profile, stated in (("rtk", 0.02), ("consumer", 0.5)):
        g = degrade_gps(tr, profile, seed=3)
        assert stated_sigma_m(profile) == stated
        np.testing.assert_array_equal(g.accuracy, stated)


def test_rtk_states_the_truth_consumer_understates() -> None:
    """The measured per-axis error std: rtk matches its stated 0.02 m; consumer's is
    sqrt(0.5^2 + 1^2) = 1.118 m, 2.24x its stated 0.5 m, while its fix-to-fix (white)
    error matches what it states."""
    tr = _truth(3000.0)
    for profile in ("rtk", "consumer"):
        errs = []
        for seed in range(4):
            g = degrade_gps(tr, profile, seed=seed)
            x, y = interpolate_truth(tr, g.t)
            errs.append(np.column_stack([g.x - x, g.y - y]))
        e = np.concatenate(errs)
        sd = e.std(axis=0)
        assert np.allclose(sd, true_sigma_m(profile), rtol=0.15), (profile, sd)
        if profile == "rtk":
            assert true_sigma_m("rtk") == stated_sigma_m("rtk")
        else:
            assert sd.mean() / stated_sigma_m("consumer") == pytest.approx(
                CONSUMER_UNDERSTATEMENT, rel=0.15)
            step = np.concatenate([np.diff(x, axis=0) for x in errs]) / math.sqrt(2.0)
            assert np.allclose(step.std(axis=0), 0.5, rtol=0.1)
