"""`bench run` wall time and peak memory against drive hours: writes reports/scaling.json
(docs: Speed).

Each case writes its drives as Parquet files in posbench's long table format to a folder,
then runs `bench run --data FOLDER` as a user runs it (a new process, default workers), once
with the default predictors and once with `-p cv` alone (--sets), and records the wall time
and the peak resident memory (RSS) of the processes:

- ``corpus``: the vehicle-dynamics corpus (scenarios.corpus, 10-minute drives) of each size of
  --hours;
- ``long-1hz``: one drive of --long-1hz-hours (8 h) with GPS fixes at 1 Hz (IMU 50 Hz, CAN
  speed 50 Hz, truth 100 Hz);
- ``long-10hz``: one drive of --long-10hz-hours (2 h) with GPS fixes at 10 Hz and IMU at
  100 Hz (CAN speed 50 Hz, truth 100 Hz);
- ``ray``: the corpus of --ray-hours (16 h) with `--executor ray --workers 2` (a local Ray
  instance of 2 CPUs); skipped, with a message, where Ray is not installed.

A long drive is one corpus route (--long-profile, urban: a delivery shift) simulated for the
whole length, its truth, speed and route as the corpus makes them; its fixes are the truth at
exact 1/f s steps plus the corpus's GPS error (white 3 cm + Gauss-Markov 5 cm, 30 s), no
dropouts; its IMU is made from the truth at the asked rate with the synthetic IMU's noise.

Memory: `bench run` runs under a small Python wrapper; every --interval seconds (0.15) this
script lists the wrapper's process tree with psutil and reads each process's peak RSS: the
kernel's high-water mark (VmHWM of /proc/PID/status, Linux), else the RSS sampled. Per
predictor set it records, in MB (10^6 bytes): ``main`` (bench's own process; the Ray driver
in the ray case), ``worker`` (the largest child process below it: replay workers, loaders,
the children combining one predictor's figures each, figure writers; the Ray processes in
the ray case; forked children count the pages they share with the main process) and
``largest`` (the larger of the two), and as a cross-check ``largest_rusage``: the wrapper's
getrusage(RUSAGE_CHILDREN).ru_maxrss, the largest single process among the descendants that
were waited for. psutil is not a dependency of posbench (the dev environment has it through
rerun-sdk, the viz extra): it is imported here only; without it only ``largest_rusage`` is
recorded.

Run from the repository root with posbench's environment's python (its bench is used, else
the one on PATH):

    python reports/scaling.py                     # the standard set (reports/regenerate.sh)
    python reports/scaling.py --hours 0.5 --cases corpus --json /tmp/scaling.json
    python reports/scaling.py --cases long-1hz --long-1hz-hours 1 --sets default

Without --json the results replace reports/scaling.json, the reference the docs show.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.config import DEFAULT_PREDICTORS
from posbench.scenarios.corpus import PROFILES, corpus_drive, corpus_plan
from posbench.scenarios.degrade import gps_noise
from posbench.scenarios.drive import Drive, GpsStream
from posbench.scenarios.synthetic_sensors import GPS_GM_SD, GPS_GM_TAU_S, GPS_WHITE_SD, imu_stream

OUT = Path(__file__).with_name("scaling.json")
CASES = ("corpus", "long-1hz", "long-10hz", "ray")
SETS = ("default", "cv")
DEFAULT_HOURS = (4.0, 16.0, 64.0)
#: the seed of the long drives (one corpus generator seed, far from corpus_plan's)
LONG_SEED = 900_000
MB = 1e6

#: runs the command of its arguments after the first; writes its wall time, exit status and
#: getrusage(RUSAGE_CHILDREN).ru_maxrss [KiB on Linux] as JSON to the first
WRAPPER = """\
import json, resource, subprocess, sys, time
t0 = time.perf_counter()
rc = subprocess.call(sys.argv[2:], stdout=subprocess.DEVNULL)
wall = time.perf_counter() - t0
r = resource.getrusage(resource.RUSAGE_CHILDREN)
with open(sys.argv[1], "w") as f:
    json.dump({"rc": rc, "wall_s": wall, "maxrss_kib": r.ru_maxrss}, f)
"""


# ------------------------------------------------------------------------------- the data
def long_table(d: Drive) -> pd.DataFrame:
    """The drive as rows of posbench's long table format (docs: The CSV format)."""
    parts = [pd.DataFrame({"stream": "gps", "t": d.gps.t, "x": d.gps.x, "y": d.gps.y})]
    if d.imu is not None:
        imu = {"stream": "imu", "t": d.imu.t, "ax": d.imu.ax, "ay": d.imu.ay}
        if d.imu.yaw is not None:
            imu["yaw"] = d.imu.yaw
        if d.imu.yaw_rate is not None:
            imu["yaw_rate"] = d.imu.yaw_rate
        parts.append(pd.DataFrame(imu))
    if d.speed is not None:
        parts.append(pd.DataFrame({"stream": "speed", "t": d.speed.t, "v": d.speed.v}))
    if d.truth is not None:
        tr = d.truth
        truth = {"stream": "truth", "t": tr.t, "x": tr.x, "y": tr.y}
        if tr.yaw is not None:
            truth["yaw"] = tr.yaw
        parts.append(pd.DataFrame(truth))
    return pd.concat(parts, ignore_index=True)


def drive_hours(d: Drive) -> float:
    """The span of the drive's fixes [h]."""
    return float(d.gps.t[-1] - d.gps.t[0]) / 3600.0


def write_corpus(hours: float, folder: Path) -> tuple[float, int]:
    """The corpus of >= ``hours`` as Parquet files in ``folder``; its drive hours and drives."""
    total, plan = 0.0, corpus_plan(hours)
    for seed, profile in plan:
        d = corpus_drive(seed, profile)
        long_table(d).to_parquet(folder / f"corpus-{seed}.parquet", index=False)
        total += drive_hours(d)
    return total, len(plan)


def long_drive(hours: float, fix_hz: float, imu_hz: int, profile: str = "urban") -> Drive:
    """One drive of ``hours`` (module doc): the corpus route, speed and truth of one seed,
    fixes at ``fix_hz`` (the truth plus the corpus's GPS error) and an IMU at ``imu_hz``
    (100 or 50 Hz, 0: none) made from the truth."""
    d = corpus_drive(LONG_SEED, profile, hours * 3600.0)
    tr = d.truth
    assert tr is not None and tr.yaw is not None and tr.v is not None
    rng = np.random.default_rng([LONG_SEED, int(round(fix_hz * 1000)), imu_hz])
    dt = float(np.median(np.diff(tr.t[:1000])))  # 0.01 s
    i = np.arange(0, tr.t.size, max(1, int(round(1.0 / (fix_hz * dt)))))
    e = gps_noise(tr.t[i], rng, GPS_WHITE_SD, GPS_GM_SD, GPS_GM_TAU_S)
    acc = np.full(i.size, float(np.hypot(GPS_WHITE_SD, GPS_GM_SD)))
    gps = GpsStream(tr.t[i], tr.x[i] + e[:, 0], tr.y[i] + e[:, 1], accuracy=acc)
    imu = None
    if imu_hz:
        yaw = np.unwrap(tr.yaw)
        step = max(1, int(round(1.0 / (imu_hz * dt))))
        imu = imu_stream(
            tr.t, yaw, tr.v, np.gradient(yaw, tr.t), np.gradient(tr.v, tr.t), rng, step=step
        )
    name = f"long-{profile}-{hours:g}h-{fix_hz:g}hz"
    meta = replace(d.meta, name=name, source=f"scaling:{name}", extra={})
    return Drive(meta=meta, gps=gps, imu=imu, speed=d.speed, truth=tr)


def write_long(
    hours: float, fix_hz: float, imu_hz: int, folder: Path, profile: str
) -> tuple[float, int]:
    """:func:`long_drive` as one Parquet file in ``folder``; its drive hours and 1."""
    d = long_drive(hours, fix_hz, imu_hz, profile)
    long_table(d).to_parquet(folder / f"{d.name}.parquet", index=False)
    return drive_hours(d), 1


# ------------------------------------------------------------------------- measuring
def _hwm_bytes(pid: int) -> int | None:
    """The peak RSS the kernel has seen of ``pid`` (VmHWM), or None (not Linux, gone)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def _label(args: Sequence[str]) -> str:
    """A process's name from its command line: the script a Python runs (bench,
    default_worker.py), or the program (raylet, ray::run_predictor)."""
    if not args:
        return "?"
    first = Path(args[0].split()[0]).name
    scripts = [a for a in args[1:] if not a.startswith("-")]
    return Path(scripts[0]).name if first.startswith("python") and scripts else first


def measure(cmd: Sequence[str], interval_s: float = 0.15) -> dict[str, Any]:
    """Run ``cmd`` under :data:`WRAPPER`, sampling its process tree every ``interval_s``:
    wall time [s] and peak RSS [MB] of the main process (the wrapper's child), of its largest
    descendant (``worker``, None without one; ``worker_name`` its name), of the
    largest, and getrusage's cross-check.

    Raises:
        RuntimeError: the command failed (its stderr's tail in the message).
    """
    try:
        import psutil
    except ImportError:
        psutil = None
    with tempfile.TemporaryDirectory() as tmp:
        report, err = Path(tmp) / "rusage.json", Path(tmp) / "stderr.txt"
        with open(err, "wb") as stderr:
            proc = subprocess.Popen(
                [sys.executable, "-c", WRAPPER, str(report), *cmd],
                stdout=subprocess.DEVNULL,
                stderr=stderr,
            )
        peaks: dict[int, int] = {}
        names: dict[int, str] = {}
        main_pid: int | None = None
        root = psutil.Process(proc.pid) if psutil is not None else None
        while proc.poll() is None:
            if root is not None:
                try:
                    if main_pid is None:
                        direct = root.children()
                        main_pid = direct[0].pid if direct else None
                    tree = root.children(recursive=True)
                except psutil.NoSuchProcess:
                    tree = []
                for p in tree:
                    try:
                        peak = max(p.memory_info().rss, _hwm_bytes(p.pid) or 0)
                        if peak > peaks.get(p.pid, 0):
                            peaks[p.pid], names[p.pid] = peak, _label(p.cmdline())
                    except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
                        continue
            time.sleep(interval_s)
        if proc.returncode != 0 or not report.is_file():
            raise RuntimeError(f"wrapper failed ({proc.returncode}): {err.read_text()[-2000:]}")
        res = json.loads(report.read_text())
        if res["rc"] != 0:
            raise RuntimeError(f"{shlex.join(cmd)} exited {res['rc']}:\n{err.read_text()[-2000:]}")
    main = peaks.pop(main_pid, None) if main_pid is not None else None
    worker_pid = max(peaks, key=peaks.__getitem__, default=None)
    worker = peaks[worker_pid] if worker_pid is not None else None
    largest = max((v for v in (main, worker) if v is not None), default=None)
    maxrss = res["maxrss_kib"] * (1 if sys.platform == "darwin" else 1024)  # bytes on macOS

    def mb(v: int | None) -> float | None:
        return None if v is None else round(v / MB, 1)

    return {
        "wall_s": res["wall_s"],
        "rss": {
            "main": mb(main),
            "worker": mb(worker),
            "largest": mb(largest),
            "largest_rusage": mb(maxrss),
            "worker_name": names.get(worker_pid) if worker_pid is not None else None,
        },
    }


def bench_run(
    folder: Path, predictors: str, out: Path, extra: Sequence[str] = (), interval_s: float = 0.15
) -> dict[str, Any]:
    """:func:`measure` of `bench run` over ``folder`` (its output in ``out``)."""
    beside = Path(sys.executable).parent / "bench"  # this interpreter's venv, else PATH's
    bench = str(beside) if beside.is_file() else shutil.which("bench") or "bench"
    cmd = [bench, "run", "--data", str(folder), "-p", predictors, "--out", str(out), "-q"]
    return measure([*cmd, *extra], interval_s)


# ---------------------------------------------------------------------------- the cases
def run_case(
    case: str,
    size: float,
    args: argparse.Namespace,
    sets: dict[str, str],
    work: Path,
) -> dict[str, Any]:
    """One case at one size: the data written to ``work/data``, each predictor set run with
    its output in ``work/out-SET``; the record of scaling.json."""
    data = work / "data"
    if data.exists():
        raise SystemExit(f"{work} holds an earlier run: give --work an empty folder")
    data.mkdir(parents=True)
    extra: list[str] = [] if args.workers is None else ["--workers", str(args.workers)]
    row: dict[str, Any] = {"case": case}
    if case in ("corpus", "ray"):
        hours, n = write_corpus(size, data)
        row["hours"] = size
        if case == "ray":
            extra = ["--executor", "ray", "--workers", str(args.workers or 2)]
            row["executor"] = "ray"
            row["workers"] = args.workers or 2
    elif case == "long-1hz":
        hours, n = write_long(size, 1.0, 50, data, args.long_profile)
        row.update(fix_hz=1.0, imu_hz=50)
    elif case == "long-10hz":
        hours, n = write_long(size, 10.0, 100, data, args.long_profile)
        row.update(fix_hz=10.0, imu_hz=100)
    else:
        raise ValueError(case)
    row.update(drive_hours=round(hours, 3), drives=n)
    walls, per_hour, rss = {}, {}, {}
    for label, predictors in sets.items():
        m = bench_run(data, predictors, work / f"out-{label}", extra, args.interval)
        walls[predictors] = round(m["wall_s"], 1)
        per_hour[predictors] = round(m["wall_s"] / hours, 1)
        rss[predictors] = m["rss"]
        r = m["rss"]
        print(
            f"{case} {hours:.2f} drive h, -p {label}: {m['wall_s']:.1f} s, peak RSS main "
            f"{r['main']} MB, worker {r['worker']} MB, largest {r['largest']} MB "
            f"(getrusage {r['largest_rusage']} MB)",
            flush=True,
        )
    row.update(wall_s=walls, seconds_per_drive_hour=per_hour, peak_rss_mb=rss)
    return row


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python reports/scaling.py",
        description="Time `bench run` and record its processes' peak memory (RSS) against "
        "drive hours; write the results as JSON (the docs' Speed page reads "
        "reports/scaling.json).",
        epilog="A small trial: python reports/scaling.py --hours 0.5 --cases corpus "
        "--json /tmp/scaling.json",
    )
    p.add_argument(
        "--cases",
        default=",".join(CASES),
        help=f"comma-separated cases to run, of {', '.join(CASES)} (default: all)",
    )
    p.add_argument(
        "--hours",
        nargs="+",
        type=float,
        default=list(DEFAULT_HOURS),
        metavar="H",
        help="corpus sizes [h] of the corpus case "
        f"(default: {' '.join(f'{h:g}' for h in DEFAULT_HOURS)})",
    )
    p.add_argument(
        "--long-1hz-hours",
        type=float,
        default=8.0,
        metavar="H",
        help="length [h] of the long-1hz drive (default: 8)",
    )
    p.add_argument(
        "--long-10hz-hours",
        type=float,
        default=2.0,
        metavar="H",
        help="length [h] of the long-10hz drive (default: 2)",
    )
    p.add_argument(
        "--ray-hours",
        type=float,
        default=16.0,
        metavar="H",
        help="corpus size [h] of the ray case (default: 16)",
    )
    p.add_argument(
        "--long-profile",
        choices=PROFILES,
        default="urban",
        help="corpus profile of the long drives (default: urban)",
    )
    p.add_argument(
        "--sets",
        default=",".join(SETS),
        help="predictor sets, comma-separated: default (the default predictors), cv "
        "(-p cv) (default: default,cv)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        help="bench run --workers (default: bench's own default; the ray case: 2)",
    )
    p.add_argument(
        "--interval",
        type=float,
        default=0.15,
        metavar="S",
        help="seconds between samples of the process tree (default: 0.15)",
    )
    p.add_argument(
        "--json",
        type=Path,
        default=OUT,
        metavar="PATH",
        help="where the results go (default: reports/scaling.json, the reference the docs "
        "show; give another path for a trial run)",
    )
    p.add_argument(
        "--work",
        type=Path,
        default=None,
        metavar="DIR",
        help="keep each case's data and bench run outputs in DIR/CASE-SIZE/ (default: a "
        "temporary folder, removed after each case)",
    )
    a = p.parse_args(argv)
    a.case_list = [c.strip() for c in a.cases.split(",") if c.strip()]
    bad = [c for c in a.case_list if c not in CASES]
    if bad or not a.case_list:
        p.error(f"--cases: unknown case {bad[0] if bad else a.cases!r}; use {', '.join(CASES)}")
    a.set_list = [s.strip() for s in a.sets.split(",") if s.strip()]
    bad = [s for s in a.set_list if s not in SETS]
    if bad or not a.set_list:
        p.error(f"--sets: unknown set {bad[0] if bad else a.sets!r}; use {', '.join(SETS)}")
    sizes = [*a.hours, a.long_1hz_hours, a.long_10hz_hours, a.ray_hours]
    if not all(np.isfinite(h) and h > 0 for h in sizes):
        p.error("every size must be > 0 hours")
    if not a.interval > 0:
        p.error("--interval must be > 0")
    return a


def _ray_missing() -> str | None:
    import importlib.util

    if importlib.util.find_spec("ray") is None:
        return "Ray is not installed (pip install 'posbench-harness[ray]')"
    return None


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    default = ",".join(DEFAULT_PREDICTORS)
    sets = {s: (default if s == "default" else "cv") for s in ("cv", "default")}
    sets = {k: v for k, v in sets.items() if k in args.set_list}
    sizes = {
        "corpus": list(args.hours),
        "long-1hz": [args.long_1hz_hours],
        "long-10hz": [args.long_10hz_hours],
        "ray": [args.ray_hours],
    }
    runs: list[dict[str, Any]] = []
    cases: list[dict[str, Any]] = []
    for case in args.case_list:
        if case == "ray" and (why := _ray_missing()):
            print(f"ray case skipped: {why}", flush=True)
            cases.append({"case": "ray", "skipped": why})
            continue
        for size in sizes[case]:
            with tempfile.TemporaryDirectory() as tmp:
                work = Path(tmp) if args.work is None else args.work / f"{case}-{size:g}h"
                row = run_case(case, size, args, sets, work)
            (runs if case == "corpus" else cases).append(row)
    given = sys.argv[1:] if argv is None else list(argv)
    result: dict[str, Any] = {
        "command": shlex.join(["python", "reports/scaling.py", *given]),
        "predictors": default,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}",
        "runs": runs,
    }
    per_hour = [r["wall_s"][default] / r["drive_hours"] for r in runs if default in r["wall_s"]]
    if per_hour:
        result["seconds_per_drive_hour"] = {
            "min": round(float(np.min(per_hour)), 1),
            "max": round(float(np.max(per_hour)), 1),
        }
    result["cases"] = cases
    result["rss"] = (
        "peak resident memory [MB] per process: main = bench's own process (the Ray driver "
        "with --executor ray), worker = the largest process below it, largest = the larger; "
        "largest_rusage = getrusage(RUSAGE_CHILDREN).ru_maxrss of a wrapper (the largest "
        "process among the descendants waited for)"
    )
    args.json.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.json}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
