"""Fix accuracy in: ``GpsStream.accuracy`` (per-axis 1-sigma [m]) from every source, the
degradation profiles' stated sigma, and its way into ``Predictor.observe_gps(sigma=)``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_loader_rosbag import _Msgs, _ns, _trajectory, _write_bag

from posbench.predictors.base import Predictor, accepts_sigma
from posbench.predictors.registry import create
from posbench.replay.gps_outliers import GatedPredictor
from posbench.replay.loop import replay
from posbench.scenarios import loaders
from posbench.scenarios.degrade import (
    CONSUMER_UNDERSTATEMENT,
    degrade_gps,
    interpolate_truth,
    stated_sigma_m,
    true_sigma_m,
)
from posbench.scenarios.drive import GpsStream, TruthStream

KITTI_SMALL = "2011_09_26/2011_09_26_drive_0001_sync"
COMMA_SEG = "b0c9d2329ad1606b_2018-08-02--08-34-47/40"


# --------------------------------------------------------------------------- real files


@pytest.mark.shared
def test_kitti_pos_accuracy_parsed(kitti_dir: Path) -> None:
    """KITTI OXTS ``pos_accuracy`` (column 24 of 30) becomes gps.accuracy unchanged [m]."""
    folder = kitti_dir / KITTI_SMALL
    (d,) = loaders.load(folder)
    names = [
        ln.split(":")[0]
        for ln in (folder / "oxts/dataformat.txt").read_text().splitlines()
        if ln.strip()
    ]
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
                CONSUMER_UNDERSTATEMENT, rel=0.15
            )
            step = np.concatenate([np.diff(x, axis=0) for x in errs]) / math.sqrt(2.0)
            assert np.allclose(step.std(axis=0), 0.5, rtol=0.1)


# --------------------------------------------------------------------------- observe_gps(sigma=)


class _OldStyle(Predictor):
    """A user predictor written before fix accuracy existed: three-argument observe_gps."""

    name = "old_style"

    def reset(self) -> None:
        self.fixes: list[tuple[float, float, float]] = []

    def observe_gps(self, t: float, x: float, y: float) -> None:  # type: ignore[override]
        self.fixes.append((t, x, y))

    def position_at(self, t: float) -> tuple[float, float]:
        return self.fixes[-1][1:] if self.fixes else (math.nan, math.nan)


class _NewStyle(_OldStyle):
    name = "new_style"

    def reset(self) -> None:
        super().reset()
        self.sigmas: list[float | None] = []

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        self.fixes.append((t, x, y))
        self.sigmas.append(sigma)


def test_accepts_sigma() -> None:
    assert not accepts_sigma(_OldStyle().observe_gps)
    assert accepts_sigma(_NewStyle().observe_gps)
    assert accepts_sigma(lambda t, x, y, **kw: None)
    assert accepts_sigma(lambda t, x, y, *, sigma=None: None)
    assert not accepts_sigma(lambda t, x, y, *args: None)
    assert not accepts_sigma(getattr)  # no signature (ValueError): the old form, never a crash
    assert accepts_sigma(create("kf").observe_gps) and accepts_sigma(create("ekf").observe_gps)
    assert not accepts_sigma(create("cv").observe_gps)


def _prep(accuracy: np.ndarray | None):
    from dataclasses import replace

    from posbench.predictor_tools.contract.inputs import cut_prepared, inputs

    prep = cut_prepared(inputs().drive, 15.0)
    g = prep.gps
    return replace(prep, gps=GpsStream(g.t, g.x, g.y, g.lat, g.lon, accuracy))


def test_replay_passes_sigma_only_to_predictors_that_take_it() -> None:
    n = len(_prep(None).gps)
    acc = np.full(n, 0.7)
    acc[::3] = np.nan  # not stated
    acc[1] = 0.0  # not a usable sigma
    prep = _prep(acc)
    old, new = _OldStyle(), _NewStyle()
    r_old = replay(old, prep, 0.2)
    r_new = replay(new, prep, 0.2)
    assert len(old.fixes) == len(new.fixes) == n
    np.testing.assert_array_equal(r_old.future_xy, r_new.future_xy)
    want = [None if not (a > 0) else 0.7 for a in acc]
    assert new.sigmas == want
    # a stream without any stated accuracy: sigma=None on every fix
    new2 = _NewStyle()
    replay(new2, _prep(None), 0.2)
    assert new2.sigmas == [None] * n


def test_gate_forwards_sigma() -> None:
    old, new = GatedPredictor(_OldStyle()), GatedPredictor(_NewStyle())
    for p in (old, new):
        p.reset()
        p.observe_gps(0.0, 0.0, 0.0, sigma=0.4)
        p.observe_gps(0.2, 2.0, 0.0)
        p.observe_gps(0.4, 4.0, 0.0, sigma=0.5)
    assert len(old.inner.fixes) == 3
    assert new.inner.sigmas == [0.4, None, 0.5]
    assert accepts_sigma(old.observe_gps)  # the gate always takes it, forwards it if it can
    # the gate survives pickling with its forwarding decision
    import pickle

    c = pickle.loads(pickle.dumps(new))
    c.observe_gps(0.6, 6.0, 0.0, sigma=0.25)
    assert c.inner.sigmas[-1] == 0.25


def test_old_style_predictor_through_the_runner() -> None:
    """A three-argument user predictor keeps working in a whole run (behind the gate)."""
    from posbench.predictor_tools.contract.inputs import cut_prepared, inputs

    prep = cut_prepared(inputs().drive, 15.0)
    assert prep.gps.accuracy is not None  # the synthetic fixes state an accuracy
    p = GatedPredictor(_OldStyle())
    res = replay(p, prep, 0.2)
    assert np.isfinite(res.future_xy).all()


@pytest.mark.parametrize("name", ["kf", "ekf"])
def test_filters_use_stated_sigma_as_R(name: str) -> None:
    """A fix stating sigma is weighed exactly like a fix of a filter whose constant R is
    (gps_sigma_scale * sigma)^2; a fix stating none (None, NaN, 0) uses gps_sigma."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 20.0, 0.2)
    x = 8.0 * t + rng.normal(0, 0.5, t.size)
    y = 0.02 * t * t + rng.normal(0, 0.5, t.size)

    def answers(p: Predictor, sigmas: list) -> np.ndarray:
        p.reset()
        out = []
        for ti, xi, yi, s in zip(t, x, y, sigmas, strict=True):
            if s == "old":  # the three-argument call
                p.observe_gps(ti, xi, yi)
            else:
                p.observe_gps(ti, xi, yi, sigma=s)
            out.append(p.position_at(ti + 0.2))
        return np.asarray(out)

    const = {"fix_noise_memory": 0.0}  # unstated fixes weighed with gps_sigma, not estimated
    stated = answers(create(name, gps_sigma=0.3, gps_sigma_scale=2.0, **const), [0.5] * t.size)
    constant = answers(create(name, gps_sigma=1.0, **const), ["old"] * t.size)
    np.testing.assert_allclose(stated, constant, rtol=0, atol=1e-9)
    plain = answers(create(name, gps_sigma=0.3, **const), ["old"] * t.size)
    for missing in (None, math.nan, 0.0):
        np.testing.assert_array_equal(
            answers(create(name, gps_sigma=0.3, gps_sigma_scale=2.0, **const), [missing] * t.size),
            plain,
        )
    assert not np.allclose(stated, plain)  # the stated sigma really changes the answers
    # by default the noise of unstated fixes is estimated from them (0.5 m here), so the
    # assumed gps_sigma hardly matters: 0.05 m and 3 m give nearly the same answers
    a = answers(create(name, gps_sigma=0.05), ["old"] * t.size)
    b = answers(create(name, gps_sigma=3.0), ["old"] * t.size)
    late = slice(60, None)  # after the estimate's warm-up and the bank's memory
    assert (
        np.abs(a[late] - b[late]).max()
        < 0.1
        * np.abs(
            answers(create(name, gps_sigma=0.05, **const), ["old"] * t.size)[late]
            - answers(create(name, gps_sigma=3.0, **const), ["old"] * t.size)[late]
        ).max()
    )
    assert create(name, gps_sigma_scale=1.5).config()["gps_sigma_scale"] == 1.5
