"""Issue 46, the drives of a fleet run: the loading processes write each drive to the run's
parts folder, check it there and describe it; the main process plans, checks the options and
reports the data check from those descriptions, and never reads a drive back (the workers
replay them, one at a time). The figures are those of the drives held in memory."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import without_timings

from posbench.config import RunConfig, gps_condition
from posbench.pipeline.data_check import check_drives, to_results
from posbench.pipeline.drives import load_drives, stored_drives
from posbench.pipeline.honoured import unhonoured
from posbench.pipeline.plan import RunOptions, plan_run
from posbench.pipeline.run import execute_run
from posbench.replay.runner import replay_cost
from posbench.scenarios.consistency import check_drive
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import DriveInfo, StoredDrive, as_drive, store_drive
from posbench.scenarios.synthetic import generate_drive


def _json(checks: dict) -> str:
    """The data check's verdicts and figures as results.json holds them (NaN included)."""
    return json.dumps(to_results(checks), sort_keys=True)


def _table(d: Drive) -> pd.DataFrame:
    """``d`` as posbench's long table (fixes, IMU, speed, truth)."""
    parts = [pd.DataFrame({"stream": "gps", "t": d.gps.t, "x": d.gps.x, "y": d.gps.y})]
    assert d.imu is not None and d.truth is not None
    parts.append(
        pd.DataFrame(
            {
                "stream": "imu",
                "t": d.imu.t,
                "ax": d.imu.ax,
                "ay": d.imu.ay,
                "yaw_rate": d.imu.yaw_rate,
            }
        )
    )
    if d.speed is not None:
        parts.append(pd.DataFrame({"stream": "speed", "t": d.speed.t, "v": d.speed.v}))
    parts.append(pd.DataFrame({"stream": "truth", "t": d.truth.t, "x": d.truth.x, "y": d.truth.y}))
    return pd.concat(parts, ignore_index=True)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """Three recordings as Parquet tables."""
    here = tmp_path_factory.mktemp("drives")
    for seed, route in ((1, "mixed"), (2, "roundabout"), (3, "turns")):
        d = generate_drive(seed=seed, route=route, duration_s=60.0)
        _table(d).to_parquet(here / f"{route}.parquet", index=False)
    return here


def test_a_stored_drive_reads_back_as_it_was_with_its_description(tmp_path):
    d = generate_drive(seed=4, route="mixed", duration_s=40.0)
    stored = store_drive(d, tmp_path / "sub" / "d.pickle")
    back = stored.load()
    for stream in ("gps", "imu", "speed", "truth"):
        a, b = getattr(d, stream), getattr(back, stream)
        for f in a.__dataclass_fields__:
            x, y = getattr(a, f), getattr(b, f)
            assert (x is None and y is None) or np.array_equal(x, y, equal_nan=True), (stream, f)
    assert back.meta == d.meta
    info = stored.info
    assert info == DriveInfo.of(d) and DriveInfo.of(stored) is info
    assert (info.name, info.duration_s, info.fix_count) == (d.name, d.duration_s, len(d.gps))
    assert (info.has_truth, info.has_imu, info.has_speed) == (True, True, d.speed is not None)
    assert info.fixes_from_truth == d.fixes_from_truth
    assert info.samples == len(d.gps) + len(d.imu) + (len(d.speed) if d.speed is not None else 0)
    assert stored.check is not None
    assert _json({d.name: stored.check}) == _json({d.name: check_drive(d)})
    assert as_drive(d) is d and as_drive(stored).meta == d.meta


@pytest.mark.parametrize("profile", ["auto", "native", "rtk", "consumer"])
def test_options_and_plans_read_the_same_from_a_description(folder, tmp_path, profile):
    held = load_drives([folder], workers=1)
    stored = stored_drives([folder], tmp_path, workers=2)
    assert all(isinstance(s, StoredDrive) for s in stored)
    assert [s.name for s in stored] == [d.name for d in held]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "drive-000000.pickle",
        "drive-000001.pickle",
        "drive-000002.pickle",
    ]
    cfg = RunConfig(predictors=("cv",), gps_profile=profile)
    assert [gps_condition(cfg, s.info) for s in stored] == [gps_condition(cfg, d) for d in held]
    assert unhonoured(stored, cfg) == unhonoured(held, cfg)
    assert [replay_cost(s, cfg) for s in stored] == [replay_cost(d, cfg) for d in held]
    assert _json(check_drives(stored)) == _json(check_drives(held))


def _figures(res: dict) -> dict:
    """results.json without what differs from run to run (timings, provenance); NaN as
    the saved file holds it (null)."""
    keep = ("predictors", "by_dataset", "by_label", "paired", "drives", "consistency", "limit")
    return {k: without_timings(res[k], nan_as_null=True) for k in keep if k in res}


@pytest.mark.slow
def test_the_main_process_never_reads_a_drive_back(folder, tmp_path, monkeypatch):
    main = os.getpid()
    loads = StoredDrive.load

    def only_in_workers(self: StoredDrive) -> Drive:
        if os.getpid() == main:
            raise AssertionError(f"the main process read drive {self.name}")
        return loads(self)

    monkeypatch.setattr(StoredDrive, "load", only_in_workers)
    opts = RunOptions(data=(folder,), predictors=("cv", "kf"), out=tmp_path / "out", workers=2)
    published = execute_run(plan_run(opts), "test")
    monkeypatch.setattr(StoredDrive, "load", loads)
    # the same figures as the drives replayed from memory, in one process
    from posbench.pipeline.results import build_results
    from posbench.pipeline.run import replay_drives

    plan = plan_run(RunOptions(data=(folder,), predictors=("cv", "kf"), workers=1))
    held = load_drives([folder], workers=1)
    runs = replay_drives(held, plan.config, plan.options, limit=True)
    res = build_results(runs, plan.config, [], "test", models={}, statistics=plan.statistics)
    res["consistency"] = to_results(check_drives(held), plan.config.predictors)
    assert _figures(published.run.results) == _figures(res)
    # the drives are gone with the parts folder once the run is published
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".parts")]
