"""Rerun recordings of a run: written to an .rrd file and read back with rerun's own
chunk reader (``rr.chunk.RrdReader``), which proves the entity paths, the number of
rows, the values and the time range of what the viewer will load. What the viewer
draws from them (colours, trailing time range) is not checked here."""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.config import RunConfig
from bench.rerun_log import drive_paths, outage_steps, sanitise, write_recording
from bench.runner import DriveRun, run
from scenarios.synthetic import generate_drive

rr = pytest.importorskip("rerun", reason="needs the viz extra")


def fake_run(name: str = "my drive/01", preds=("cv", "kf-paper"), dur: float = 20.0,
             now_step: float = 0.05, seed: int = 0) -> DriveRun:
    """A DriveRun by hand: circle track, fixes every 0.2 s (every 7th dropped), one outage."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, dur, 0.2)
    received = np.arange(tf.size) % 7 != 3
    received[(tf > 8.0) & (tf < 9.5)] = False
    fixes = pd.DataFrame({"t": tf, "x": 30 * np.cos(tf / 10), "y": 30 * np.sin(tf / 10),
                          "received": received})
    tt = np.arange(0.0, dur, 0.1)
    track = pd.DataFrame({"t": tt, "x": 30 * np.cos(tt / 10), "y": 30 * np.sin(tt / 10)})
    track.loc[50:54, ["x", "y"]] = np.nan  # a gap: two strips
    frames = []
    tn = np.arange(0.0, dur, now_step)
    for p in preds:
        for kind, tq in (("future", tf[received] + 0.2), ("now", tn)):
            n = tq.size
            err = rng.uniform(0, 1, n)
            err[0] = np.nan  # not scorable
            lab = np.where((tq >= 5) & (tq < 10), "turn", "straight")
            frames.append(pd.DataFrame({
                "dataset": "mem", "drive": name, "predictor": p, "kind": kind,
                "t_issue": tq, "t_query": tq, "x": 30 * np.cos(tq / 10) + err,
                "y": 30 * np.sin(tq / 10), "x_ref": 30 * np.cos(tq / 10),
                "y_ref": 30 * np.sin(tq / 10), "error_m": err, "label": lab,
                "speed_mps": 3.0, "since_fix_s": 0.1, "outage": -1}))
        frames[-1].loc[0, ["x", "y"]] = np.nan  # no answer before the first fix
    outages = [(float(tf[received & (tf <= 8.0)][-1]), float(tf[received & (tf >= 9.5)][0]))]
    return DriveRun(name, "mem", "truth", ["a note"], ["a warning"], pd.concat(frames),
                    outages=outages, gps_count=int(received.sum()), duration_s=dur, fixes=fixes,
                    track=track)


def read_back(path: Path):
    """entity path -> {"static": [record batches], "temporal": [record batches]}, and the
    blueprint's view origins by class."""
    reader = rr.chunk.RrdReader(path)
    [recording] = reader.recordings()
    out: dict[str, dict[str, list]] = defaultdict(lambda: {"static": [], "temporal": []})
    for c in reader.stream(store=recording).to_chunks():
        assert not c.is_static or c.timeline_names == []
        if not c.is_static:
            assert c.timeline_names == ["time"]
        out[c.entity_path.lstrip("/")]["static" if c.is_static else "temporal"].append(
            c.to_record_batch())
    views = {}
    for c in reader.stream(store=reader.blueprints()[0]).to_chunks():
        rb = c.to_record_batch()
        if "ViewBlueprint:space_origin" in rb.schema.names:
            cls = rb.column("ViewBlueprint:class_identifier").to_pylist()[0][0]
            views[cls] = rb.column("ViewBlueprint:space_origin").to_pylist()[0][0]
    return out, views


def times_s(batches) -> np.ndarray:
    return np.concatenate([b.column("time").cast("int64").to_numpy() for b in batches]) / 1e9


def column(batches, name: str) -> list:
    return [v for b in batches for v in b.column(name).to_pylist()]


def test_sanitise_and_unique_roots():
    assert sanitise("my drive/01") == "my_drive_01"
    assert sanitise("kf-paper") == "kf-paper"
    assert sanitise("///") == "_"
    assert drive_paths(["a b", "a/b", "c"]) == ["drives/a_b", "drives/a_b_2", "drives/c"]


def test_outage_steps():
    t, v = outage_steps([(5.0, 7.0), (1.0, 2.0)], 0.0, 10.0)
    np.testing.assert_array_equal(t, [0, 1, 2, 5, 7, 10])
    np.testing.assert_array_equal(v, [0, 1, 0, 1, 0, 0])
    t, v = outage_steps([], 0.0, 3.0)
    np.testing.assert_array_equal(v, [0, 0])


def test_hand_made_run_round_trips(tmp_path):
    r = fake_run()
    path = tmp_path / "run.rrd"
    write_recording(path, [r], ["cv", "kf-paper"])
    assert path.stat().st_size > 10_000
    ents, views = read_back(path)
    root = "drives/my_drive_01"
    expected = {f"{root}/{e}" for e in (
        "info", "map/truth", "map/fixes/received", "map/fixes/dropped", "labels", "outages",
        "map/cv/future", "map/cv/now", "errors/cv/future", "errors/cv/now",
        "map/kf-paper/future", "map/kf-paper/now", "errors/kf-paper/future",
        "errors/kf-paper/now")}
    assert expected <= set(ents), expected - set(ents)
    assert {e for e in ents if e.startswith("drives/")} == expected

    # the track: static, split at its NaN gap into two strips holding every finite point
    [truth] = ents[f"{root}/map/truth"]["static"]
    strips = column([truth], "LineStrips2D:strips")[0]  # one row: both strips
    assert [len(s) for s in strips] == [50, 200 - 55]
    assert not ents[f"{root}/map/truth"]["temporal"]

    # fixes: one row per fix at its own time
    f = r.fixes
    for kind, mask in (("received", f.received), ("dropped", ~f.received)):
        b = ents[f"{root}/map/fixes/{kind}"]["temporal"]
        np.testing.assert_allclose(times_s(b), f.t[mask], atol=1e-9)
        pos = np.array([p[0] for p in column(b, "Points2D:positions")])
        np.testing.assert_allclose(pos, f.loc[mask, ["x", "y"]].to_numpy(), atol=1e-4)

    # errors: every query (NaN kept as a gap), time range = the drive's query times
    for p in ("cv", "kf-paper"):
        for kind in ("future", "now"):
            g = r.traces[(r.traces.predictor == p) & (r.traces.kind == kind)]
            b = ents[f"{root}/errors/{p}/{kind}"]["temporal"]
            t = times_s(b)
            np.testing.assert_allclose(t, g.t_query, atol=1e-9)
            vals = np.array([v[0] for v in column(b, "Scalars:scalars")])
            np.testing.assert_array_equal(np.isnan(vals), np.isnan(g.error_m))
            np.testing.assert_allclose(vals[1:], g.error_m.to_numpy()[1:])
            names = column(ents[f"{root}/errors/{p}/{kind}"]["static"], next(
                n for n in ents[f"{root}/errors/{p}/{kind}"]["static"][0].schema.names
                if n.endswith(":names")))
            assert names == [[f"{p} {kind}"]]
    now_t = times_s(ents[f"{root}/errors/cv/now"]["temporal"])
    assert now_t.min() == pytest.approx(0.0) and now_t.max() == pytest.approx(19.95)
    # map: rows without a position are left out (the first 'now' row has NaN x, y)
    assert sum(b.num_rows for b in ents[f"{root}/map/cv/now"]["temporal"]) == now_t.size - 1

    # labels: one entry per change, at the change time
    b = ents[f"{root}/labels"]["temporal"]
    assert [v[0] for v in column(b, "TextLog:text")] == ["straight", "turn", "straight"]
    np.testing.assert_allclose(times_s(b), [0.0, 5.0, 10.0], atol=1e-9)

    # outages: 1 exactly between the last fix before and the first fix after
    b = ents[f"{root}/outages"]["temporal"]
    t, v = times_s(b), np.array([x[0] for x in column(b, "Scalars:scalars")])
    (a, e), = r.outages
    np.testing.assert_allclose(t[v == 1.0], [a], atol=1e-9)
    assert t[np.flatnonzero(v == 1.0)[0] + 1] == pytest.approx(e)

    info = column(ents[f"{root}/info"]["static"], "TextDocument:text")[0][0]
    assert "a note" in info and "a warning" in info
    assert views == {"2D": f"{root}/map", "TimeSeries": root, "TextLog": f"{root}/labels"}


def test_runner_output_with_cv_and_skipped_drive(tmp_path):
    d = generate_drive(seed=3, route="mixed", duration_s=20.0)
    cfg = RunConfig(predictors=("cv",), dropouts="outage:1")
    [r] = run([d], cfg)
    skipped = DriveRun("bad drive", "mem", "", [], [], pd.DataFrame(), skipped="poor truth")
    path = tmp_path / "cv.rrd"
    write_recording(path, [skipped, r], ["cv"])
    ents, views = read_back(path)
    root = f"drives/{sanitise(d.name)}"
    assert views["2D"] == f"{root}/map"  # the first drive that was not skipped
    assert set(ents["drives/bad_drive/info"]) and [e for e in ents if "bad_drive" in e] == [
        "drives/bad_drive/info"]
    assert "SKIPPED: poor truth" in column(ents["drives/bad_drive/info"]["static"],
                                           "TextDocument:text")[0][0]
    for e in ("map/cv/future", "map/cv/now", "errors/cv/future", "errors/cv/now",
              "map/fixes/received", "map/truth", "labels", "outages"):
        assert f"{root}/{e}" in ents
    # the recorded time range is the drive's (now queries span first to last received fix)
    t = times_s(ents[f"{root}/errors/cv/now"]["temporal"])
    assert t.min() == pytest.approx(r.fixes.t[r.fixes.received].min(), abs=1e-6)
    assert t.max() <= d.duration_s + 1e-6 and t.max() > d.duration_s - 1.0
    fut = times_s(ents[f"{root}/errors/cv/future"]["temporal"])
    assert fut.size == r.gps_count and fut.max() <= d.duration_s + cfg.horizon_s + 1e-6
    n_drop = int((~r.fixes.received).sum())
    if n_drop:
        assert times_s(ents[f"{root}/map/fixes/dropped"]["temporal"]).size == n_drop


def test_missing_rerun_raises_the_hint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)
    with pytest.raises(ImportError, match=r"pip install 'posbench\[viz\]'"):
        write_recording(tmp_path / "x.rrd", [fake_run()], ["cv"])
    assert not (tmp_path / "x.rrd").exists()


def test_two_minute_drive_three_predictors_is_fast(tmp_path):
    r = fake_run("long", preds=("cv", "kf", "poly"), dur=120.0)
    write_recording(tmp_path / "warm.rrd", [fake_run()], ["cv"])  # import, first stream
    t0 = time.perf_counter()
    write_recording(tmp_path / "long.rrd", [r], ["cv", "kf", "poly"])
    dt = time.perf_counter() - t0
    print(f"2-min drive, 3 predictors, {len(r.traces)} trace rows: {dt * 1e3:.0f} ms")
    assert dt < 2.0  # ~30-40 ms measured; generous for a loaded machine
    ents, _ = read_back(tmp_path / "long.rrd")
    assert times_s(ents["drives/long/errors/poly/now"]["temporal"]).size == 2400
