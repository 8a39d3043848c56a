"""`bench run` wall time against drive hours: writes reports/scaling.json (docs: Speed).

For each size in HOURS, the vehicle-dynamics corpus (scenarios.corpus, 10-minute drives)
is written as Parquet files in posbench's long table format to a temporary folder, then
`bench run --data FOLDER` is timed as a user runs it (a new process, default workers),
once with the default predictors and once with `-p cv` alone. Run from the repository
root (reports/regenerate.sh does): python reports/scaling.py [HOURS ...]
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from posbench.config import DEFAULT_PREDICTORS
from posbench.scenarios.corpus import corpus_drive, corpus_plan
from posbench.scenarios.drive import Drive

HOURS = (1.0, 4.0, 16.0)
OUT = Path(__file__).with_name("scaling.json")


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


def write_corpus(hours: float, folder: Path) -> float:
    """The corpus of >= ``hours`` as Parquet files in ``folder``; its drive hours."""
    total = 0.0
    for seed, profile in corpus_plan(hours):
        d = corpus_drive(seed, profile)
        long_table(d).to_parquet(folder / f"corpus-{seed}.parquet", index=False)
        total += float(d.gps.t[-1] - d.gps.t[0]) / 3600.0
    return total


def timed_run(folder: Path, predictors: str, out: Path) -> float:
    """Wall time [s] of `bench run` over ``folder`` in a new process."""
    cmd = ["bench", "run", "--data", str(folder), "-p", predictors, "--out", str(out), "-q"]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(hours: tuple[float, ...]) -> None:
    rows = []
    default = ",".join(DEFAULT_PREDICTORS)
    for h in hours:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "drives"
            folder.mkdir()
            drive_hours = write_corpus(h, folder)
            walls = {p: timed_run(folder, p, Path(tmp) / "out") for p in ("cv", default)}
        rows.append(
            {
                "hours": h,
                "drive_hours": round(drive_hours, 3),
                "wall_s": {k: round(v, 1) for k, v in walls.items()},
            }
        )
        print(f"{h:g} h: " + ", ".join(f"{k} {v:.0f} s" for k, v in walls.items()), flush=True)
    per_hour = [r["wall_s"][default] / r["drive_hours"] for r in rows]
    OUT.write_text(
        json.dumps(
            {
                "command": "python reports/scaling.py " + " ".join(f"{h:g}" for h in hours),
                "predictors": default,
                "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python "
                f"{platform.python_version()}",
                "runs": rows,
                "seconds_per_drive_hour": {
                    "min": round(float(np.min(per_hour)), 1),
                    "max": round(float(np.max(per_hour)), 1),
                },
            },
            indent=2,
        )
        + "\n"
    )


if __name__ == "__main__":
    main(tuple(float(a) for a in sys.argv[1:]) or HOURS)
