"""GPS degradation: fix times, noise profiles, latency, dropouts."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from posbench.scenarios.degrade import (
    ASLAN_FIX_INTERVAL_QUANTILES_S,
    GPS_PROFILES,
    _quantile_table,
    degrade_gps,
    draw_fix_times,
    gauss_markov,
)
from posbench.scenarios.drive import GpsStream, TruthStream
from posbench.scenarios.dropouts import OUTAGE_LENGTHS_S, apply_dropouts, outage_windows
from posbench.scenarios.errors import DataError

# the fix-interval table, whichever measured constant is in use: {p: q} or even-p quantiles
P_IV, Q_IV = _quantile_table(ASLAN_FIX_INTERVAL_QUANTILES_S)
MAX_IV = float(Q_IV.max())


def _truth(duration: float = 200.0, hz: float = 100.0) -> TruthStream:
    t = np.arange(0.0, duration, 1.0 / hz)
    return TruthStream(t, 10.0 * t, 50.0 * np.sin(t / 10.0))


@pytest.fixture(scope="module")
def truth() -> TruthStream:
    return _truth()


def test_aslan_intervals_distribution() -> None:
    t = draw_fix_times(0.0, 2000.0, np.random.default_rng(0))
    d = np.diff(t)
    assert 0.0 <= t[0] and t[-1] <= 2000.0
    # the paper's routes (data README): median 200 ms, p5 ~101 ms, max ~400 ms
    assert abs(np.median(d) - 0.200) < 0.01
    for p in (0.05, 0.25, 0.5, 0.75, 0.95):
        assert abs(np.quantile(d, p) - np.interp(p, P_IV, Q_IV)) < 0.01
    assert Q_IV.min() - 1e-12 <= d.min() and d.max() <= MAX_IV + 1e-12
    assert t[-1] > 2000.0 - MAX_IV


def test_uniform_intervals_and_bad_spec() -> None:
    t = draw_fix_times(5.0, 500.0, np.random.default_rng(1), "uniform:0.1,0.6")
    d = np.diff(t)
    assert d.min() >= 0.1 and d.max() <= 0.6
    assert abs(d.mean() - 0.35) < 0.02
    assert t[0] >= 5.0
    for bad in ("uniform:0.6", "uniform:a,b", "uniform:0.5,0.1", "gaussian"):
        with pytest.raises(DataError):
            draw_fix_times(0.0, 10.0, np.random.default_rng(0), bad)


def test_none_profile_equals_truth_spline(truth: TruthStream) -> None:
    g = degrade_gps(truth, "none", seed=5)
    cs = CubicSpline(truth.t, np.column_stack([truth.x, truth.y]), axis=0)
    p = cs(g.t)
    assert np.array_equal(g.x, p[:, 0]) and np.array_equal(g.y, p[:, 1])
    assert np.max(np.abs(g.x - 10.0 * g.t)) < 1e-9  # spline of a line is the line
    assert np.max(np.abs(g.y - 50.0 * np.sin(g.t / 10.0))) < 1e-6
    assert g.accuracy is None and g.lat is None


def test_same_fix_times_across_profiles_and_deterministic(truth: TruthStream) -> None:
    streams = {p: degrade_gps(truth, p, seed=7) for p in GPS_PROFILES}
    for p in GPS_PROFILES:
        assert np.array_equal(streams[p].t, streams["none"].t)
    again = degrade_gps(truth, "consumer", seed=7)
    assert np.array_equal(again.x, streams["consumer"].x)
    other = degrade_gps(truth, "consumer", seed=8)
    assert not np.array_equal(other.t[:10], again.t[:10])


def test_rtk_noise_two_cm(truth: TruthStream) -> None:
    exact = degrade_gps(truth, "none", seed=2)
    rtk = degrade_gps(truth, "rtk", seed=2)
    e = np.concatenate([rtk.x - exact.x, rtk.y - exact.y])
    assert 0.017 < np.std(e) < 0.023
    assert abs(np.mean(e)) < 0.003


def test_consumer_noise_metre_level_and_correlated() -> None:
    tr = _truth(3000.0, hz=10.0)
    exact = degrade_gps(tr, "none", seed=3)
    con = degrade_gps(tr, "consumer", seed=3)
    ex, ey = con.x - exact.x, con.y - exact.y
    rms = np.sqrt(np.mean(np.concatenate([ex, ey]) ** 2))
    assert 0.6 < rms < 2.0
    j = np.searchsorted(con.t, con.t + 1.0)
    ok = j < con.t.size
    for e in (ex, ey):
        r = np.corrcoef(e[ok], e[j[ok]])[0, 1]
        assert r > 0.6  # theory ~0.78 (1 m GM, tau 45 s, plus 0.5 m white)


def test_gauss_markov_statistics() -> None:
    t = np.arange(0.0, 20000.0, 0.5)
    e = gauss_markov(t, 1.0, 30.0, np.random.default_rng(0), dims=1)[:, 0]
    assert 0.85 < np.std(e) < 1.15
    lag = int(30.0 / 0.5)
    r = np.corrcoef(e[:-lag], e[lag:])[0, 1]
    assert abs(r - np.exp(-1.0)) < 0.1


def test_latency_stale_positions(truth: TruthStream) -> None:
    g = degrade_gps(truth, "none", seed=1, latency_s=0.5)
    assert g.t[0] >= truth.t[0] + 0.5
    assert np.max(np.abs(g.x - 10.0 * (g.t - 0.5))) < 1e-9
    with pytest.raises(DataError):
        degrade_gps(truth, "none", latency_s=-1.0)


def test_origin_fills_latlon(truth: TruthStream) -> None:
    from posbench.scenarios.projection import to_local

    g = degrade_gps(truth, "rtk", seed=1, origin=(45.8, 16.0))
    x, y = to_local(g.lat, g.lon, 45.8, 16.0)
    assert np.max(np.hypot(x - g.x, y - g.y)) < 1e-3
    assert np.all(g.accuracy > 0)


def test_bad_profile() -> None:
    with pytest.raises(DataError):
        degrade_gps(_truth(10.0), "military")


# ------------------------------------------------------------------ dropouts


def _gps(duration: float = 120.0, seed: int = 0) -> GpsStream:
    return degrade_gps(_truth(duration), "none", seed=seed)


def test_outage_windows_lengths_separation_and_turns() -> None:
    rng = np.random.default_rng(0)
    turns = np.array([30.0, 31.0, 70.0])
    w = outage_windows(0.0, 120.0, OUTAGE_LENGTHS_S, rng, t_turns=turns)
    assert sorted(np.round(w[:, 1] - w[:, 0], 9)) == sorted(OUTAGE_LENGTHS_S)
    assert w[0, 0] >= 10.0 and w[-1, 1] <= 119.0
    assert np.all(w[1:, 0] - w[:-1, 1] >= 10.0 - 1e-9)
    contains = [(np.any((turns >= a) & (turns <= b))) for a, b in w]
    assert sum(contains) >= 1
    # long streams repeat the set
    w_long = outage_windows(0.0, 1000.0, OUTAGE_LENGTHS_S, np.random.default_rng(1))
    assert len(w_long) == 4 * 10
    assert np.all(w_long[1:, 0] - w_long[:-1, 1] >= 10.0 - 1e-9)


def test_apply_outages_no_fix_inside() -> None:
    g = _gps()
    thin, outages = apply_dropouts(g, "outages", seed=4)
    assert len(outages) == 4
    gaps = np.array([b - a for a, b in outages])
    assert np.all(gaps >= 0.5)
    assert np.all(gaps <= 5.0 + 2 * MAX_IV + 1e-9)
    for a, b in outages:
        assert not np.any((thin.t > a) & (thin.t < b))
        assert np.any((g.t > a) & (g.t < b))  # something was removed there
        assert a in thin.t and b in thin.t
    assert len(g) - len(thin) > 0
    again, out2 = apply_dropouts(g, "outages", seed=4)
    assert np.array_equal(again.t, thin.t) and out2 == outages


def test_apply_single_length_outage() -> None:
    g = _gps(200.0)
    thin, outages = apply_dropouts(g, "outage:2", seed=0)
    assert len(outages) >= 1
    for a, b in outages:
        assert 2.0 <= b - a <= 2.0 + 2 * MAX_IV + 1e-9
        assert not np.any((thin.t > a) & (thin.t < b))


def test_apply_outages_in_turns() -> None:
    g = _gps(120.0)
    turns = np.arange(40.0, 45.0, 0.1)
    _, outages = apply_dropouts(g, "outages", seed=2, t_turns=turns)
    assert any(a <= 45.0 and b >= 40.0 for a, b in outages)


def test_random_dropouts_fraction() -> None:
    g = _gps(2000.0)
    thin, outages = apply_dropouts(g, "random:0.2", seed=1)
    lost = 1.0 - len(thin) / len(g)
    sd = np.sqrt(0.2 * 0.8 / len(g))
    assert abs(lost - 0.2) < 4 * sd
    for a, b in outages[:50]:
        assert a in thin.t or a == g.t[0]
        assert not np.any((thin.t > a) & (thin.t < b))
    same, _ = apply_dropouts(g, "random:0.2", seed=1)
    assert np.array_equal(same.t, thin.t)


def test_dropouts_none_and_bad() -> None:
    g = _gps(30.0)
    thin, outages = apply_dropouts(g, "none", seed=0)
    assert thin is g and outages == []
    for bad in ("random:1.5", "random:x", "outage:-1", "sometimes"):
        with pytest.raises(DataError):
            apply_dropouts(g, bad, seed=0)
