"""Issue 40, "a failed run looks like a normal one": results.json of a run whose command
exited non-zero says so (``status`` failed or interrupted, ``reason`` the error line);
``posbench.load`` and ``bench compare`` refuse it in one line unless asked; results.json
written before schema 1.7 (no status) loads as complete; results.json is replaced
atomically, so a write cut short never leaves a run that loads as complete."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import jsonschema
import pandas as pd
import pytest
from helpers import ROOT, assert_one_error_line, bench

import posbench
from posbench.saved_run.run import (
    COMPLETE,
    FAILED,
    INTERRUPTED,
    RESULTS,
    Run,
    load_run,
    marked_if_unfinished,
    results_schema,
    write_results,
)
from posbench.scenarios.errors import DataError

REPORTS = ROOT / "reports"


@pytest.fixture(scope="module")
def failed_run(tmp_path_factory) -> tuple[Path, str]:
    """``bench run`` on a drive of one fix: nothing can be scored, exit 2; the run's folder
    and its error line."""
    here = tmp_path_factory.mktemp("failed")
    frame = pd.DataFrame({"stream": ["gps"], "t": [0.0], "x": [0.0], "y": [0.0]})
    frame.to_csv(here / "one.csv", index=False)
    r = bench(
        "run", "--data", "one.csv", "-p", "cv", "--out", "out", "--drive-plots", "0",
        "--table-format", "md", "--workers", "1", cwd=here, columns=200,
    )  # fmt: skip
    line = assert_one_error_line(r, "no query of any drive could be scored")
    return here / "out", line


@pytest.mark.slow
def test_results_json_of_a_failed_run_says_failed_and_why(failed_run):
    out, line = failed_run
    res = json.loads((out / RESULTS).read_text())
    assert res["status"] == FAILED
    assert res["reason"] == line.removeprefix("error: ")  # the very line the command printed
    assert (out / "report.md").is_file()  # written all the same, as the line says
    jsonschema.validate(res, results_schema())


@pytest.mark.slow
def test_a_failed_run_is_refused_by_load_and_compare_unless_asked(failed_run):
    out, _ = failed_run
    with pytest.raises(DataError, match=r"a failed run \(no query of any drive"):
        posbench.load(out)
    with pytest.raises(DataError, match="allow_failed=True"):
        posbench.compare(out, out)
    r = bench("compare", out, out, columns=200)
    assert_one_error_line(r, f"{out / RESULTS}: a failed run (", "--allow-failed")

    run = posbench.load(out, allow_failed=True)
    assert (run.status, run.reason) == (FAILED, json.loads((out / RESULTS).read_text())["reason"])
    with pytest.raises(DataError, match="a failed run"):  # a Run object is checked too
        posbench.compare(run, run)
    assert any("is a failed run" in n for n in posbench.compare(run, run, allow_failed=True).notes)
    r = bench("compare", out, out, "--allow-failed", columns=200)
    assert r.returncode == 0, r.stderr
    assert "is a failed run: no query of any drive could be scored" in r.stderr


@pytest.mark.parametrize("name", ["synthetic", "kitti", "outages"])
def test_an_old_results_json_without_status_loads_as_complete(name, tmp_path):
    """A committed report's results.json as schema 1.6 wrote it: no status, no reason."""
    res = json.loads((REPORTS / name / RESULTS).read_text())
    res.pop("status", None)
    res.pop("reason", None)
    res["schema_version"] = "1.6"
    old = tmp_path / name
    old.mkdir()
    (old / RESULTS).write_text(json.dumps(res))
    run = load_run(old)
    assert (run.status, run.reason) == (COMPLETE, None)
    assert posbench.load(old).predictors == run.predictors


@pytest.mark.slow
def test_a_run_interrupted_while_writing_its_report_does_not_load_as_complete(
    tmp_path, monkeypatch
):
    frame = pd.DataFrame({"stream": "gps", "t": [0.2 * i for i in range(50)], "x": 0.0, "y": 0.0})
    frame.to_csv(tmp_path / "d.csv", index=False)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr("posbench.report.markdown.write_report", interrupted)
    with pytest.raises(KeyboardInterrupt):
        posbench.run(
            tmp_path / "d.csv", "cv", tmp_path / "out", drive_plots=0, table_formats="csv",
            workers=1,
        )  # fmt: skip
    with pytest.raises(DataError, match=r"an interrupted run \(interrupted \(Ctrl-C\) while"):
        posbench.load(tmp_path / "out")


def _old_run(tmp_path: Path) -> Run:
    """A copy of the committed synthetic run in ``tmp_path`` (results.json only)."""
    shutil.copy(REPORTS / "synthetic" / RESULTS, tmp_path / RESULTS)
    return load_run(tmp_path)


def test_a_run_interrupted_while_its_files_are_written_is_marked(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    fresh = Run.from_results(json.loads((REPORTS / "synthetic" / RESULTS).read_text()))
    assert fresh.status == COMPLETE  # not saved yet: no results.json in out
    with pytest.raises(KeyboardInterrupt), marked_if_unfinished(fresh, out=out):
        (out / "report.md").write_text("# half a report\n")
        raise KeyboardInterrupt
    res = json.loads((out / RESULTS).read_text())
    assert res["status"] == INTERRUPTED
    assert res["reason"] == "interrupted (Ctrl-C) while writing the run's files"
    jsonschema.validate(res, results_schema())
    with pytest.raises(DataError, match="an interrupted run"):
        load_run(out)
    assert load_run(out, allow_failed=True).status == INTERRUPTED

    saved = _old_run(tmp_path)  # a saved run whose next step fails: its results.json says so
    with pytest.raises(DataError), marked_if_unfinished(saved, "writing the rerun recording"):
        raise DataError("x.rrd", "cannot join the recordings")
    assert load_run(tmp_path, allow_failed=True).reason == "x.rrd: cannot join the recordings"


def test_results_json_is_replaced_whole_or_not_at_all(tmp_path, monkeypatch):
    run = _old_run(tmp_path)
    before = (tmp_path / RESULTS).read_bytes()

    def cut_short(self, text, *args, **kwargs):
        Path.write_bytes(self, text[: len(text) // 2].encode())  # half written, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(Path, "write_text", cut_short)
    with pytest.raises(KeyboardInterrupt):
        write_results(tmp_path, {**run.results, "status": FAILED, "reason": "x"})
    monkeypatch.undo()
    assert (tmp_path / RESULTS).read_bytes() == before  # the previous file, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == [RESULTS]  # no temporary file left
