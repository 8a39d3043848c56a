"""The figures and the rerun recording read the traces from a TraceSet, one predictor or one
drive at a time: the files are the same whether the traces are a frame in memory or Parquet
parts on disk (one per drive, or one per drive and predictor), and no figure's read asks for
every row or every column."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest
from test_plots import make_traces, res_for

from posbench.figures.writer import write_plots
from posbench.scoring.part_writer import write_part
from posbench.scoring.trace_set import TraceSet


def _files(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*.png"))}


def _parts(folder: Path, traces: pd.DataFrame, by: list[str]) -> TraceSet:
    """``traces`` as parts, one per group of ``by`` in the traces' order."""
    groups = traces.groupby(by, sort=False)
    return TraceSet(parts=[write_part(folder, g, f"{i:04d}") for i, (_, g) in enumerate(groups)])


def _traces() -> pd.DataFrame:
    """Three drives, three predictors, a warm-up; the middle drive the worst."""
    tr = make_traces(n_fix=70, drives=3, preds=("cv", "kf", "poly"))
    tr["warmup"] = tr.t_query < 1.0
    tr.loc[tr.drive == "drive-1", "error_m"] *= 3
    return tr


def test_drive_and_order_reads_are_the_same_in_memory_and_on_disk(tmp_path):
    tr = _traces()
    for ts in (
        TraceSet(tr),
        _parts(tmp_path / "d", tr, ["drive"]),
        _parts(tmp_path / "dp", tr, ["drive", "predictor"]),
    ):
        assert ts.drives() == ["drive-0", "drive-1", "drive-2"]
        assert ts.predictors() == ["cv", "kf", "poly"]
        got = ts.frame(["predictor", "t_query", "error_m"], drive="drive-1")
        want = tr.loc[tr.drive == "drive-1", ["predictor", "t_query", "error_m"]]
        assert got["predictor"].astype(str).tolist() == want["predictor"].tolist()
        assert got["error_m"].tolist() == want["error_m"].tolist()
        one = ts.frame(["error_m"], "kf", drive="drive-2")["error_m"].tolist()
        assert one == tr.loc[(tr.drive == "drive-2") & (tr.predictor == "kf"), "error_m"].tolist()
        assert ts.frame(["error_m"], drive="no such drive").empty


@pytest.mark.slow
def test_figures_from_parts_are_the_bytes_of_figures_from_a_frame(tmp_path, monkeypatch):
    tr = _traces()
    res = res_for(tr)
    here = write_plots(tr, res, tmp_path / "frame", drive_plots=2)
    assert "2 of 3 drives" in here.notes["error_over_time"]
    reads: list[tuple[object, object, object]] = []
    frame = TraceSet.frame

    def spy(self, columns=None, predictor=None, drive=None, rows=None):
        reads.append((columns, predictor, drive))
        return frame(self, columns, predictor, drive, rows)

    monkeypatch.setattr(TraceSet, "frame", spy)
    for by in (["drive"], ["drive", "predictor"]):
        out = tmp_path / "-".join(by)
        w = write_plots(_parts(tmp_path / f"parts-{out.name}", tr, by), res, out, drive_plots=2)
        assert w.notes == here.notes
        assert _files(out) == _files(tmp_path / "frame")
    # every read names a predictor or a drive, and the columns it needs
    assert reads and all(c is not None and (p is not None or d is not None) for c, p, d in reads)


def test_recording_from_a_trace_set_is_the_recording_from_the_runs(tmp_path):
    rr = pytest.importorskip("rerun", reason="needs the viz extra")
    from test_rerun_log import fake_run, read_back

    from posbench.recording.writer import write_recording

    runs = [fake_run("a", dur=12.0), fake_run("b", dur=10.5, seed=1)]
    ts = TraceSet(parts=[write_part(tmp_path / "p", r.traces, r.name) for r in runs])
    write_recording(tmp_path / "own.rrd", runs, ["cv", "kf-paper"])
    bare = [replace(r, traces=pd.DataFrame()) for r in runs]
    write_recording(tmp_path / "set.rrd", bare, ["cv", "kf-paper"], traces=ts)

    def values(path: Path) -> dict:
        return {
            rid: {
                e: [
                    str(b.select([c for c in b.schema.names if "RowId" not in c]).to_pylist())
                    for b in bs
                ]
                for e, parts in ents.items()
                for bs in (parts["static"] + parts["temporal"],)
            }
            for rid, (ents, _) in read_back(path, one=False).items()
        }

    assert rr is not None and values(tmp_path / "set.rrd") == values(tmp_path / "own.rrd")


@pytest.mark.slow
def test_figures_reading_only_the_rows_they_draw_are_the_same_bytes(tmp_path, monkeypatch):
    """The maps and the per-drive plots read only the rows they draw (a long drive's now
    queries of every predictor are not read), a row group at a time: the same files as the
    figures drawn from the whole frame. Thresholds lowered so that these small drives take
    the long drive's path."""
    import posbench.figures.per_drive as per_drive
    import posbench.scoring.trace_parts as trace_parts

    tr = _traces()
    res = res_for(tr)
    here = write_plots(tr, res, tmp_path / "frame", drive_plots=2)
    monkeypatch.setattr(per_drive, "CHOSEN_ABOVE_ROWS", 0)
    monkeypatch.setattr(trace_parts, "CHOOSE_BY_GROUP_ABOVE_ROWS", 1)
    chosen: list[str] = []
    drawn_rows = per_drive._drawn_rows

    def spy(ts, drive):
        keep = drawn_rows(ts, drive)
        assert keep is not None
        chosen.append(drive)
        return keep

    monkeypatch.setattr(per_drive, "_drawn_rows", spy)
    out = tmp_path / "parts-out"
    w = write_plots(_parts(tmp_path / "parts", tr, ["drive"]), res, out, drive_plots=2)
    assert w.notes == here.notes and len(chosen) == 2
    assert _files(out) == _files(tmp_path / "frame")
