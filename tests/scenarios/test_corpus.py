"""The training corpus (scenarios.corpus): envelope, manoeuvres, sensors, seeds, determinism;
and the built-in synthetic data set left bit-for-bit as it was."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios.consistency import check_drive
from posbench.scenarios.corpus import (
    PROFILES,
    corpus_drive,
    corpus_drives,
    corpus_plan,
    drive_dynamics,
    envelope,
    iter_corpus,
)
from posbench.scenarios.corpus_routes import MANOEUVRES
from posbench.scenarios.degrade import interpolate_truth
from posbench.scenarios.drive import Drive
from posbench.scenarios.labels import LABELS, label_times
from posbench.scenarios.synthetic import default_drives
from posbench.scenarios.synthetic_motion import simulate, stop, straight, turn

#: A fingerprint of default_drives(0), taken on main at commit 34f3d46 (where the earlier
#: sha256 of every array, 80c6912's, still held): per stream array its length and 65 values
#: at evenly spaced indices, mean and RMS; plus names and meta.extra. Floats are compared to
#: FINGERPRINT_TOL_M, not bit for bit: transcendental functions may differ in the last bit
#: between processors and numpy builds, and the built-in data set need only stay the same to
#: well under a millimetre. Rewrite it (``python tests/scenarios/test_corpus.py --write``) only
#: when the data set is meant to change, and say so in the commit.
FINGERPRINT = Path(__file__).with_name("data") / "default_drives_fingerprint.json"
#: metres (and seconds, m/s, radians, degrees: every stream array is held to the same bound)
FINGERPRINT_TOL_M = 1e-9
N_SAMPLES = 65


def _drive_arrays(d: Drive) -> dict[str, np.ndarray]:
    out = {}
    for sname in ("gps", "imu", "speed", "truth"):
        s = getattr(d, sname)
        for k, v in sorted(vars(s).items()):
            if v is not None:
                out[f"{sname}.{k}"] = v
    return out


def _array_fingerprint(v: np.ndarray) -> dict:
    a = np.asarray(v, dtype=np.float64)
    idx = np.unique(np.linspace(0, len(a) - 1, N_SAMPLES).round().astype(int))
    return {
        "n": len(a),
        "samples": a[idx].tolist(),
        "mean": float(a.mean()),
        "rms": float(np.sqrt(np.mean(a**2))),
    }


def fingerprint(drives: list[Drive]) -> dict:
    """Names, meta.extra, and per stream array its length, ``N_SAMPLES`` values at evenly
    spaced indices, its mean and RMS (float64 as JSON numbers, which round-trip exactly)."""
    return {
        d.name: {
            "meta_extra": json.loads(json.dumps(d.meta.extra)),
            "arrays": {k: _array_fingerprint(v) for k, v in _drive_arrays(d).items()},
        }
        for d in drives
    }


def fingerprint_differences(got: dict, want: dict) -> list[str]:
    """What differs: names, meta.extra or lengths at all, floats by more than the tolerance."""
    if list(got) != list(want):
        return [f"drives {list(got)} != {list(want)}"]
    out = []
    for name, w in want.items():
        g = got[name]
        if g["meta_extra"] != w["meta_extra"]:
            out.append(f"{name}: meta.extra")
        if list(g["arrays"]) != list(w["arrays"]):
            out.append(f"{name}: arrays {list(g['arrays'])} != {list(w['arrays'])}")
            continue
        for k, wa in w["arrays"].items():
            ga = g["arrays"][k]
            if ga["n"] != wa["n"]:
                out.append(f"{name} {k}: {ga['n']} values, was {wa['n']}")
                continue
            worst = max(
                float(np.max(np.abs(np.subtract(ga["samples"], wa["samples"])))),
                abs(ga["mean"] - wa["mean"]),
                abs(ga["rms"] - wa["rms"]),
            )
            if worst > FINGERPRINT_TOL_M:
                out.append(f"{name} {k}: off by {worst:.3g}")
    return out


def test_default_drives_unchanged_to_a_nanometre() -> None:
    want = json.loads(FINGERPRINT.read_text())
    assert fingerprint_differences(fingerprint(default_drives(0)), want) == []


def test_fingerprint_sees_a_micrometre() -> None:
    """Not blind: one stream of one drive shifted by 1 um is named."""
    want = json.loads(FINGERPRINT.read_text())
    got = fingerprint(default_drives(0))
    d = next(iter(got))
    x = np.asarray(default_drives(0)[0].truth.x)
    got[d]["arrays"]["truth.x"] = _array_fingerprint(x + 1e-6)
    assert fingerprint_differences(got, want) == [f"{d} truth.x: off by 1e-06"]


@pytest.fixture(scope="module")
def corpus() -> list[Drive]:
    return corpus_drives(1.5, seed=0)


@pytest.fixture(scope="module")
def env(corpus: list[Drive]) -> dict:
    return envelope(corpus)


def test_plan_seeds_mix_and_hours(corpus: list[Drive]) -> None:
    plan = corpus_plan(1.5, seed=0)
    assert [s for s, _ in plan] == list(range(100_000, 100_009))
    assert [d.name for d in corpus] == [f"corpus-{p}-s{s}" for s, p in plan]
    counts = {p: sum(q == p for _, q in plan) for p in PROFILES}
    assert counts == {"urban": 4, "rural": 3, "highway": 2}  # 9 x (0.4, 0.35, 0.25)
    assert corpus_plan(20, seed=3)[5][0] == 103_005
    assert len(corpus_plan(20)) == 120
    assert {p for _, p in corpus_plan(1, mix=(0, 0, 1))} == {"highway"}
    for d in corpus:
        assert d.meta.format == "synthetic"
        assert abs(d.duration_s - 600.0) < 0.02
        assert d.meta.extra["profile"] in PROFILES


@pytest.mark.parametrize(
    "kw",
    [
        {"hours": 0},
        {"hours": float("nan")},
        {"hours": 200},
        {"hours": 1, "mix": (1, 1)},
        {"hours": 1, "mix": (0, 0, 0)},
        {"hours": 1, "mix": (1, -1, 1)},
        {"hours": 1, "duration_s": 0.5},
    ],
)
def test_plan_rejects_bad_arguments(kw: dict) -> None:
    with pytest.raises(ValueError):
        corpus_plan(**kw)


def test_drive_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError, match="profile"):
        corpus_drive(100_000, "offroad")
    with pytest.raises(ValueError, match="duration_s"):
        corpus_drive(100_000, "urban", duration_s=0.0)


def test_envelope_speeds_accelerations_curvature(env: dict) -> None:
    a = env["all"]
    assert env["drives"] == 9 and a["hours"] == pytest.approx(1.5)
    assert a["speed_min_mps"] == 0.0 and a["speed_percentiles_mps"]["1"] == 0.0  # standstills
    assert a["speed_max_mps"] >= 35.0
    assert a["speed_max_mps"] <= 40.0 + 1e-6
    assert a["abs_lat_accel_max_mps2"] <= 6.0
    assert a["abs_curvature_max_inv_m"] >= 1.0 / 12.0  # U-turns
    assert a["abs_jerk_p99_mps3"] < 6.0 and a["abs_jerk_max_mps3"] < 15.0
    lo = {"urban": (0.0, 16.0), "rural": (0.0, 27.0), "highway": (0.0, 40.0)}
    assert set(env["profiles"]) == set(PROFILES)
    for p, st in env["profiles"].items():
        assert st["speed_min_mps"] == lo[p][0] and st["speed_max_mps"] <= lo[p][1] + 1e-6
    assert env["profiles"]["highway"]["speed_percentiles_mps"]["50"] > 22.0
    assert env["profiles"]["urban"]["speed_percentiles_mps"]["95"] < 16.0


def test_every_label_and_manoeuvre_present(env: dict, corpus: list[Drive]) -> None:
    a = env["all"]
    assert set(a["label_share"]) == set(LABELS)
    assert all(v > 0.005 for v in a["label_share"].values()), a["label_share"]
    assert set(a["manoeuvre_share"]) == set(MANOEUVRES)
    assert all(v > 0.002 for v in a["manoeuvre_share"].values()), a["manoeuvre_share"]
    # spans of neighbouring manoeuvres overlap by their transition curves (~1 %)
    assert sum(a["manoeuvre_share"].values()) == pytest.approx(1.0, abs=0.03)
    for d in corpus:
        assert {lab for lab, _, _ in d.meta.extra["segments"]} <= set(LABELS)
        assert {k for k, _, _ in d.meta.extra["manoeuvres"]} <= set(MANOEUVRES)


def _spans(corpus: list[Drive], kind: str, profile: str | None = None):
    for d in corpus:
        if profile is None or d.meta.extra["profile"] == profile:
            for k, a, b in d.meta.extra["manoeuvres"]:
                if k == kind:
                    yield d, a, b


def test_manoeuvre_geometry(corpus: list[Drive]) -> None:
    # highway curves: gentle (radius >= 300 m) but curved
    kmax = []
    for d, a, b in _spans(corpus, "curve", "highway"):
        m = (d.truth.t >= a) & (d.truth.t <= b)
        kmax.append(np.abs(drive_dynamics(d)["kappa"][m]).max())
    assert kmax and max(kmax) <= 1.0 / 300.0 + 1e-4 and min(kmax) > 1.0 / 2500.0
    # U-turns: heading reversed, radius 6-12 m
    n_u = 0
    for d, a, b in _spans(corpus, "u_turn"):
        m = (d.truth.t >= a - 3.0) & (d.truth.t <= b + 3.0)  # + the transition curves
        yaw = np.unwrap(d.truth.yaw[m])
        assert abs(abs(yaw[-1] - yaw[0]) - np.pi) < 0.05
        assert 1 / 12.5 < np.abs(drive_dynamics(d)["kappa"][m]).max() < 1 / 5.5
        n_u += 1
    assert n_u >= 1
    # lane changes: heading back where it was, ~3.5 m sideways
    n_lc = 0
    for d, a, b in _spans(corpus, "lane_change"):
        tr = d.truth
        i0, i1 = np.searchsorted(tr.t, [a - 1.0, b + 1.0])
        if i1 >= tr.t.size:
            continue
        h = tr.yaw[i0]
        dx, dy = tr.x[i1] - tr.x[i0], tr.y[i1] - tr.y[i0]
        lateral = -np.sin(h) * dx + np.cos(h) * dy
        assert 3.0 < abs(lateral) < 4.0, lateral
        assert abs(np.angle(np.exp(1j * (tr.yaw[i1] - h)))) < 0.01
        n_lc += 1
    assert n_lc >= 3
    # roundabouts of several radii
    radii = []
    for d, a, b in _spans(corpus, "roundabout"):
        tr, dyn = d.truth, drive_dynamics(d)
        m = (tr.t >= a) & (tr.t <= b) & (dyn["kappa"] > 0.02)  # the counter-clockwise ring
        radii.append(np.median(1.0 / dyn["kappa"][m]))
    assert len(radii) >= 3 and min(radii) < 20.0 and max(radii) > 25.0


def test_stops_and_creeping(corpus: list[Drive]) -> None:
    dwell = [b - a for d in corpus for k, a, b in d.meta.extra["manoeuvres"] if k == "start_stop"]
    assert len(dwell) >= 10 and min(dwell) < 3.0 and max(dwell) > 10.0
    for d, a, b in _spans(corpus, "creep"):
        m = (d.truth.t > a + 3.0) & (d.truth.t < b - 3.0)
        if m.any():
            assert d.truth.v[m].max() <= 2.0 + 1e-6


def test_vehicle_limits_hold_per_drive(corpus: list[Drive]) -> None:
    for d in corpus:
        lim, dyn = d.meta.extra["vehicle"], drive_dynamics(d)
        assert 1.0 <= lim["a_acc"] <= 3.5 and 1.5 <= lim["a_dec"] <= 6.0
        assert 2.0 <= lim["ay_max"] <= 5.0
        assert np.abs(dyn["a_lat"]).max() <= lim["ay_max"] + 0.05
        acc = np.gradient(d.truth.v, d.truth.t)
        assert acc.max() <= lim["a_acc"] + 0.05 and acc.min() >= -lim["a_dec"] - 0.05


def test_sensors_follow_their_draws(corpus: list[Drive]) -> None:
    rates = set()
    for d in corpus:
        s, imu, tr = d.meta.extra["sensors"], d.imu, d.truth
        rates.add(s["imu_hz"])
        assert np.allclose(np.diff(imu.t), 1.0 / s["imu_hz"])
        assert 0.02 <= s["accel_sd"] <= 0.2 and 0.02 <= s["bias_sd"] <= 0.3
        res = imu.ax - np.interp(imu.t, tr.t, np.gradient(tr.v, tr.t))
        assert np.std(res) == pytest.approx(s["accel_sd"], rel=0.1)
        yr = np.interp(imu.t, tr.t, np.gradient(np.unwrap(tr.yaw), tr.t))
        assert np.std(imu.yaw_rate - yr) == pytest.approx(s["yaw_rate_sd"], rel=0.1, abs=2e-4)
        # CAN speed: 50 Hz, exactly 0 at standstill
        v_true = np.interp(d.speed.t, tr.t, tr.v)
        assert np.allclose(np.diff(d.speed.t), 0.02)
        assert np.all(d.speed.v[v_true == 0.0] == 0.0)
        # GPS: the paper's intervals with late fixes, 1-2 s dropouts, noise ~0.06 m
        dt = np.diff(d.gps.t)
        assert dt.min() >= 0.1 - 1e-9 and 0.18 < np.median(dt) < 0.22
        assert np.sum(dt > 0.6 + 1e-6) == len(d.meta.extra["gps_outages"]) >= 10
        gx, gy = interpolate_truth(tr, d.gps.t)
        assert 0.03 < np.sqrt(np.mean((d.gps.x - gx) ** 2 + (d.gps.y - gy) ** 2)) < 0.2
    assert rates == {50, 100}


def test_drives_pass_the_consistency_checks(corpus: list[Drive]) -> None:
    for d in corpus:
        c = check_drive(d)
        assert not c.failures() and not c.warnings(), (d.name, c.to_dict())


def test_segments_agree_with_the_labeller(corpus: list[Drive]) -> None:
    for d in corpus[:3]:
        tr = d.truth
        tq = tr.t[::10]
        lab = label_times(tq, tr.t, tr.x, tr.y)
        for name, a, b in d.meta.extra["segments"]:
            if name == "straight":
                continue  # straights next to stops are start_stop for the labeller's 3 s
            m = (tq >= a + 0.5) & (tq <= b - 0.5)
            if m.sum() >= 20:
                assert np.mean(lab[m] == name) > 0.8, (d.name, name, a, b)


def test_deterministic_and_seeds_differ() -> None:
    a, b = corpus_drive(100_007, "rural", 120.0), corpus_drive(100_007, "rural", 120.0)
    aa, bb = _drive_arrays(a), _drive_arrays(b)
    assert aa.keys() == bb.keys() and all(np.array_equal(aa[k], bb[k]) for k in aa)
    assert a.meta.extra == b.meta.extra
    c = corpus_drive(100_008, "rural", 120.0)
    assert not np.array_equal(a.truth.x[:2000], c.truth.x[:2000])
    assert a.meta.extra["vehicle"] != c.meta.extra["vehicle"]
    u = corpus_drive(100_007, "urban", 120.0)
    assert not np.array_equal(a.truth.x[:2000], u.truth.x[:2000])
    it = iter_corpus(0.05, seed=2, duration_s=90.0)
    first = next(it)
    assert first.name == "corpus-urban-s102000"
    assert np.array_equal(first.truth.x, corpus_drive(102_000, "urban", 90.0).truth.x)


def test_simulate_keyword_limits() -> None:
    route = [stop(2.0), straight(300, 30.0), turn(90, 60, 30.0), straight(100, 20.0), stop(2.0)]
    slow = simulate(route, a_acc=1.0, a_dec=1.5, ay_max=2.0, ay_window_m=35.0)
    fast = simulate(route, a_acc=3.0, a_dec=5.0, ay_max=5.0, v_smooth_s=1.2, ay_window_m=40.0)
    for sim, (acc, dec, ay) in ((slow, (1.0, 1.5, 2.0)), (fast, (3.0, 5.0, 5.0))):
        a = np.gradient(sim.v, sim.t)
        assert a.max() <= acc + 0.05 and a.min() >= -dec - 0.05
        assert np.abs(sim.v * sim.yaw_rate).max() <= ay + 0.02
    assert fast.t[-1] < slow.t[-1] - 10.0
    assert [m[0] for m in slow.manoeuvres] == [m[0] for m in slow.segments]


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    FINGERPRINT.parent.mkdir(exist_ok=True)
    FINGERPRINT.write_text(json.dumps(fingerprint(default_drives(0)), indent=1) + "\n")
    print(f"wrote {FINGERPRINT}")
