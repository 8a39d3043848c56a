"""reports/scaling.py at a small scale, as a bound on memory: `bench run` with the default
predictors over 1 h of corpus drives (6 drives of 10 min) and over one 1 h drive with 1 Hz
fixes, each in a new process as a user runs it, finishes with its results.json, and no
process of either run holds more than :data:`LIMIT_MB` of resident memory at its peak.

The bound is generous (a run of 1 h took 0.4-0.7 GB at the largest process on the
development machine): it catches a run whose memory grows by multiples, not a drift.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from helpers import ROOT

pytestmark = pytest.mark.slow

#: peak RSS [MB] no process of a 1-hour run may reach
LIMIT_MB = 2500.0


def test_one_hour_runs_stay_under_the_memory_bound(tmp_path):
    out, work = tmp_path / "scaling.json", tmp_path / "work"
    r = subprocess.run(
        [
            sys.executable,
            str(ROOT / "reports" / "scaling.py"),
            "--cases",
            "corpus,long-1hz",
            "--hours",
            "1",
            "--long-1hz-hours",
            "1",
            "--sets",
            "default",
            "--json",
            str(out),
            "--work",
            str(work),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    res = json.loads(out.read_text())
    rows = res["runs"] + res["cases"]
    assert [row["case"] for row in rows] == ["corpus", "long-1hz"]
    for row in rows:
        case = row["case"]
        assert row["drives"] == (6 if case == "corpus" else 1)
        assert row["drive_hours"] == pytest.approx(1.0, abs=0.01)
        results = json.loads((work / f"{case}-1h" / "out-default" / "results.json").read_text())
        assert len(results["drives"]) == row["drives"], case
        assert not [d for d in results["drives"] if d.get("skipped")], case
        rss = row["peak_rss_mb"][res["predictors"]]
        # getrusage's figure needs no psutil; the sampled ones are there when psutil is
        assert 0 < rss["largest_rusage"] < LIMIT_MB, (case, rss)
        if rss["largest"] is not None:
            assert rss["main"] is not None and rss["worker"] is not None, (case, rss)
            assert 0 < rss["largest"] < LIMIT_MB, (case, rss)
