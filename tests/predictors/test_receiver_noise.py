"""A receiver's error in two parts (white fix to fix, slow the rest of what it states):
the split itself, its place in the filters' covariance, white receivers unchanged, and a
receiver whose error is slow: scored against its own fixes and against its truth, kf and
ekf hold against constant velocity and their 95 % ellipses cover the truth (issue 35).
Drives are synthetic; nothing here is tuned to a recording."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from reference_filters.banks import member_bank
from reference_filters.ctra_ekf import CtraEkf
from reference_filters.linear_kalman import LinearKalman

from posbench.config import RunConfig
from posbench.predictors.kalman.gnss_noise import GnssNoise, white_share
from posbench.predictors.kalman.kf import KalmanBank
from posbench.replay.runner import run
from posbench.scenarios.degrade import draw_fix_times, gps_noise, interpolate_truth
from posbench.scenarios.drive import Drive, GpsStream
from posbench.scenarios.synthetic import generate_drive

#: chi-square (2 dof) 95 % point: a 2-D error inside the 95 % ellipse has NEES below it
CHI2_2_95 = 5.991


def fixes(t: np.ndarray, x: np.ndarray, y: np.ndarray, est: GnssNoise) -> None:
    for ti, xi, yi in zip(t.tolist(), x.tolist(), y.tolist(), strict=True):
        est.observe(ti, xi, yi)


def test_white_share_is_continuous_and_keeps_a_white_receiver_white():
    assert white_share(1.3) == 1.0
    assert white_share(0.3) == 1.0
    assert white_share(0.05) == pytest.approx(0.05)
    assert white_share(0.1) == pytest.approx(0.1)
    eps = 1e-9
    for r in (0.1, 0.3):
        assert white_share(r - eps) == pytest.approx(white_share(r + eps), abs=1e-6)
    r = np.linspace(0.0, 1.0, 101)
    assert np.all(np.diff([white_share(v) for v in r]) >= 0.0)


def straight_fixes(white_sd: float, slow_sd: float, seed: int, n: int = 300):
    """Fixes of a vehicle at 10 m/s east, every 0.2 s, with white and Gauss-Markov (30 s)
    noise per axis [m]."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.2
    e = gps_noise(t, rng, white_sd, slow_sd, 30.0)
    return t, 10.0 * t + e[:, 0], 5.0 + e[:, 1]


def test_a_white_receiver_stays_white():
    est = GnssNoise(0.3, 1.0, 30.0)
    fixes(*straight_fixes(0.5, 0.0, seed=1), est)
    assert est.parts(0.5) == (0.25, 0.0)


def test_a_smooth_receiver_is_weighed_by_its_white_part():
    est = GnssNoise(0.3, 1.0, 30.0)
    fixes(*straight_fixes(0.05, 1.0, seed=2), est)
    white, slow = est.parts(1.0)
    assert 0.03**2 < white < 0.08**2
    assert white + slow == pytest.approx(1.0)
    assert est.weigh(1.0) == white and est.slow_var == slow
    # a fix that states nothing: the white estimate, no slow part (nothing is known of it)
    assert est.parts(None) == (est.estimate, 0.0)
    # no split asked for: a statement is all white
    off = GnssNoise(0.3, 1.0, 30.0, split=False)
    fixes(*straight_fixes(0.05, 1.0, seed=2), off)
    assert off.parts(1.0) == (1.0, 0.0)


@pytest.mark.parametrize("cls", [LinearKalman, CtraEkf])
def test_the_slow_part_is_added_to_the_covariance_and_not_to_the_weight(cls):
    t, x, y = straight_fixes(0.05, 1.0, seed=3)
    split, plain = cls(fix_noise_memory=30.0), cls(fix_noise_memory=30.0, gps_split=False)
    for f in (split, plain):
        for ti, xi, yi in zip(t.tolist(), x.tolist(), y.tolist(), strict=True):
            f.observe_gps(ti, xi, yi, 1.0)
    assert 0.9 < split.slow_variance < 1.0
    assert plain.slow_variance == 0.0
    assert split.fix_variance(1.0) < 0.01 and plain.fix_variance(1.0) == 1.0
    q = float(t[-1]) + 0.2
    P = split.covariance_at(q)
    assert P is not None
    # the filter's own part is far smaller than the slow part: it follows the fixes
    own = P - split.slow_variance * np.eye(2)
    assert 0.0 < own[0, 0] < 0.05 and 0.0 < own[1, 1] < 0.05


def test_the_bank_scales_its_members_own_covariance_not_the_receivers_slow_part():
    t, x, y = straight_fixes(0.05, 1.0, seed=4)
    one, four = KalmanBank(cov_scale=1.0), KalmanBank(cov_scale=4.0)
    for b in (one, four):
        for ti, xi, yi in zip(t.tolist(), x.tolist(), y.tolist(), strict=True):
            b.observe_gps(ti, xi, yi, 1.0)
    q = float(t[-1]) + 0.2
    P1, P4 = one.covariance_at(q), four.covariance_at(q)
    assert P1 is not None and P4 is not None
    slow = one.slow_variance
    assert slow > 0.9
    own = P1 - slow * np.eye(2)
    np.testing.assert_allclose(P4, 4.0 * own + slow * np.eye(2), rtol=1e-12)


def slow_receiver_drive(seed: int, route: str) -> Drive:
    """A synthetic drive whose receiver's error is 5 cm white plus a 1 m Gauss-Markov error
    of 30 s correlation time per axis, and which states 1 m (its total, rounded)."""
    d = generate_drive(seed=seed, route=route, duration_s=240.0)
    rng = np.random.default_rng(seed)
    tr = d.truth
    assert tr is not None
    tf = draw_fix_times(float(tr.t[0]), float(tr.t[-1]), rng, "aslan")
    x, y = interpolate_truth(tr, tf)
    e = gps_noise(tf, rng, 0.05, 1.0, 30.0)
    gps = GpsStream(tf, x + e[:, 0], y + e[:, 1], None, None, np.full(tf.size, 1.0))
    meta = replace(d.meta, name=f"slow-{route}-s{seed}", source=f"test:slow:{route}:{seed}")
    return Drive(meta=meta, gps=gps, imu=d.imu, speed=d.speed, truth=tr)


def scored(drives: list[Drive]) -> pd.DataFrame:
    cfg = RunConfig(predictors=("cv", "kf", "ekf"), gps_profile="native")
    runs = run(drives, cfg, workers=1)
    t = pd.concat([r.traces for r in runs], ignore_index=True)
    return t[np.isfinite(t.error_m) & ~t.warmup.astype(bool)]


def coverage95(t: pd.DataFrame) -> float:
    ex, ey = (t.x - t.x_ref).to_numpy(), (t.y - t.y_ref).to_numpy()
    a, b, d = t.cov_xx.to_numpy(), t.cov_xy.to_numpy(), t.cov_yy.to_numpy()
    nees = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / (a * d - b * b)
    return float(np.mean(nees <= CHI2_2_95))


@pytest.fixture(scope="module")
def slow_drives() -> list[Drive]:
    return [
        slow_receiver_drive(seed, route)
        for seed, route in ((3101, "mixed"), (3102, "turns"), (3103, "stop_and_go"))
    ]


@pytest.mark.slow
def test_a_slow_receiver_against_its_own_fixes_kf_and_ekf_hold_against_cv(slow_drives):
    own = scored([replace(d, truth=None) for d in slow_drives])
    for kind in ("future", "now"):
        m = own[own.kind == kind].groupby("predictor").error_m.mean()
        assert m["kf"] <= m["cv"], (kind, m.to_dict())
        assert m["ekf"] <= m["cv"], (kind, m.to_dict())


@pytest.mark.slow
def test_a_slow_receiver_against_its_truth_kf_and_ekf_hold_and_cover(slow_drives):
    truth = scored(slow_drives)
    for kind in ("future", "now"):
        k = truth[truth.kind == kind]
        m = k.groupby("predictor").error_m.mean()
        assert m["kf"] <= m["cv"], (kind, m.to_dict())
        assert m["ekf"] <= m["cv"], (kind, m.to_dict())
        for p in ("kf", "ekf"):
            c = coverage95(k[k.predictor == p])
            assert 0.88 <= c <= 0.98, (kind, p, c)


def test_white_receivers_come_out_as_before():
    """consumer (states its white part) and rtk fixes: the split changes no answer."""
    from posbench.scenarios.degrade import degrade_gps

    d = generate_drive(seed=3201, route="turns", duration_s=90.0)
    assert d.truth is not None
    for profile in ("rtk", "consumer"):
        drive = replace(d, gps=degrade_gps(d.truth, profile, seed=3201))
        answers = []
        for split in (True, False):
            bank = KalmanBank(gps_split=split)
            out = []
            g = drive.gps
            assert g.accuracy is not None
            for ti, xi, yi, si in zip(
                g.t.tolist(), g.x.tolist(), g.y.tolist(), g.accuracy.tolist(), strict=True
            ):
                bank.observe_gps(ti, xi, yi, si)
                out.append(bank.position_at(ti + 0.2))
            answers.append(np.array(out))
        np.testing.assert_array_equal(answers[0], answers[1])
        assert not math.isnan(float(answers[0][-1, 0]))


# -- the bank's shadows: copies that answer as the members would, and outages ----------


def prepared(drive: Drive, dropouts: str = "none"):
    from posbench.replay.prepare import prepare_drive

    return prepare_drive(drive, RunConfig(dropouts=dropouts, gps_profile="rtk"))


@pytest.mark.parametrize("bank_cls", ["kf", "ekf"])
def test_a_copy_of_the_members_answers_exactly_as_they_do(bank_cls):
    """The copies a bank's shadows run (``copy.deepcopy`` of its members) are independent
    and exact: fed the rest of a drive, each answers as its member does, to the bit."""
    import copy

    from posbench.predictors.kalman.ekf import EkfBank
    from posbench.replay.loop import events, feed

    # the members as objects: the banks' reference (the banks themselves run them as rows)
    cls = KalmanBank if bank_cls == "kf" else EkfBank
    bank = member_bank(cls(horizons_s=()))
    evs = events(prepared(generate_drive(seed=3301, route="turns", duration_s=60.0)))
    half = len(evs) // 2
    feed(bank, evs, 0.2, stop=half)
    copies = copy.deepcopy(bank.members)
    for original, clone in zip(bank.members, copies, strict=True):
        a = feed(original, evs, 0.2, start=half)
        b = feed(clone, evs, 0.2, start=half)
        assert a == b and len(a) > 100


def late_imu_outage_drives() -> list:
    """Drives with outages of 0.5-5 s whose IMU is stamped 0.4 s late (as some of the
    paper's routes measure): one fix ahead a fixes-only member predicts best, yet over a
    gap of seconds the late IMU still bridges far better than no IMU at all."""
    out = []
    for seed, route in ((3401, "mixed"), (3402, "turns")):
        d = generate_drive(seed=seed, route=route)
        assert d.imu is not None
        d = replace(d, imu=replace(d.imu, t=d.imu.t + 0.4), speed=None)
        out.append((d, prepared(d, dropouts="outages")))
    return out


def far_errors(bank_factory, drives) -> dict[str, float]:
    """Mean error [m] of the bank and of each of its members run alone, over the "now"
    queries more than 1 s after the newest fix."""
    import copy

    from posbench.replay.loop import replay

    err: dict[str, list[np.ndarray]] = {}
    for d, prep in drives:
        bank = bank_factory()
        source = member_bank(bank)
        members = [copy.deepcopy(m) for m in source.members]  # type: ignore[attr-defined]
        tq = prep.now.t_query
        ref = np.column_stack(interpolate_truth(d.truth, tq))
        gap = tq - prep.gps.t[np.maximum(np.searchsorted(prep.gps.t, tq, "right") - 1, 0)]
        far = gap > 1.0
        assert far.sum() > 50
        for label, p in [("bank", bank)] + list(zip(bank.labels, members, strict=True)):
            r = replay(p, prep, 0.2)
            err.setdefault(label, []).append(np.hypot(*(r.now_xy[far] - ref[far]).T))
    return {k: float(np.mean(np.concatenate(v))) for k, v in err.items()}


@pytest.mark.slow
@pytest.mark.parametrize("bank_cls", ["kf", "ekf"])
def test_over_an_outage_the_bank_answers_no_worse_than_its_best_member(bank_cls):
    """Over the gaps the bank answers with the member its shadows found best there: within
    10 % of the best member's mean error (measured: kf 0.583 m = its best member,
    ekf 1.688 m against 1.669), where the one-fix-ahead choice alone is off by 4.1 m and
    4.6 m."""
    from posbench.predictors.kalman.ekf import EkfBank

    cls = KalmanBank if bank_cls == "kf" else EkfBank
    drives = late_imu_outage_drives()
    mean = far_errors(cls, drives)
    best = min(v for k, v in mean.items() if k != "bank")
    assert mean["bank"] <= 1.10 * best, mean
    one_fix = far_errors(lambda: cls(horizons_s=()), drives)["bank"]
    assert one_fix > 2.0 * best, (one_fix, mean)


def test_every_attribute_of_a_filter_is_listed_for_its_copy():
    """The copies list attributes by name (``_ATTRS``, :mod:`posbench.predictors.kalman.copying`):
    one missing would leave a shadow sharing, or lacking, a piece of its member's state."""
    from posbench.predictors.kalman.ekf import EkfBank
    from posbench.replay.loop import replay

    prep = prepared(generate_drive(seed=3501, route="mixed", duration_s=60.0), "outages")
    kb, eb = member_bank(KalmanBank()), member_bank(EkfBank())
    replay(kb, prep, 0.2)
    replay(eb, prep, 0.2)
    aided = kb.members[0]
    objects = [aided, aided.kf, aided._gnss, aided._gnss.estimator, aided._course]
    objects += [aided._bias_est, eb.members[0], eb.members[0]._gnss]
    for obj in objects:
        assert obj is not None
        missing = set(vars(obj)) - set(type(obj)._ATTRS)  # type: ignore[attr-defined]
        assert not missing, (type(obj).__name__, missing)
