"""Rerun recordings of a run: written to an .rrd file and read back with rerun's own
chunk reader (``rr.chunk.RrdReader``), which proves the entity paths, the number of
rows, the values and the time range of what the viewer will load. What the viewer
draws from them (colours, trailing time range) is not checked here."""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from posbench.config import RunConfig
from posbench.metrics.calibration import mahalanobis_sq
from posbench.metrics.ellipses import ELLIPSE_SEGMENTS
from posbench.metrics.track_errors import track_errors
from posbench.recording.blueprint import AROUND_M, VEHICLE_M
from posbench.recording.layout import (
    ELLIPSE_RADIUS,
    N_LAST_FIXES,
    PALETTE,
    drive_paths,
    error_colours,
    last_fixes,
    nice_scale,
    outage_steps,
    sanitise,
)
from posbench.recording.writer import write_recording
from posbench.replay.runner import run
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import COV_COLUMNS

rr = pytest.importorskip("rerun", reason="needs the viz extra")


def fake_run(
    name: str = "my drive/01",
    preds=("cv", "kf-paper"),
    dur: float = 20.0,
    now_step: float = 0.05,
    seed: int = 0,
    cov: Sequence[str] = (),
) -> DriveRun:
    """A DriveRun by hand: circle track, fixes every 0.2 s (every 7th dropped), one outage.
    Predictors in ``cov`` report a covariance (NaN for the first 10 queries of each kind,
    as before a filter is warm); the others' cov columns are NaN, as in real traces."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0.0, dur, 0.2)
    received = np.arange(tf.size) % 7 != 3
    received[(tf > 8.0) & (tf < 9.5)] = False
    fixes = pd.DataFrame(
        {"t": tf, "x": 30 * np.cos(tf / 10), "y": 30 * np.sin(tf / 10), "received": received}
    )
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
            ref = 30 * np.column_stack([np.cos(tq / 10), np.sin(tq / 10)])
            heading = tq / 10 + np.pi / 2  # counter-clockwise on the circle
            along, cross = track_errors(ref + np.column_stack([err, 0 * err]), ref, heading)
            frames.append(
                pd.DataFrame(
                    {
                        "dataset": "mem",
                        "drive": name,
                        "predictor": p,
                        "kind": kind,
                        "t_issue": tq,
                        "t_query": tq,
                        "x": ref[:, 0] + err,
                        "y": ref[:, 1],
                        "x_ref": ref[:, 0],
                        "y_ref": ref[:, 1],
                        "error_m": err,
                        "along_m": along,
                        "cross_m": cross,
                        "label": lab,
                        "speed_mps": 3.0,
                        "since_fix_s": 0.1,
                        "outage": -1,
                        "heading_ref": heading,
                        "yaw_rate_ref": 0.1,
                        **dict(
                            zip(
                                COV_COLUMNS,
                                _covariances(rng, n) if p in cov else np.full((3, n), np.nan),
                                strict=True,
                            )
                        ),
                    }
                )
            )
        frames[-1].loc[0, ["x", "y"]] = np.nan  # no answer before the first fix
    outages = [(float(tf[received & (tf <= 8.0)][-1]), float(tf[received & (tf >= 9.5)][0]))]
    return DriveRun(
        name,
        "mem",
        "truth",
        ["a note"],
        ["a warning"],
        pd.concat(frames),
        outages=outages,
        gps_count=int(received.sum()),
        duration_s=dur,
        fixes=fixes,
        track=track,
    )


def _covariances(rng: np.random.Generator, n: int) -> np.ndarray:
    """(3, n) columns xx, xy, yy [m^2] of random positive definite covariances (sigmas
    0.05-1 m, any orientation); the first 10 NaN."""
    a, b = rng.uniform(0.05, 1.0, n), rng.uniform(0.05, 1.0, n)
    th = rng.uniform(-np.pi, np.pi, n)
    c, s = np.cos(th), np.sin(th)
    xx, yy = a**2 * c**2 + b**2 * s**2, a**2 * s**2 + b**2 * c**2
    xy = (a**2 - b**2) * c * s
    out = np.array([xx, xy, yy])
    out[:, :10] = np.nan
    return out


def read_back(path: Path, one: bool = True):
    """Per recording: entity path -> {"static": [record batches], "temporal": [record
    batches]}, and its own blueprint's views: display name -> (class, origin, visual bounds
    or None). ``one``: the file must hold exactly one recording; return its pair."""
    reader = rr.chunk.RrdReader(path)
    blueprints = {b.application_id: b for b in reader.blueprints()}
    out = {}
    for recording in reader.recordings():
        ents: dict[str, dict[str, list]] = defaultdict(lambda: {"static": [], "temporal": []})
        for c in reader.stream(store=recording).to_chunks():
            if c.entity_path == "/__properties":
                continue
            assert not c.is_static or c.timeline_names == []
            if not c.is_static:
                assert c.timeline_names == ["time"]
            ents[c.entity_path.lstrip("/")]["static" if c.is_static else "temporal"].append(
                c.to_record_batch()
            )
        views, bounds = {}, {}
        for c in reader.stream(store=blueprints[recording.application_id]).to_chunks():
            rb = c.to_record_batch()
            if "ViewBlueprint:space_origin" in rb.schema.names:
                views[c.entity_path] = (
                    rb.column("ViewBlueprint:display_name").to_pylist()[0][0],
                    rb.column("ViewBlueprint:class_identifier").to_pylist()[0][0],
                    rb.column("ViewBlueprint:space_origin").to_pylist()[0][0],
                )
            if "VisualBounds2D:range" in rb.schema.names:
                bounds[c.entity_path.rsplit("/", 1)[0]] = rb.column(
                    "VisualBounds2D:range"
                ).to_pylist()[0][0]
        out[recording.recording_id] = (
            ents,
            {name: (cls, origin, bounds.get(vp)) for vp, (name, cls, origin) in views.items()},
        )
    if one:
        [pair] = out.values()
        return pair
    return out


def screen(xy) -> np.ndarray:
    """ENU -> rerun 2-D view coordinates, as the writer logs them (north up)."""
    xy = np.asarray(xy, dtype=float)
    return np.column_stack([xy[:, 0], -xy[:, 1]])


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
    per_pred = (
        "map/{p}/future",
        "map/{p}/now",
        "errors/{p}/future",
        "errors/{p}/now",
        "along/{p}/future",
        "along/{p}/now",
        "cross/{p}/future",
        "cross/{p}/now",
        "around/{p}/future",
        "around/{p}/error",
        "vehicle_frame/{p}",
    )
    expected = {
        f"{root}/{e}"
        for e in (
            "info",
            "map/truth",
            "map/track_error",
            "colour_scale",
            "map/fixes/received",
            "map/fixes/dropped",
            "labels",
            "outages",
            "around/reference",
            "around/road",
            "around/fixes",
            "vehicle_frame/axes",
            *(e.format(p=p) for p in ("cv", "kf-paper") for e in per_pred),
        )
    }
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
        np.testing.assert_allclose(pos, screen(f.loc[mask, ["x", "y"]]), atol=1e-4)

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
            names = column(
                ents[f"{root}/errors/{p}/{kind}"]["static"],
                next(
                    n
                    for n in ents[f"{root}/errors/{p}/{kind}"]["static"][0].schema.names
                    if n.endswith(":names")
                ),
            )
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
    ((a, e),) = r.outages
    np.testing.assert_allclose(t[v == 1.0], [a], atol=1e-9)
    assert t[np.flatnonzero(v == 1.0)[0] + 1] == pytest.approx(e)

    info = column(ents[f"{root}/info"]["static"], "TextDocument:text")[0][0]
    assert "a note" in info and "a warning" in info
    assert {(c, o) for c, o, _ in views.values()} == {
        ("2D", f"{root}/map"),
        ("2D", f"{root}/around"),
        ("2D", f"{root}/vehicle_frame"),
        ("TimeSeries", root),
        ("TextLog", f"{root}/labels"),
        ("TextDocument", f"{root}/colour_scale"),
    }
    assert sum(c == "TimeSeries" for c, _, _ in views.values()) == 3  # error, along, cross


def test_runner_output_with_cv_and_skipped_drive(tmp_path):
    d = generate_drive(seed=3, route="mixed", duration_s=20.0)
    cfg = RunConfig(predictors=("cv",), dropouts="outage:1")
    [r] = run([d], cfg)
    skipped = DriveRun("bad drive", "mem", "", [], [], pd.DataFrame(), skipped="poor truth")
    path = tmp_path / "cv.rrd"
    write_recording(path, [skipped, r], ["cv"])
    recs = read_back(path, one=False)
    assert list(recs) == ["mem/bad drive", f"{r.dataset}/{d.name}"]  # one per drive, in order
    bad, bad_views = recs["mem/bad drive"]
    ents, views = recs[f"{r.dataset}/{d.name}"]
    root = f"drives/{sanitise(d.name)}"
    assert ("2D", f"{root}/map") in {(c, o) for c, o, _ in views.values()}  # its own layout
    assert ("2D", "drives/bad_drive/map") in {(c, o) for c, o, _ in bad_views.values()}
    assert list(bad) == ["drives/bad_drive/info"]
    assert not any("bad_drive" in e for e in ents)
    assert (
        "SKIPPED: poor truth"
        in column(bad["drives/bad_drive/info"]["static"], "TextDocument:text")[0][0]
    )
    for e in (
        "map/cv/future",
        "map/cv/now",
        "errors/cv/future",
        "errors/cv/now",
        "map/fixes/received",
        "map/truth",
        "labels",
        "outages",
    ):
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
    with pytest.raises(ImportError, match=r"pip install 'posbench-harness\[viz\]'"):
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


def test_around_the_vehicle_is_reference_relative_and_metre_scaled(tmp_path):
    r = fake_run()
    path = tmp_path / "around.rrd"
    write_recording(path, [r], ["cv", "kf-paper"], color_by="kf-paper")
    ents, views = read_back(path)
    root = "drives/my_drive_01"
    tr = r.traces
    for p in ("cv", "kf-paper"):
        g = tr[(tr.predictor == p) & (tr.kind == "now")].sort_values("t_query")
        rel = g[["x", "y"]].to_numpy() - g[["x_ref", "y_ref"]].to_numpy()
        ok = np.isfinite(rel).all(axis=1)
        # the error arrow: from the reference (0, 0) to the answer, relative to the
        # reference at its query time, north up
        b = ents[f"{root}/around/{p}/error"]["temporal"]
        np.testing.assert_allclose(times_s(b), g.t_query[ok], atol=1e-9)
        vec = np.array([v[0] for v in column(b, "Arrows2D:vectors")])
        np.testing.assert_allclose(vec, screen(rel[ok]), atol=1e-5)
        origins = column(ents[f"{root}/around/{p}/error"]["static"], "Arrows2D:origins")
        assert origins == [[[0.0, 0.0]]]
        gf = tr[(tr.predictor == p) & (tr.kind == "future")].sort_values("t_query")
        relf = gf[["x", "y"]].to_numpy() - gf[["x_ref", "y_ref"]].to_numpy()
        pos = np.array(
            [
                v[0]
                for v in column(ents[f"{root}/around/{p}/future"]["temporal"], "Points2D:positions")
            ]
        )
        np.testing.assert_allclose(pos, screen(relf[np.isfinite(relf).all(axis=1)]), atol=1e-5)
        # the vehicle frame: (along, cross), left up
        b = ents[f"{root}/vehicle_frame/{p}"]["temporal"]
        ac = g[["along_m", "cross_m"]].to_numpy()
        pos = np.array([v[0] for v in column(b, "Points2D:positions")])
        np.testing.assert_allclose(pos, screen(ac[np.isfinite(ac).all(axis=1)]), atol=1e-5)
        # along/cross series: every query, NaN kept
        vals = np.array(
            [v[0] for v in column(ents[f"{root}/along/{p}/now"]["temporal"], "Scalars:scalars")]
        )
        np.testing.assert_allclose(vals[1:], g.along_m.to_numpy()[1:])
    # fixes around the vehicle: at each 'now' time the last received fixes, relative
    b = ents[f"{root}/around/fixes"]["temporal"]
    t = times_s(b)
    rows = column(b, "Points2D:positions")
    g = tr[(tr.predictor == "cv") & (tr.kind == "now")].sort_values("t_query")
    f = r.fixes[r.fixes.received]
    k = 100  # t = 5.0 s
    assert t[k] == pytest.approx(g.t_query.iloc[k])
    last = f[f.t <= t[k] + 1e-9].tail(N_LAST_FIXES)
    want = last[["x", "y"]].to_numpy() - g[["x_ref", "y_ref"]].to_numpy()[k]
    np.testing.assert_allclose(np.array(rows[k]), screen(want), atol=1e-4)
    # the views around the vehicle are a few metres wide, not the whole drive
    by_origin = {o: b for c, o, b in views.values() if c == "2D"}
    assert by_origin[f"{root}/around"] == {
        "x_range": [-AROUND_M, AROUND_M],
        "y_range": [-AROUND_M, AROUND_M],
    }
    assert by_origin[f"{root}/vehicle_frame"] == {
        "x_range": [-VEHICLE_M, VEHICLE_M],
        "y_range": [-VEHICLE_M, VEHICLE_M],
    }
    assert AROUND_M <= 10 and VEHICLE_M <= 2
    assert by_origin[f"{root}/map"] is None  # the overview fits the drive
    # the track coloured by kf-paper's error, with its scale in words
    text = column(ents[f"{root}/colour_scale"]["static"], "TextDocument:text")[0][0]
    assert "kf-paper" in text and "red >=" in text
    [strips] = [
        b
        for b in ents[f"{root}/map/track_error"]["static"]
        if "LineStrips2D:strips" in b.schema.names
    ]
    n_seg = len(column([strips], "LineStrips2D:strips")[0])
    assert n_seg == 200 - 1 - 6  # every segment with both ends known (the gap cuts 6)
    colours = column([strips], "LineStrips2D:colors")[0]
    assert len(colours) == n_seg and len(set(colours)) > 10  # a colour per segment


def test_one_recording_per_drive_each_on_its_own_time(tmp_path):
    a = fake_run("drive a", dur=10.0)
    b = fake_run("drive b", dur=12.0, seed=1)
    b.traces = b.traces.assign(t_issue=b.traces.t_issue + 1000.0, t_query=b.traces.t_query + 1000.0)
    path = tmp_path / "two.rrd"
    write_recording(path, [a, b], ["cv", "kf-paper"])
    recs = read_back(path, one=False)
    assert list(recs) == ["mem/drive a", "mem/drive b"]
    reader = rr.chunk.RrdReader(path)
    assert sorted(e.application_id for e in reader.recordings()) == sorted(
        e.application_id for e in reader.blueprints()
    )  # a layout of its own each
    for rid, root, t0 in (
        ("mem/drive a", "drives/drive_a", 0.0),
        ("mem/drive b", "drives/drive_b", 1000.0),
    ):
        ents, views = recs[rid]
        assert {e.split("/")[1] for e in ents} == {root.split("/")[1]}
        assert all(o.startswith(root) for _, o, _ in views.values())
        assert times_s(ents[f"{root}/errors/cv/now"]["temporal"]).min() == pytest.approx(t0)


def test_colour_scale():
    assert nice_scale(np.array([0.01, 0.02, 0.03, 0.04])) == pytest.approx(0.05)
    assert nice_scale(np.array([0.3] * 10)) == pytest.approx(0.5)
    assert nice_scale(np.array([0.1] * 10)) == pytest.approx(0.1)
    assert nice_scale(np.array([np.nan])) == pytest.approx(0.1)
    c = error_colours(np.array([0.0, 0.05, 0.1, 0.5, np.nan]), 0.1)
    np.testing.assert_array_equal(c[0], [26, 152, 80])  # green
    np.testing.assert_array_equal(c[1], [254, 224, 60])  # yellow at half the scale
    np.testing.assert_array_equal(c[2], c[3])  # red at and above the top
    np.testing.assert_array_equal(c[3], [215, 25, 28])
    np.testing.assert_array_equal(c[4], [190, 190, 190])  # no error known


def test_last_fixes():
    idx, n = last_fixes(np.array([-1.0, 0.0, 0.5, 3.0]), np.array([0.0, 1.0, 2.0]), n=2)
    np.testing.assert_array_equal(n, [0, 1, 1, 2])
    np.testing.assert_array_equal(idx, [0, 0, 1, 2])


def test_95_percent_ellipses_of_predictors_with_covariance(tmp_path):
    """cv reports a covariance (NaN for its first queries), kf-paper none: cv gets a closed
    95 % outline around each answer at its query time, in the map's screen frame and its
    colour, an empty row (cleared) where it has no covariance; kf-paper gets nothing."""
    r = fake_run(cov=("cv",))
    path = tmp_path / "cov.rrd"
    write_recording(path, [r], ["cv", "kf-paper"])
    ents, _ = read_back(path)
    root = "drives/my_drive_01"
    assert not any("ellipse" in e for e in ents if "/kf-paper/" in e)
    tr = r.traces
    for kind in ("future", "now"):
        e = ents[f"{root}/map/cv/ellipse_{kind}"]
        g = tr[(tr.predictor == "cv") & (tr.kind == kind)].sort_values("t_query")
        b = e["temporal"]
        np.testing.assert_allclose(times_s(b), g.t_query, atol=1e-9)  # a row per query
        rows = column(b, "LineStrips2D:strips")
        xy = g[["x", "y"]].to_numpy()
        cov = g[list(COV_COLUMNS)].to_numpy()
        drawn = np.isfinite(xy).all(axis=1) & np.isfinite(cov).all(axis=1)
        assert [len(x) for x in rows] == drawn.astype(int).tolist()
        assert drawn.sum() == len(g) - 10  # the first 10 have no covariance
        strips = np.array([x[0] for x in rows if x])  # (drawn, segments + 1, 2), screen
        assert strips.shape == (drawn.sum(), ELLIPSE_SEGMENTS + 1, 2)
        np.testing.assert_allclose(strips[:, 0], strips[:, -1])  # closed
        enu = np.stack([strips[..., 0], -strips[..., 1]], axis=-1)  # back from (x, -y)
        rel = enu - xy[drawn][:, None, :]
        d2 = mahalanobis_sq(rel.reshape(-1, 2), np.repeat(cov[drawn], ELLIPSE_SEGMENTS + 1, axis=0))
        np.testing.assert_allclose(d2, 5.991, rtol=2e-3)  # on the 95 % boundary (float32)
        # the centre is the answer: the outline's mean point
        np.testing.assert_allclose(rel[:, :-1].mean(axis=1), 0.0, atol=1e-3)
        [style] = e["static"]
        assert (
            column([style], "LineStrips2D:colors")[0]
            == column(ents[f"{root}/map/cv/{kind}"]["static"], "Points2D:colors")[0]
        )
        assert column([style], "LineStrips2D:colors")[0][0] == int.from_bytes(
            bytes([*PALETTE[0], 255]), "big"
        )  # cv's colour, the first predictor's
        assert column([style], "LineStrips2D:radii")[0] == [ELLIPSE_RADIUS]


def test_ellipses_keep_the_recording_small(tmp_path):
    """Each drawn ellipse costs about its 25 float32 points (200 bytes); predictors that
    report no covariance write no ellipse entity at all."""
    plain, with_cov = tmp_path / "plain.rrd", tmp_path / "cov.rrd"
    preds = ("cv", "kf", "poly")
    write_recording(plain, [fake_run("long", preds=preds, dur=120.0)], list(preds))
    r = fake_run("long", preds=preds, dur=120.0, cov=("cv", "kf"))
    write_recording(with_cov, [r], list(preds))
    assert not any("ellipse" in e for e in read_back(plain)[0])
    tr = r.traces
    n = int(
        (
            np.isfinite(tr[list(COV_COLUMNS)]).all(axis=1) & np.isfinite(tr[["x", "y"]]).all(axis=1)
        ).sum()
    )
    extra = with_cov.stat().st_size - plain.stat().st_size
    per = extra / n
    print(
        f"{n} ellipses: {plain.stat().st_size} -> {with_cov.stat().st_size} bytes, "
        f"{per:.0f} bytes each"
    )
    assert n > 5000
    assert 150 < per < 300, per


def _content(ents: dict) -> tuple[dict, dict]:
    """A recording's content however it was chunked: per entity its static values (the last
    of each column) and its temporal rows (time and components) in a canonical order; row
    ids left out."""
    static, temporal = {}, {}
    for path, e in ents.items():
        for rb in e["static"]:
            for name in rb.schema.names:
                if "RowId" not in name:
                    static[(path, name)] = rb.column(name).to_pylist()[-1]
        rows = []
        for rb in e["temporal"]:
            cols = {n: rb.column(n).to_pylist() for n in rb.schema.names if "RowId" not in n}
            for i in range(rb.num_rows):
                rows.append(repr(sorted((n, v[i]) for n, v in cols.items() if v[i] is not None)))
        temporal[path] = sorted(rows)
    return static, temporal


def test_a_drive_logged_in_pieces_is_the_drive_logged_at_once(tmp_path, monkeypatch):
    """A long drive's traces are read one predictor at a time and logged in pieces (read a
    row group at a time from its part on disk): the recording holds the same rows, and the
    ellipses, labels, outages, around view and coloured track of the drive at once."""
    import posbench.recording.reference_views as views
    import posbench.recording.writer as writer
    from posbench.scoring import part_writer
    from posbench.scoring.part_writer import PartWriter
    from posbench.scoring.trace_set import TraceSet

    r = fake_run("pieces", preds=("cv", "kf-paper"), dur=60.0, cov=("kf-paper",))
    tr = r.traces
    gap = (tr.predictor == "kf-paper") & (tr.t_query >= 20) & (tr.t_query < 30)
    tr.loc[gap.to_numpy(), list(COV_COLUMNS)] = np.nan  # pieces without an ellipse
    preds = ["cv", "kf-paper"]
    whole = tmp_path / "whole.rrd"
    write_recording(whole, [r], preds, color_by="kf-paper")
    expected = _content(read_back(whole)[0])

    monkeypatch.setattr(writer, "PIECE_ROWS", 97)
    monkeypatch.setattr(views, "AROUND_ROWS", 50)
    in_memory = tmp_path / "pieces.rrd"
    write_recording(in_memory, [r], preds, color_by="kf-paper")
    assert _content(read_back(in_memory)[0]) == expected

    monkeypatch.setattr(part_writer, "GROUP_ROWS", 300)
    with PartWriter(tmp_path / "parts", "pieces") as part:
        for _, rows in r.traces.groupby("predictor", sort=False):
            for a in range(0, len(rows), 120):  # pieces gathered into row groups of 300
                part.write(rows.iloc[a : a + 120])
        traces = TraceSet(parts=[part.close()])
    assert len(list(traces.drive_rows("pieces", "cv", ["t_query"]))) > 1
    on_disk = tmp_path / "parts.rrd"
    write_recording(on_disk, [r], preds, color_by="kf-paper", traces=traces)
    assert _content(read_back(on_disk)[0]) == expected
