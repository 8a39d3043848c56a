"""Issue 40: memory bounded by the data, not by its time stamps; the time axis checked at load
(:mod:`posbench.scenarios.time_axis`); non-finite sensor values refused by every loader, each
with one ``error:`` line naming the file and where in it.

The memory cases run ``python -m posbench`` in a new process under an address-space limit of
2 GiB (:func:`_limited`), so a regression fails with a MemoryError there instead of swapping.
"""

from __future__ import annotations

import math
import pickle
import re
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_one_error_line, bench

from posbench.scenarios import consistency_reference
from posbench.scenarios.consistency_model import TOLERANCES
from posbench.scenarios.drive import Drive, DriveMeta, GpsStream, ImuStream
from posbench.scenarios.errors import DataError
from posbench.scenarios.loaders.aslan import load_aslan_pickle
from posbench.scenarios.loaders.rosbag import load_rosbag
from posbench.scenarios.loaders.table import load_table
from posbench.scenarios.time_axis import (
    MAX_GAP_S,
    MAX_GRID_POINTS,
    MAX_SPAN_S,
    check_span,
    evident_unit,
    grid_size,
)

#: the address space [bytes] a command gets in the memory tests (the issue's target: 2 GB)
MEMORY_LIMIT = 2 << 30
TEN_YEARS_S = 10 * 365.25 * 86400
UNIX_T0 = 1.6e9  # s


def _fixes_csv(path: Path, t: np.ndarray) -> Path:
    """A wide GPS-only table: ``t`` as given, a fix creeping north-east 1 m per fix."""
    k = np.arange(t.size)
    lat, lon = 49.0 + 1e-5 * k, 8.4 + 1e-5 * np.sin(k / 50)
    cols = zip(t.tolist(), lat.tolist(), lon.tolist(), strict=True)
    rows = (f"{a!r},{b!r},{c!r}" for a, b, c in cols)
    path.write_text("t,lat,lon\n" + "\n".join(rows) + "\n")
    return path


def _shifted_csv(folder: Path) -> Path:
    """The issue's file: 300 fixes at 5 Hz in Unix seconds, the second half ten years later."""
    t = UNIX_T0 + 0.2 * np.arange(300)
    t[150:] += TEN_YEARS_S
    return _fixes_csv(folder / "shifted.csv", t)


def _milliseconds_csv(folder: Path) -> Path:
    """The issue's file: one hour of 5 Hz fixes with ``t`` in milliseconds."""
    return _fixes_csv(folder / "ms.csv", UNIX_T0 * 1e3 + 200.0 * np.arange(18_000))


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _limited(*args: object, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``bench ARGS`` in a new process whose address space is held to :data:`MEMORY_LIMIT`."""
    return subprocess.run(
        [sys.executable, "-m", "posbench", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
        preexec_fn=_limit_memory,
    )


# --------------------------------------------------------------------------- one bad stamp


def test_ten_year_shift_refused_at_the_line_where_the_gap_starts(tmp_path: Path) -> None:
    path = _shifted_csv(tmp_path)
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(
        r, "shifted.csv: line 151:", "next sample (line 152)", "3652.5 days later", "1 h"
    )


@pytest.mark.slow
def test_ten_year_shift_within_the_memory_limit(tmp_path: Path) -> None:
    path = _shifted_csv(tmp_path)
    r = _limited("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(r, "line 151:", "3652.5 days later")
    r = _limited("run", "--data", path, "-p", "cv", "--out", tmp_path / "o", cwd=tmp_path)
    assert_one_error_line(r, "line 151:", "3652.5 days later")


# --------------------------------------------------------------------------- units


def test_milliseconds_refused_naming_the_unit(tmp_path: Path) -> None:
    path = _milliseconds_csv(tmp_path)
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(
        r, "ms.csv: t looks like milliseconds, not seconds", "median step is 200", "5 Hz"
    )


@pytest.mark.slow
def test_milliseconds_within_the_memory_limit(tmp_path: Path) -> None:
    path = _milliseconds_csv(tmp_path)
    r = _limited("run", "--data", path, "-p", "cv", "--out", tmp_path / "o", cwd=tmp_path)
    assert_one_error_line(r, "t looks like milliseconds")
    r = _limited("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(r, "t looks like milliseconds")


def test_t_ns_in_microseconds_refused(tmp_path: Path) -> None:
    us = 1_600_000_000_000_000 + 200_000 * np.arange(50)  # 5 Hz, microseconds
    rows = "\n".join(f"gps,{t},{1.0 * i},0" for i, t in enumerate(us.tolist()))
    path = tmp_path / "us.csv"
    path.write_text("stream,t_ns,x,y\n" + rows + "\n")
    with pytest.raises(DataError, match=r"t_ns looks like microseconds, not nanoseconds"):
        load_table(path)


def test_evident_unit() -> None:
    assert evident_unit(200.0, "seconds", "gps") == "milliseconds"
    assert evident_unit(2e5, "seconds", "gps") == "microseconds"
    assert evident_unit(10.0, "seconds", "imu") == "milliseconds"  # a 100 Hz IMU in ms
    assert evident_unit(2e-4, "nanoseconds", "gps") == "microseconds"
    assert evident_unit(1e15, "seconds", "gps") is None


def test_streams_on_different_clocks_refused(tmp_path: Path) -> None:
    gps = [f"gps,{UNIX_T0 + 0.2 * i!r},{1.0 * i},0,," for i in range(20)]
    imu = [f"imu,{100.0 + 0.02 * i!r},,,0.1,0.0" for i in range(200)]  # seconds since boot
    path = tmp_path / "clocks.csv"
    path.write_text("stream,t,x,y,ax,ay\n" + "\n".join(gps + imu) + "\n")
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(r, "clocks.csv: the drive spans", "do not overlap in time")


def test_drive_span_bounded_however_it_was_made() -> None:
    t = np.arange(0.0, MAX_SPAN_S + 3600.0, 1800.0)  # gaps within the limit, span over it
    gps = GpsStream(t, t * 0.0, t * 0.0)
    with pytest.raises(DataError, match=r"mem: the drive spans 8\.5 h .* over the 8 h allowed"):
        Drive(meta=DriveMeta(name="long", source="mem", format="test"), gps=gps)
    imu = ImuStream(t[:3] + 5e9, t[:3] * 0.0, t[:3] * 0.0)
    with pytest.raises(DataError, match="different clocks"):
        check_span({"gps": t[:3], "imu": imu.t}, "mem")


def test_grids_refuse_before_allocating() -> None:
    assert grid_size(0.0, 10.0, 0.1) == np.arange(0.0, 10.0 + 0.05, 0.1).size
    with pytest.raises(DataError, match=r"x\.csv: a 0\.1 s grid over 3652\.5 days"):
        grid_size(0.0, TEN_YEARS_S, 0.1, "x.csv")
    with pytest.raises(DataError, match="cannot build a time grid"):
        grid_size(0.0, math.inf, 0.1)
    t = np.array([0.0, 0.2, 0.4, 0.6, TEN_YEARS_S])  # a drive no loader lets through
    with pytest.raises(DataError, match=str(MAX_GRID_POINTS)):
        consistency_reference._grid(t, TOLERANCES, "x.csv")


# --------------------------------------------------------------------------- bags


def _bag(
    folder: Path,
    kind: str,
    imu_field: tuple[int, str, tuple[float, ...]] | None = None,
    absent: str | None = None,
    fix_jump: tuple[int, float] | None = None,
    twist_nan_at: int | None = None,
) -> Path:
    """A 12 s bag: /fix (NavSatFix, 5 Hz, moving north-east), /imu (Imu, 50 Hz, level, gravity
    on z) and /vel (TwistStamped, 10 Hz). ``imu_field`` = (message, field, values) replaces one
    IMU field; ``absent`` marks that field absent in every IMU message (covariance[0] = -1);
    ``fix_jump`` = (message, s) moves the fixes from that one on later; ``twist_nan_at`` gives
    that /vel message a NaN speed."""
    from rosbags.typesys import Stores, get_typestore

    ros1 = kind == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    t0 = 1_700_000_000_000_000_000

    def header(t_ns: int, frame: str) -> object:
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if ros1:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def vec(v: tuple[float, ...]) -> object:
        return T["geometry_msgs/msg/Vector3"](x=v[0], y=v[1], z=v[2])

    msgs: list[tuple[str, str, int, object]] = []
    status = T["sensor_msgs/msg/NavSatStatus"](status=0, service=1)
    for k in range(60):
        t_ns = t0 + k * 200_000_000
        if fix_jump is not None and k >= fix_jump[0]:
            t_ns += int(fix_jump[1] * 1e9)
        fix = T["sensor_msgs/msg/NavSatFix"](
            header=header(t_ns, "gps"),
            status=status,
            latitude=49.0 + 1e-5 * k,
            longitude=8.4 + 1e-5 * k,
            altitude=100.0,
            position_covariance=np.zeros(9),
            position_covariance_type=0,
        )
        msgs.append(("/fix", "sensor_msgs/msg/NavSatFix", t_ns, fix))
    for k in range(600):
        t_ns = t0 + 3_000_000 + k * 20_000_000
        fields = {
            "linear_acceleration": (0.1, 0.0, 9.81),
            "angular_velocity": (0.0, 0.0, 0.01),
            "orientation": (1.0, 0.0, 0.0, 0.0),  # w, x, y, z
        }
        if imu_field is not None and k == imu_field[0]:
            fields[imu_field[1]] = imu_field[2]
        cov = {f: np.full(9, -1.0 if f == absent else 0.0) for f in fields}
        w, x, y, z = fields["orientation"]
        imu = T["sensor_msgs/msg/Imu"](
            header=header(t_ns, "imu_link"),
            orientation=T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w),
            orientation_covariance=cov["orientation"],
            angular_velocity=vec(fields["angular_velocity"]),
            angular_velocity_covariance=cov["angular_velocity"],
            linear_acceleration=vec(fields["linear_acceleration"]),
            linear_acceleration_covariance=cov["linear_acceleration"],
        )
        msgs.append(("/imu", "sensor_msgs/msg/Imu", t_ns, imu))
    for k in range(120):
        t_ns = t0 + 7_000_000 + k * 100_000_000
        v = math.nan if k == twist_nan_at else 1.5
        twist = T["geometry_msgs/msg/Twist"](linear=vec((v, 0.0, 0.0)), angular=vec((0, 0, 0)))
        msg = T["geometry_msgs/msg/TwistStamped"](header=header(t_ns, "base_link"), twist=twist)
        msgs.append(("/vel", "geometry_msgs/msg/TwistStamped", t_ns, msg))
    msgs.sort(key=lambda m: m[2])
    topics = {tp: mt for tp, mt, _, _ in msgs}
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        path = folder / "drive.bag"
        with Writer1(path) as w1:
            conns = {tp: w1.add_connection(tp, mt, typestore=ts) for tp, mt in topics.items()}
            for tp, mt, t_ns, msg in msgs:
                w1.write(conns[tp], t_ns, ts.serialize_ros1(msg, mt))
        return path
    from rosbags.rosbag2 import Writer as Writer2

    path = folder / "drive"
    with Writer2(path, version=9) as w2:
        conns = {tp: w2.add_connection(tp, mt, typestore=ts) for tp, mt in topics.items()}
        for tp, mt, t_ns, msg in msgs:
            w2.write(conns[tp], t_ns, ts.serialize_cdr(msg, mt))
    return path


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_nan_from_a_bags_imu_refused_naming_topic_and_message(tmp_path: Path, kind: str) -> None:
    (tmp_path / "ok").mkdir()
    clean = load_rosbag(_bag(tmp_path / "ok", kind))
    assert clean.imu is not None and np.all(np.isfinite(clean.imu.ax))
    path = _bag(tmp_path, kind, imu_field=(17, "linear_acceleration", (math.nan, 0.0, 9.81)))
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(
        r, "topic /imu message 17: non-finite linear_acceleration (nan, 0.0, 9.81)"
    )


@pytest.mark.parametrize(
    ("field", "values", "shown"),
    [
        ("angular_velocity", (0.0, 0.0, math.inf), "angular_velocity (0.0, 0.0, inf)"),
        ("orientation", (math.nan, 0.0, 0.0, 0.0), "orientation (w, x, y, z) (nan, 0.0"),
    ],
)
def test_every_imu_field_refused(
    tmp_path: Path, field: str, values: tuple[float, ...], shown: str
) -> None:
    path = _bag(tmp_path, "ros1", imu_field=(5, field, values))
    with pytest.raises(DataError, match=re.escape(f"topic /imu message 5: non-finite {shown}")):
        load_rosbag(path)


def test_a_field_marked_absent_is_not_read(tmp_path: Path) -> None:
    """REP 145: covariance[0] = -1 says the field is absent; whatever it holds is not a value."""
    path = _bag(
        tmp_path,
        "ros1",
        imu_field=(5, "orientation", (math.nan, 0.0, 0.0, 0.0)),
        absent="orientation",
    )
    d = load_rosbag(path)
    assert d.imu is not None and d.imu.yaw is None


def test_nan_twist_refused(tmp_path: Path) -> None:
    path = _bag(tmp_path, "ros1", twist_nan_at=30)
    with pytest.raises(DataError, match=r"topic /vel message 30: non-finite twist linear"):
        load_rosbag(path)


def test_gap_in_a_bag_names_topic_and_message(tmp_path: Path) -> None:
    path = _bag(tmp_path, "sqlite3", fix_jump=(40, 2 * 3600.0))
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(
        r, "topic /fix message 39: the gps stream's next sample (topic /fix message 40)", "2 h"
    )


# --------------------------------------------------------------------------- other loaders


def test_table_refuses_an_infinite_cell(tmp_path: Path) -> None:
    path = tmp_path / "inf.csv"
    path.write_text("stream,t,x,y,yaw\ngps,0,0,0,\ngps,0.2,1,0,0.1\ntruth,0.2,1,0,inf\n")
    r = bench("data", "inspect", path, cwd=tmp_path)
    assert_one_error_line(r, "inf.csv: line 4, column 'yaw': infinite value inf")


def _route(n_fix: int = 30) -> dict[int, dict]:
    """Windows of 8 fixes (stride 1) of a straight 5 m/s drive, as the paper's pickles hold."""
    t0 = 1_649_851_224_583_364_005
    tf = t0 + np.arange(n_fix, dtype=np.int64) * 200_000_000
    pos = np.stack([np.arange(n_fix) * 1.0, np.zeros(n_fix)], axis=1)
    ta = t0 + 5_000_000 + np.arange(n_fix * 10, dtype=np.int64) * 20_000_000
    return {
        k: {
            "tstamps": [int(t) for t in tf[k : k + 8]],
            "ground_truth": pos[k : k + 8].copy(),
            "ACCEL": [(str(int(t)), 0.25, -0.05) for t in ta[(ta >= tf[k]) & (ta <= tf[k + 7])]],
            "theta": 0.0,
        }
        for k in range(n_fix - 7)
    }


def test_route_pickle_refuses_non_finite_values(tmp_path: Path) -> None:
    path = tmp_path / "route.pickle"
    route = _route()
    route[3]["ACCEL"][2] = (route[3]["ACCEL"][2][0], math.nan, 0.0)
    path.write_bytes(pickle.dumps(route, protocol=5))
    with pytest.raises(DataError, match=r"window 3: ACCEL \(ax, ay\) row 2 is not finite"):
        load_aslan_pickle(path)
    route = _route()
    route[5]["ground_truth"][1, 0] = math.inf
    path.write_bytes(pickle.dumps(route, protocol=5))
    with pytest.raises(DataError, match=r"window 5: ground_truth row 1 is not finite \(inf"):
        load_aslan_pickle(path)
    route = _route()
    for w in list(route.values())[12:]:
        w["tstamps"] = [t + int(2 * MAX_GAP_S * 1e9) for t in w["tstamps"]]
    path.write_bytes(pickle.dumps(route, protocol=5))
    with pytest.raises(
        DataError,
        match=r"window 11 \(tstamps stamp \d+ ns\): the gps stream's next sample \(window 12",
    ):
        load_aslan_pickle(path)


@pytest.mark.shared
def test_kitti_refuses_a_nan_naming_the_data_file(kitti_dir: Path, tmp_path: Path) -> None:
    src = kitti_dir / "2011_09_26" / "2011_09_26_drive_0001_sync"
    dst = tmp_path / "2011_09_26_drive_0001_sync"
    shutil.copytree(src, dst)
    f = dst / "oxts" / "data" / "0000000042.txt"
    values = f.read_text().split()
    values[14] = "nan"  # af, the forward acceleration
    f.write_text(" ".join(values) + "\n")
    r = bench("data", "inspect", dst, cwd=tmp_path)
    assert_one_error_line(r, "0000000042.txt: column 15 (af): non-finite value nan")


@pytest.mark.shared
def test_comma_refuses_a_nan_naming_the_array_and_row(comma_dir: Path, tmp_path: Path) -> None:
    seg = next(p for p in sorted(comma_dir.rglob("processed_log"))).parent
    dst = tmp_path / "route" / "7"
    shutil.copytree(seg, dst)
    f = dst / "processed_log" / "IMU" / "accelerometer" / "value"
    a = np.load(f)
    a[10, 0] = np.nan
    with open(f, "wb") as fh:
        np.save(fh, a)
    r = bench("data", "inspect", dst, cwd=tmp_path)
    assert_one_error_line(r, "accelerometer/value: row 10, forward: non-finite value nan")


@pytest.mark.slow
@pytest.mark.shared
def test_real_drives_far_inside_the_limits(
    kitti_dir: Path, comma_dir: Path, aslan_dir: Path
) -> None:
    """The limits leave the shared real drives a wide margin: their largest gap inside a
    stream is ~1 s (limit 1 h), their longest span minutes (limit 8 h); every one loads."""
    from posbench.scenarios.loaders import load_many

    drives = load_many([kitti_dir, comma_dir, aslan_dir])
    assert len(drives) == 62
    streams = [s for d in drives for s in (d.gps, d.imu, d.speed, d.truth) if s is not None]
    assert max(float(np.diff(s.t).max()) for s in streams if len(s) > 1) < MAX_GAP_S / 1000
    assert max(d.duration_s for d in drives) < MAX_SPAN_S / 10
