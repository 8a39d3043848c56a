"""The reference named (issue 35): where a data set has no truth, the terminal, report.md and
results.json say its figures are measured against the receiver's own fixes; "true metres"
only where a truth is the reference. A tuned baseline is said to be tuned on its development
drives (not trained as a bundled model), and the tuning section names the file, its hash and
each set of development drives once."""

from __future__ import annotations

import json
from dataclasses import replace

import jsonschema
import pandas as pd
import pytest
from helpers import bench

from posbench.config import RunConfig
from posbench.pipeline.results import build_results
from posbench.replay.runner import run
from posbench.report.markdown import render_markdown
from posbench.report.notes import held_out_note, trained_note, tuning_lines
from posbench.saved_run.run import SCHEMA_VERSION, Run, results_schema
from posbench.scenarios.drive import Drive
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.reference import FIXES_TEXT, dataset_references, references

#: what the terminal and report.md say of a data set scored against its receiver's own fixes
FIXES_LINE = f"reference in `table`: {FIXES_TEXT}"


def receiver_only(seconds: float = 20.0) -> Drive:
    """A drive as a GPS-only table loads: fixes of its own receiver, no truth."""
    d = generate_drive(seed=1, route="turns", duration_s=seconds)
    return replace(d, truth=None, meta=replace(d.meta, name="receiver-only", format="table"))


@pytest.fixture(scope="module")
def mixed_run() -> dict:
    """results.json of cv over a receiver-only drive (data set `table`) and a synthetic
    drive with its truth (data set `synthetic`)."""
    drives = [receiver_only(), generate_drive(seed=0, duration_s=20.0)]
    cfg = RunConfig(predictors=("cv",))
    return build_results(run(drives, cfg, workers=1), cfg, [], "test")


def test_results_json_names_each_data_sets_reference(mixed_run):
    refs = mixed_run["references"]
    assert refs["table"] == {"kind": "fixes", "text": FIXES_TEXT}
    assert refs["synthetic"]["kind"] == "truth"
    assert refs["synthetic"]["truth"] == "the simulated vehicle path"
    assert refs["synthetic"]["text"] == (
        "the truth, the simulated vehicle path (errors in true metres)"
    )
    by_name = {d["name"]: d for d in mixed_run["drives"]}
    assert by_name["receiver-only"]["truth_source"] == ""
    assert by_name["synthetic-mixed-s0"]["truth_source"] == "the simulated vehicle path"
    saved = Run.from_results(mixed_run).results  # as results.json holds it
    assert saved["schema_version"] == SCHEMA_VERSION
    jsonschema.validate(saved, results_schema())


def test_report_opens_with_the_reference_of_each_data_set(mixed_run):
    md = render_markdown(mixed_run, [])
    top = md.split("## All drives")[0]
    assert f"- R{FIXES_LINE[1:]}." in top
    assert (
        "- Reference in `synthetic`: the truth, the simulated vehicle path (errors in true "
        "metres); fixes scored: simulated `rtk` fixes drawn from the truth." in top
    )
    # true metres only where a truth is the reference
    for line in md.splitlines():
        if "true metres" in line:
            assert "the truth" in line and "`table`" not in line, line
    table = md.split("## Data set `table`")[1].split("###")[0]
    assert f"1 drive; reference: {FIXES_TEXT}; the reference position" in table


def test_older_runs_say_their_reference_from_their_drives():
    """results.json before schema 1.8 has no references and no truth_source: the drives'
    reference says which, the data set names the truth."""
    drives = [
        {"name": "a", "dataset": "kitti", "reference": "truth", "skipped": None},
        {"name": "b", "dataset": "aslan", "reference": "cubic through surrounding fixes"},
        {"name": "c", "dataset": "aslan", "reference": "", "skipped": "poor truth"},
    ]
    refs = references({"drives": drives})
    assert list(refs) == ["kitti", "aslan"]
    assert refs["kitti"]["truth"] == "the OXTS RT3003 INS/GNSS solution"
    assert refs["aslan"] == {"kind": "fixes", "text": FIXES_TEXT}
    # a saved 1.8 run's own references are read as they are
    assert references({"references": {"x": {"kind": "fixes", "text": "t"}}, "drives": drives}) == {
        "x": {"kind": "fixes", "text": "t"}
    }


def test_a_data_set_of_both_kinds_says_both_in_one_line():
    drives = [
        {"name": "a", "dataset": "ros2", "reference": "truth", "truth_source": "topic /rtk"},
        {"name": "b", "dataset": "ros2", "reference": "cubic through surrounding fixes"},
        {"name": "c", "dataset": "ros2", "reference": "cubic through surrounding fixes"},
    ]
    ref = dataset_references(drives)["ros2"]
    assert ref["kind"] == "mixed" and ref["drives"] == {"fixes": 2, "truth": 1}
    assert ref["text"].startswith("the truth, topic /rtk (errors in true metres) on 1 drive; ")
    assert "the receiver's own fixes on 2 drives (no independent truth" in ref["text"]
    assert "\n" not in ref["text"]


def _tuned(res: dict) -> dict:
    """``res`` as a run of cv, kf and ekf tuned with the built-in file: its development drives
    per GPS condition, shared by all three (the shape of reports/outages)."""
    native = [f"aslan-{i}" for i in range(12)]
    rtk = [f"synthetic-{i}" for i in range(3)]
    cmd = "`bench tune {p} --gps-profile native --calibrate-only " + " ".join(
        f"--data ../shared/data/aslan/{n}.pickle" for n in native
    )
    paths = ", ".join(f"../shared/data/aslan/{n}.pickle" for n in native)

    def entry(p: str) -> dict:
        return {
            "file": "posbench/predictors/tuned.json",
            "built_in": True,
            "sha256": "2a77c01e9afc" + "0" * 52,
            "conditions": {
                "native": {
                    "params": {"cov_scale": 1.43},
                    "how": f"cov_scale for 95 % coverage by {cmd.format(p=p)}` on development "
                    f"drives {paths}",
                    "file": "posbench/predictors/tuned.json",
                    "drives": native,
                },
                "rtk": {
                    "params": {"cov_scale": 0.18},
                    "how": f"cov_scale for 95 % coverage by `bench tune {p} --gps-profile rtk "
                    "--calibrate-only --drives 3` on synthetic development drives, seeds 1000-1002",
                    "file": "posbench/predictors/tuned.json",
                    "drives": rtk,
                },
            },
            "drives": sorted(native + rtk),
        }

    names = ("cv", "kf", "ekf")
    drives = [
        {"name": n, "dataset": "aslan", "skipped": None, "reference": "cubic"}
        for n in [*native, "aslan-held"]
    ]
    return {
        **res,
        "drives": drives,
        "tuning": {p: entry(p) for p in names},
        "models": {
            p: {
                "model": "tuning posbench/predictors/tuned.json",
                "bundled": True,
                "train_drives": sorted(native + rtk),
            }
            for p in names
        },
        "training_drives": {p: sorted(native + rtk) for p in names},
    }


def test_a_tuned_baseline_is_tuned_on_its_development_drives_not_a_bundled_model(mixed_run):
    res = _tuned(mixed_run)
    note = trained_note(res)
    assert "bundled" not in note and "model.onnx" not in note
    assert note.startswith(
        "* cv, kf and ekf were tuned on 12 of these 13 drives (development drives of the "
        "built-in predictors/tuned.json)"
    )
    held = held_out_note(res, [f"aslan-{i}" for i in range(12)])
    assert held.startswith("`cv`, `kf` and `ekf` were tuned (development drives of the built-in")
    assert held.count("aslan-3") == 1


def test_tuning_names_file_hash_and_drives_once(mixed_run):
    lines = tuning_lines(_tuned(mixed_run))
    text = "\n".join(lines)
    assert text.count("sha256 2a77c01e9afc") == 1 and text.count("predictors/tuned.json") == 1
    assert text.count("aslan-3") == 1 and text.count("synthetic-2") == 1  # each set once
    assert "bench tune" not in text.replace("the `bench tune` command", "")  # in results.json
    assert "../shared" not in text and max(len(x) for x in lines) < 400
    assert (
        "- `kf`: native [D1]: cov_scale=1.43 (cov_scale for 95 % coverage on the development "
        "drives); rtk [D2]: cov_scale=0.18 (cov_scale for 95 % coverage on synthetic "
        "development drives, seeds 1000-1002)" in lines
    )
    assert lines[-2].startswith("- development drives D2 (3): synthetic-0, synthetic-1")


def test_the_terminal_says_each_reference_in_one_line(mixed_run, capsys, monkeypatch):
    """One line per data set, wrapped to the terminal's width (80 columns) as every line of
    the summary is."""
    from posbench.cli.summary import print_run_summary
    from posbench.pipeline.publish import Published

    monkeypatch.setenv("COLUMNS", "80")
    print_run_summary(Published(Run.from_results(mixed_run)))
    out = capsys.readouterr().out
    assert max(len(line) for line in out.splitlines()) <= 80
    assert [line.split(":")[0] for line in out.splitlines() if line.startswith("ref")] == [
        "reference in table",
        "reference in synthetic",
    ]
    assert " ".join(out.split()).startswith(
        FIXES_LINE.replace("`", "") + " reference in synthetic: the truth, the simulated "
        "vehicle path (errors in true metres); fixes scored: simulated rtk fixes drawn from "
        "the truth 2 drives - errors in metres"
    )


@pytest.mark.slow
def test_bench_run_names_a_fixes_only_reference(tmp_path):
    d = receiver_only(15.0)
    csv = tmp_path / "receiver.csv"
    pd.DataFrame({"t": d.gps.t, "x": d.gps.x, "y": d.gps.y}).to_csv(csv, index=False)
    out = tmp_path / "o"
    r = bench(
        "run", "--data", csv, "-p", "cv", "--out", out, "--workers", "1", "--drive-plots", "0",
        "--table-format", "md", "--plot-format", "svg", columns=80,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert FIXES_LINE.replace("`", "") in " ".join(r.stdout.split())
    assert max(len(line) for line in r.stdout.splitlines()) <= 80
    assert "true metres" not in r.stdout and "Traceback" not in r.stderr
    res = json.loads((out / "results.json").read_text())
    assert res["references"] == {"table": {"kind": "fixes", "text": FIXES_TEXT}}
    assert f"- R{FIXES_LINE[1:]}." in (out / "report.md").read_text()
