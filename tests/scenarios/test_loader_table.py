"""CSV / Parquet table loader: round trips and every kind of bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios.drive import (
    Drive,
    DriveMeta,
    GpsStream,
    ImuStream,
    SpeedStream,
    TruthStream,
)
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders import load
from posbench.scenarios.loaders.table import load_table, write_table
from posbench.scenarios.projection import to_local

HEADER = "stream,t,lat,lon,accuracy,ax,ay,yaw,yaw_rate,v"


def _synthetic() -> Drive:
    t = np.arange(0.0, 10.0, 0.1)
    x, y = 10.0 * t, 0.5 * t**2
    ti = np.arange(0.0, 10.0, 0.02)
    return Drive(
        meta=DriveMeta(name="syn", source="mem", format="test"),
        gps=GpsStream(t[::2] + 0.013, x[::2], y[::2], accuracy=np.full(50, 2.5)),
        imu=ImuStream(ti, np.sin(ti), np.cos(ti), yaw=0.1 * ti, yaw_rate=np.full(ti.size, 0.1)),
        speed=SpeedStream(t + 0.005, 10.0 + 0.1 * t),
        truth=TruthStream(t, x, y, yaw=np.arctan2(t, 10.0), v=np.hypot(10.0, t)),
    )


def _same(a: Drive, b: Drive) -> None:
    for sa, sb in ((a.gps, b.gps), (a.imu, b.imu), (a.speed, b.speed), (a.truth, b.truth)):
        for k in ("t", "x", "y", "ax", "ay", "yaw", "yaw_rate", "v", "accuracy", "lat", "lon"):
            va, vb = getattr(sa, k, None), getattr(sb, k, None)
            assert (va is None) == (vb is None), k
            if va is not None:
                np.testing.assert_allclose(vb, va, rtol=0, atol=1e-9, err_msg=k)


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_synthetic(tmp_path: Path, suffix: str):
    d = _synthetic()
    p = tmp_path / f"drive{suffix}"
    write_table(d, p)
    (back,) = load(p)  # through the dispatcher
    assert back.meta.format == "table" and back.name == "drive"
    assert back.meta.projection == "source"
    assert back.meta.warnings == []
    _same(d, back)


@pytest.mark.shared
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_round_trip_kitti_drive(kitti_dir: Path, tmp_path: Path, suffix: str):
    from posbench.scenarios.loaders.kitti import load_kitti_drive

    d = load_kitti_drive(kitti_dir / "2011_09_26" / "2011_09_26_drive_0005_sync")
    p = tmp_path / f"k{suffix}"
    write_table(d, p)
    back = load_table(p)
    _same(d, back)


def test_long_format_latlon_projected_and_t_ns(tmp_path: Path):
    ns0 = 1_700_000_000_123_456_789
    p = tmp_path / "ll.csv"
    p.write_text(
        "stream,t_ns,lat,lon,ax,ay,v\n"
        f"gps,{ns0 + 100_000_000},49.0001,8.4,,,\n"
        f"imu,{ns0},,,0.1,0.2,\n"
        f"gps,{ns0 + 300_000_000},49.0002,8.4001,,,\n"
        f"speed,{ns0 + 50_000_000},,,,,5.0\n"
        f"truth,{ns0 + 100_000_000},49.0001,8.4,,,5.1\n"
    )
    d = load_table(p)
    assert d.meta.epoch_s == pytest.approx(ns0 / 1e9, abs=1e-6)
    np.testing.assert_allclose(d.gps.t, [0.1, 0.3], atol=1e-12)
    assert d.imu.t[0] == 0.0 and d.speed.t[0] == pytest.approx(0.05)
    assert d.meta.projection == "enu"
    assert (d.meta.origin_lat, d.meta.origin_lon) == (49.0001, 8.4)
    assert d.gps.x[0] == 0.0 and d.gps.y[0] == 0.0
    ex, ey = to_local(np.array([49.0002]), np.array([8.4001]), 49.0001, 8.4)
    assert d.gps.x[1] == pytest.approx(ex[0]) and d.gps.y[1] == pytest.approx(ey[0])
    assert d.truth.x[0] == pytest.approx(0.0) and d.truth.v[0] == 5.1
    assert d.imu.yaw is None and d.truth.yaw is None
    m = load_table(p, projection="mercator")
    assert m.meta.projection == "mercator" and m.gps.x[1] > ex[0] * 1.4


def test_wide_gps_only_file(tmp_path: Path):
    p = tmp_path / "fixes.csv"
    p.write_text("t, X ,y,accuracy\n5.0,1,2,3\n5.2,2,3,3\n5.1,1.5,2.5,3\n")
    d = load_table(p)
    np.testing.assert_allclose(d.gps.t, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(d.gps.x, [1, 1.5, 2])
    assert d.imu is None and d.truth is None
    assert np.isnan(d.meta.epoch_s)
    text = " | ".join(d.meta.warnings)
    assert "no 'stream' column" in text and "re-sorted 1" in text


def test_duplicates_blank_lines_and_unknown_columns_warn(tmp_path: Path):
    p = tmp_path / "w.csv"
    p.write_text("stream,t,x,y,colour\ngps,0,0,0,red\n\ngps,1,1,1,red\ngps,1,1,1,red\n")
    d = load_table(p)
    assert len(d.gps) == 2
    text = " | ".join(d.meta.warnings)
    assert "dropped 1 blank lines" in text
    assert "ignored unknown columns colour" in text
    assert "dropped 1 samples with duplicate" in text


def _err(tmp_path: Path, text: str, name: str = "bad.csv") -> str:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(DataError) as ei:
        load_table(p)
    msg = str(ei.value)
    assert msg.startswith(str(p) + ": "), msg
    return msg


def test_missing_columns_named(tmp_path: Path):
    msg = _err(tmp_path, "stream,t,lat,lon\ngps,0,49,8\nimu,0.1,,\nspeed,0.2,,\n")
    assert "missing required column(s)" in msg
    assert "ax (for imu rows)" in msg and "ay (for imu rows)" in msg
    assert "v (for speed rows)" in msg
    msg = _err(tmp_path, "stream,time,x,y\ngps,0,1,2\n")
    assert "t (or t_ns)" in msg
    msg = _err(tmp_path, "stream,t,x\ngps,0,1\n")
    assert "lat and lon, or x and y (for gps rows)" in msg


def test_unknown_stream_names_line(tmp_path: Path):
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,1,1,2\ngyro,2,1,2\n")
    assert "line 4, column 'stream': unknown stream 'gyro'" in msg


def test_non_numeric_cell_names_line_and_column(tmp_path: Path):
    msg = _err(tmp_path, f"{HEADER}\ngps,0,49,8,3,,,,,\nimu,0.1,,,,0.5,abc,,,\n")
    assert "line 3, column 'ay': not a number: 'abc'" in msg
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,zero,1,2\n")
    assert "line 3, column 't': not a number: 'zero'" in msg


def test_missing_required_cell_names_line(tmp_path: Path):
    msg = _err(tmp_path, "stream,t,x,y,ax,ay\ngps,0,1,2,,\nimu,0.1,,,0.3,\n")
    assert "line 3, column 'ay': missing or non-finite value (required for imu rows)" in msg
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,,1,2\n")
    assert "line 3, column 't': missing" in msg
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,1,,\n")
    assert "line 3: position row has neither lat/lon nor x/y" in msg


def test_truncated_or_malformed_csv(tmp_path: Path):
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,1,1,2,7,8\n")
    assert "line 3: malformed CSV, expected 4 fields, saw 6" in msg
    msg = _err(tmp_path, 'stream,t,x,y\ngps,0,1,2\ngps,1,"1')
    assert "line 3: malformed CSV, quoted field never closed" in msg
    # cut mid-row: the last row lacks its y value
    msg = _err(tmp_path, "stream,t,x,y\ngps,0,1,2\ngps,1,1")
    assert "line 3: position row has neither lat/lon nor x/y" in msg


def test_invalid_latlon_named(tmp_path: Path):
    msg = _err(tmp_path, "stream,t,lat,lon\ngps,0,49,8\ngps,1,95,8\n")
    assert "gps row 1: invalid lat/lon" in msg


def test_empty_files(tmp_path: Path):
    assert "empty file" in _err(tmp_path, "")
    assert "no data rows" in _err(tmp_path, "stream,t,x,y\n")
    assert "empty file" in _err(tmp_path, "\n\n")
    assert "empty file" in _err(tmp_path, "", name="bad.parquet")


def test_parquet_errors_name_rows(tmp_path: Path):
    import pandas as pd

    p = tmp_path / "bad.parquet"
    pd.DataFrame(
        {
            "stream": ["gps", "gps", "lidar"],
            "t": [0.0, 1.0, 2.0],
            "x": [0.0, 1.0, 2.0],
            "y": [0.0, 1.0, 2.0],
        }
    ).to_parquet(p)
    with pytest.raises(DataError, match=r"bad\.parquet: row 3, column 'stream': unknown stream"):
        load_table(p)
    p.write_bytes(b"PAR1 garbage")
    with pytest.raises(DataError, match=r"bad\.parquet: cannot read Parquet"):
        load_table(p)


def test_parquet_read_a_column_at_a_time_as_pandas_reads_it(tmp_path: Path, monkeypatch):
    # a stored pandas index is the frame's index, not a column; text in a numeric column
    # is named; a Parquet file's drive equals the same table's as CSV
    import pandas as pd

    d = _synthetic()
    csv, pq = tmp_path / "d.csv", tmp_path / "d.parquet"
    write_table(d, csv)
    frame = pd.read_csv(csv)
    frame.index = pd.Index(np.arange(len(frame)) * 7, name="sample")
    frame.to_parquet(pq)
    with monkeypatch.context() as m:  # a column at a time: never the whole table
        m.setattr(pd, "read_parquet", lambda *a, **k: pytest.fail("read the table whole"))
        back = load_table(pq)
    assert back.meta.warnings == []  # no 'sample' column ignored
    _same(load_table(csv), back)
    frame["ax"] = frame["ax"].astype(str)  # a text column in the file
    frame.loc[frame.index[3], "ax"] = "n/a"
    frame.to_parquet(pq)
    with pytest.raises(DataError, match=r"d\.parquet: row 4, column 'ax': not a number: 'n/a'"):
        load_table(pq)


def test_csv_read_in_chunks_as_pandas_reads_it_whole(tmp_path: Path, monkeypatch):
    # a CSV is parsed a few rows at a time into columns sized for the file: the drive, the
    # warnings and the first bad cell's line are those of the file read whole
    from posbench.scenarios.loaders import table_file

    p = tmp_path / "d.csv"
    write_table(_synthetic(), p)
    text = p.read_text().splitlines()
    text.insert(7, "")  # a blank line, counted as a line
    text[3] = text[3].replace("gps", " GPS ", 1)  # a stream named in other case and spacing
    p.write_text("\n".join(text) + "\n")
    whole = load_table(p)
    monkeypatch.setattr(table_file, "CSV_CHUNK_ROWS", 3)
    chunked = load_table(p)
    assert chunked.meta.warnings == whole.meta.warnings != []
    _same(whole, chunked)
    # integers, then empty cells, then text in one numeric column: widened as pandas widens
    rows = ["stream,t,x,y"] + [f"gps,{i},{i},0" for i in range(7)]
    rows[5], rows[7] = "gps,4,,0", "gps,6,six,0"
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(DataError, match=r"line 8, column 'x': not a number: 'six'"):
        load_table(p)
    # lines that end in a lone CR (no newline to count): read all the same
    p.write_bytes("\r".join(r for r in rows if "six" not in r and ",," not in r).encode())
    assert load_table(p).gps.x.tolist() == [0.0, 1.0, 2.0, 3.0, 5.0]


def test_imu_only_file_has_no_fixes(tmp_path: Path):
    p = tmp_path / "imu.csv"
    p.write_text("stream,t,ax,ay\nimu,0,0.1,0.2\n")
    with pytest.raises(DataError, match="no GPS fixes"):
        load_table(p)
