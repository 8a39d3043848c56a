"""The fleet-scale data path: workers write each drive's traces (and call durations and bound
rows) to parts on disk and return small records; every figure combined from them is the one
the in-memory path gives, to the bit; the saved traces are the same rows."""

from __future__ import annotations

import gc
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import without_timings

import posbench.scoring.trace_set as trace_set_module
from posbench.aggregation.aggregate import aggregate
from posbench.config import RunConfig
from posbench.replay.runner import run
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.records import all_traces, trace_set
from posbench.scoring.trace_parts import part_values, text_values
from posbench.scoring.trace_set import TraceSet

CFG = RunConfig(predictors=("cv", "kf", "poly"), dropouts="outages")


@pytest.fixture(scope="module")
def drives():
    return [
        generate_drive(seed=1, route="mixed", duration_s=90.0),
        generate_drive(seed=2, route="roundabout", duration_s=70.0),
    ]


@pytest.fixture(scope="module")
def both(drives, tmp_path_factory):
    """The same drives replayed with traces in memory, and written to parts (split by
    predictor: ``workers`` > 1 and a drive holding more than its share)."""
    folder = tmp_path_factory.mktemp("parts")
    return run(drives, CFG, workers=1, limit=True), run(
        drives, CFG, workers=2, limit=True, parts=folder
    )


def test_records_from_parts_hold_nothing_that_grows_with_the_drive(both):
    _, spilled = both
    for r in spilled:
        assert r.traces.empty and r.trace_rows > 0 and r.trace_parts
        assert r.step_ns == {} and r.query_ns == {} and r.cov_ns == {} and r.timing_parts
        assert r.limit is None and Path(r.limit_part).is_file()
        assert r.fixes is None and r.track is None and Path(r.track_part).is_file()
        assert all(Path(p).is_file() for p in r.trace_parts)


def test_fixes_and_track_read_back_are_the_ones_the_replay_made(both):
    """The fixes fed (received or dropped) and the reference track, written by the workers
    and read back for the recording and the paper figures: the same columns, dtypes and
    values; a record that holds them gives itself."""
    memory, spilled = both
    for held, written in zip(memory, spilled, strict=True):
        assert held.with_fixes_and_track() is held
        back = written.with_fixes_and_track()
        assert back.track_part == ""
        assert (~back.fixes["received"]).any()  # the outages' dropped fixes are kept
        pd.testing.assert_frame_equal(back.fixes, held.fixes)
        pd.testing.assert_frame_equal(back.track, held.track)


def test_every_figure_from_parts_equals_the_in_memory_one(both):
    memory, spilled = both
    a = aggregate(memory, CFG, models={})
    b = aggregate(spilled, CFG, models={})
    assert a["outages"] and a["limit"]  # the families that read more than the traces
    assert json.dumps(without_timings(a), sort_keys=True, default=str) == json.dumps(
        without_timings(b), sort_keys=True, default=str
    )
    # the same calls were timed, read back from the spilled timings
    for name in CFG.predictors:
        assert (
            a["predictors"][name]["latency_us"]["count"]
            == b["predictors"][name]["latency_us"]["count"]
        )


@pytest.mark.parametrize("hold_rows", [0, 10**9], ids=["from the parts", "held"])
def test_every_figure_is_the_same_whether_a_predictor_is_held_or_read_again(
    both, monkeypatch, hold_rows
):
    memory, spilled = both
    monkeypatch.setattr(trace_set_module, "HOLD_ROWS", hold_rows)
    a = aggregate(memory, CFG, models={})
    b = aggregate(spilled, CFG, models={})
    assert json.dumps(without_timings(a), sort_keys=True, default=str) == json.dumps(
        without_timings(b), sort_keys=True, default=str
    )


def test_a_small_predictor_is_read_from_the_parts_once(both, monkeypatch):
    """Up to HOLD_ROWS rows, a predictor's reads after the first come from what the first
    read: the same rows, columns, dtypes and categories as reads from the parts; beyond, no
    read is held."""
    _, spilled = both
    calls: list[str] = []
    read_part = trace_set_module.read_part

    def counted(path, *args, **kwargs):
        calls.append(str(path))
        return read_part(path, *args, **kwargs)

    monkeypatch.setattr(trace_set_module, "read_part", counted)
    asks = [(["drive", "error_m"], "kf"), (None, "kf"), (["kind", "x", "drive", "x"], "kf")]
    monkeypatch.setattr(trace_set_module, "HOLD_ROWS", 0)
    again = trace_set(spilled)
    want = [again.frame(cols, name) for cols, name in asks]
    want_scored = again.scored("kf", ["t_query", "error_m", "drive"])
    assert len(calls) == 3 * len(again.parts) + len(again.parts)  # every read, every part
    monkeypatch.setattr(trace_set_module, "HOLD_ROWS", 10**9)
    calls.clear()
    held = trace_set(spilled)
    got = [held.frame(cols, name) for cols, name in asks]
    got_scored = held.scored("kf", ["t_query", "error_m", "drive"])
    for g, w in [*zip(got, want, strict=True), (got_scored, want_scored)]:
        pd.testing.assert_frame_equal(g, w)  # categories included
    kf_parts = [p for p in held.parts if "kf" in part_values(p, "predictor")]
    assert 0 < len(calls) == len(kf_parts)  # once, only the parts that hold kf
    got[0]["added"] = 1.0  # a caller's change is its own
    assert "added" not in held.frame(None, "kf")


def test_the_trace_set_reads_the_rows_of_the_frame(both, tmp_path):
    memory, spilled = both
    frame = all_traces(memory)
    parts = trace_set(spilled)
    assert parts.in_memory is None and parts.rows == len(frame)
    for name in CFG.predictors:
        want = frame[frame["predictor"] == name].reset_index(drop=True)
        got = parts.frame(None, name)
        pd.testing.assert_frame_equal(
            got.astype({c: str for c in ("dataset", "drive", "predictor")}),
            want.astype({c: str for c in ("dataset", "drive", "predictor")}),
            check_categorical=False,
        )
        scored = parts.scored(name, ["t_query", "error_m"])
        assert np.array_equal(
            scored["error_m"].to_numpy(),
            TraceSet(frame).scored(name, ["error_m"])["error_m"].to_numpy(),
        )
    written = parts.write(tmp_path / "traces.parquet")
    back = pd.read_parquet(written)
    assert np.array_equal(back["error_m"].to_numpy(), frame["error_m"].to_numpy(), equal_nan=True)
    assert list(back["drive"].astype(str)) == list(frame["drive"].astype(str))


def test_a_run_without_a_folder_reads_its_parts_until_it_is_gone(drives):
    import posbench

    result = posbench.run(predictors=["cv"], synthetic_duration_s=60.0)
    parts = result._trace_parts
    assert parts and all(Path(p).is_file() for p in parts)
    n = len(result.traces)
    assert n > 0 and result.trace_set.rows == n
    folder = Path(parts[0]).parent.parent
    del result
    gc.collect()
    assert not folder.exists()


def test_a_run_into_a_folder_leaves_no_parts_behind(tmp_path):
    import posbench

    out = tmp_path / "out"
    result = posbench.run(predictors=["cv"], synthetic_duration_s=60.0, out=out)
    assert not [p for p in out.iterdir() if p.name.startswith(".parts-")]
    assert len(pd.read_parquet(out / "traces.parquet")) == len(result.traces) > 0


@pytest.mark.parametrize("as_str", [False, True])
def test_text_values_are_the_columns_values_with_one_string_per_category(as_str):
    values = ["now", None, "future", "now", "future", None, "now"]
    column = pd.Series(pd.Categorical(values, categories=["future", "now", "unused"]))
    got = text_values(column, as_str=as_str)
    want = column.astype(str).to_numpy() if as_str else column.to_numpy()
    assert got.dtype == object and len(got) == len(want)
    assert [v if v == v else "missing" for v in got] == [v if v == v else "missing" for v in want]
    present = [v for v in got if v == v and v != "nan"]
    assert len({id(v) for v in present}) == 2  # shared: one object per category used
    plain = pd.Series(["a", "b", "a"])  # not categorical: pandas' own values
    assert text_values(plain).tolist() == ["a", "b", "a"]


def test_trim_heap_calls_the_c_librarys_trim_where_there_is_one():
    import platform

    from posbench.heap import _malloc_trim, trim_heap

    assert trim_heap() is None
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert _malloc_trim() is not None


@pytest.mark.parametrize("hold_rows", [0, 10**9], ids=["from the parts", "held"])
def test_pieces_are_a_predictors_rows_in_pieces(both, monkeypatch, hold_rows):
    """Read part by part (what a figure that reduces each piece reads), the rows are those of
    one read, in the same order, for the scored rows and for every row; from the parts, one
    piece per part that holds the predictor."""
    memory, spilled = both
    monkeypatch.setattr(trace_set_module, "HOLD_ROWS", hold_rows)
    cols = ["drive", "kind", "t_query", "error_m", "warmup"]
    on_disk, in_memory = trace_set(spilled), trace_set(memory)
    for scored in (True, False):
        whole = on_disk.scored("kf", cols) if scored else on_disk.frame(cols, "kf")
        pieces = list(on_disk.pieces("kf", cols, scored=scored))
        kf_parts = [p for p in on_disk.parts if "kf" in part_values(p, "predictor")]
        assert len(pieces) == (len(kf_parts) if hold_rows == 0 else 1)
        joined = pd.concat([p.astype({"drive": str}) for p in pieces], ignore_index=True)
        pd.testing.assert_frame_equal(joined, whole.astype({"drive": str}))
        [one] = list(in_memory.pieces("kf", cols, scored=scored))
        assert len(one) == len(whole)


def test_a_predictors_row_bound_comes_from_the_parts_metadata(both):
    """row_bound: the predictor's rows (scored or not) without reading them, from the parts'
    row groups, and the same count from a frame in memory."""
    memory, spilled = both
    on_disk, in_memory = trace_set(spilled), trace_set(memory)
    for name in ("cv", "kf"):
        n = len(on_disk.frame(["kind"], name))
        assert on_disk.row_bound(name) == in_memory.row_bound(name) == n > 0
        assert len(on_disk.scored(name, ["kind"])) < n
    assert on_disk.row_bound("nobody") == 0


def test_a_drive_scored_in_pieces_gives_the_rows_scored_at_once(drives, tmp_path, monkeypatch):
    """A worker scores a drive's queries TRACE_CHUNK_ROWS at a time and writes each piece to
    its part as it goes (what it holds does not grow with the drive's span): the rows, their
    order and types are those of one piece per predictor, in memory and read back from the
    part; a read of one predictor still skips the others' row groups."""
    import pyarrow.parquet as pq

    import posbench.replay.runner as runner
    import posbench.scoring.part_writer as part_writer
    from posbench.scoring.trace_parts import read_file, read_part

    drive = drives[0]
    monkeypatch.setattr(runner, "TRACE_CHUNK_ROWS", 1 << 30)
    whole = runner.run_drive(drive, CFG, limit=True)
    monkeypatch.setattr(runner, "TRACE_CHUNK_ROWS", 97)
    monkeypatch.setattr(part_writer, "GROUP_ROWS", 300)  # row groups gather a few pieces
    pieces = runner.run_drive(drive, CFG, limit=True)
    pd.testing.assert_frame_equal(pieces.traces, whole.traces, check_exact=True)
    pd.testing.assert_frame_equal(pieces.limit, whole.limit, check_exact=True)
    written = runner.run_drive(drive, CFG, limit=True, parts=tmp_path, part="d")
    assert written.traces.empty and list(written.traces.columns) == list(whole.traces.columns)
    (path,) = written.trace_parts
    assert written.trace_rows == len(whole.traces)
    meta = pq.ParquetFile(path).metadata
    sizes = [meta.row_group(i).num_rows for i in range(meta.num_row_groups)]
    assert len(sizes) > 2 * len(CFG.predictors) and max(sizes) <= 300
    pd.testing.assert_frame_equal(read_file(path), whole.traces, check_exact=True)
    kf = whole.traces[whole.traces["predictor"] == "kf"].reset_index(drop=True)
    got = read_part(path, predictor="kf")
    assert len(got) == len(kf)
    np.testing.assert_array_equal(got["error_m"].to_numpy(), kf["error_m"].to_numpy())
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_part_left_unfinished_by_an_error_is_not_left_behind(tmp_path):
    from posbench.scoring.part_writer import PartWriter

    with pytest.raises(RuntimeError), PartWriter(tmp_path, "d") as part:
        part.write(pd.DataFrame({"predictor": ["cv"], "error_m": [0.5]}))
        raise RuntimeError("the predictor failed")
    assert list(tmp_path.iterdir()) == []


def test_a_choice_of_rows_reads_the_same_rows_from_memory_and_from_parts(both):
    """TraceSet.frame(rows=...): the rows a figure draws chosen as they are read, one row
    group at a time on disk; the same rows and values as choosing them in a frame in memory."""
    memory, spilled = both

    def future_late(column):
        return (column("kind") == "future") & (column("t_query") > 20.0)

    cols = ["drive", "predictor", "kind", "t_query", "error_m"]
    in_memory, on_disk = trace_set(memory), trace_set(spilled)
    for drive in in_memory.drives():
        a = in_memory.frame(cols, drive=drive, rows=future_late)
        b = on_disk.frame(cols, drive=drive, rows=future_late)
        whole = in_memory.frame(cols, drive=drive)
        expected = whole[(whole["kind"] == "future") & (whole["t_query"] > 20.0)]
        assert 0 < len(a) < len(whole)
        for got in (a, b):
            np.testing.assert_array_equal(got["error_m"].to_numpy(), expected["error_m"])
            assert list(got["predictor"].astype(str)) == list(expected["predictor"].astype(str))
    kf = on_disk.frame(cols, predictor="kf", rows=future_late)
    assert set(kf["predictor"].astype(str)) == {"kf"} and set(kf["kind"].astype(str)) == {"future"}


def test_traces_parquet_keeps_a_row_group_per_drive_and_predictor(drives, tmp_path):
    """traces.parquet copies the parts' row groups: each holds one drive's rows of one
    predictor (a part here holds a drive's every predictor), so that a saved run read one
    predictor or drive at a time skips the others; the rows are those of the parts, in
    their order."""
    import pyarrow.parquet as pq

    from posbench.scoring.trace_parts import single_value

    runs = run(drives, CFG, workers=1, parts=tmp_path / "parts")
    assert all(len(r.trace_parts) == 1 for r in runs)
    ts = trace_set(runs)
    path = ts.write(tmp_path / "traces.parquet")
    meta = pq.ParquetFile(path).metadata
    names = meta.schema.names
    held = set()
    for g in range(meta.num_row_groups):
        group = meta.row_group(g)
        one = [
            single_value(group.column(names.index(c)).statistics) for c in ("drive", "predictor")
        ]
        assert None not in one
        held.add(tuple(one))
    assert len(held) == len(drives) * len(CFG.predictors)
    pd.testing.assert_frame_equal(
        pd.read_parquet(path), ts.materialize(), check_categorical=False, check_dtype=False
    )
