"""`bench compare`: aligned figures, flagged configs, paired differences and the accuracy gate.

One real synthetic run (cv, kf) is made once; the other runs are copies of it, some with
their kf figures scaled by hand in results.json (a known regression) or their config
changed, so every verdict below has a known right answer.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_cli_errors import assert_one_error_line, bench

from bench.compare import (
    Gate,
    Metric,
    aligned,
    check_gates,
    config_differences,
    paired_difference,
    run_labels,
)
from bench.options import UsageError
from bench.saved_run import load_run

STATS = ("mean_m", "median_m", "rmse_m", "p95_m", "max_m")


@pytest.fixture(scope="module")
def base_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cmp") / "old"
    r = bench("run", "-p", "cv,kf", "--out", str(out), "--drive-plots", "0", timeout=300)
    assert r.returncode == 0, r.stderr
    return out


def _copy(src: Path, dst: Path, kf_scale: float = 1.0, config: dict | None = None,
          drop_drives: int = 0) -> Path:
    """A copy of run ``src`` whose kf figures (whole run and per drive) are ``kf_scale``
    times larger, with ``config`` keys overridden and the last ``drop_drives`` drives gone."""
    shutil.copytree(src, dst)
    p = dst / "results.json"
    res = json.loads(p.read_text())

    def scale(s: dict) -> None:
        for k in STATS:
            if s.get(k) is not None:
                s[k] *= kf_scale
            ci = (s.get("ci95") or {}).get(k)
            if ci and None not in ci:
                s["ci95"][k] = [c * kf_scale for c in ci]

    for kind in ("future", "now"):
        scale(res["predictors"]["kf"][kind])
        for ds in res["by_dataset"].values():
            scale(ds["kf"][kind])
    for d in res["drives"]:
        for kind in ("future", "now"):
            scale(d["predictors"]["kf"][kind])
    if drop_drives:
        res["drives"] = res["drives"][:-drop_drives]
    res["config"].update(config or {})
    p.write_text(json.dumps(res))
    return dst


def test_metric_and_gate_parsing() -> None:
    assert Metric.parse("now.p95_m") == Metric("now", "p95_m")
    g = Gate.parse("lstm:future.mean_m:5%")
    assert (g.predictor, str(g.metric), g.relative) == ("lstm", "future.mean_m", True)
    assert g.limit(0.10) == pytest.approx(0.105)
    g = Gate.parse("kf:now.max_m:0.02m")
    assert not g.relative and g.limit(0.10) == pytest.approx(0.12)
    for bad in ("future", "later.mean_m", "future.mean"):
        with pytest.raises(UsageError, match="not a metric"):
            Metric.parse(bad)
    for bad in ("lstm", "lstm:future.mean_m", "lstm:future.mean_m:5", "lstm:future.mean_m:x%",
                ":future.mean_m:5%"):
        with pytest.raises(UsageError):
            Gate.parse(bad)


def test_identical_runs_differ_by_exactly_zero(base_run: Path, tmp_path: Path) -> None:
    old, new = load_run(base_run), load_run(_copy(base_run, tmp_path / "new"))
    assert config_differences([old, new], run_labels([old, new])) == []
    for stat in STATS:
        p = paired_difference(old, new, "kf", Metric("future", stat))
        assert p.diff == 0 and p.lo == 0 and p.hi == 0 and p.drives == 4, (stat, p)
        assert not p.conclusive
    checks = check_gates(old, new, [Gate.parse("kf:future.mean_m:0%")])
    assert not checks[0].failed


def test_paired_mean_matches_pooled_figures(base_run: Path, tmp_path: Path) -> None:
    old = load_run(base_run)
    new = load_run(_copy(base_run, tmp_path / "new", kf_scale=1.3))
    p = paired_difference(old, new, "kf", Metric("future", "mean_m"))
    want_old = old.results["predictors"]["kf"]["future"]["mean_m"]
    assert p.old == pytest.approx(want_old, rel=1e-12)
    assert p.new == pytest.approx(1.3 * want_old, rel=1e-12)
    # every drive got 30 % worse: every resample is worse, the CI sits above 0
    assert 0 < p.lo <= p.diff <= p.hi
    assert p.conclusive
    # the same seed gives the same CI; another seed a slightly different one
    again = paired_difference(old, new, "kf", Metric("future", "mean_m"))
    assert (again.lo, again.hi) == (p.lo, p.hi)


def test_one_shared_drive_has_no_ci_and_cannot_fail_a_gate(base_run: Path, tmp_path: Path) -> None:
    old = load_run(base_run)
    new = load_run(_copy(base_run, tmp_path / "new", kf_scale=2.0, drop_drives=3))
    p = paired_difference(old, new, "kf", Metric("future", "mean_m"))
    assert p.drives == 1 and np.isnan(p.lo) and np.isnan(p.hi) and p.diff > 0
    assert not check_gates(old, new, [Gate.parse("kf:future.mean_m:1%")])[0].failed


def test_aligned_keeps_rows_missing_from_one_run(base_run: Path, tmp_path: Path) -> None:
    old = load_run(base_run)
    new = load_run(_copy(base_run, tmp_path / "new", drop_drives=1))
    labels = run_labels([old, new])
    assert labels == ["old", "new"]
    f = aligned([old, new], labels, Metric("future", "mean_m"))
    drives = f[f["scope"] == "drive"]
    assert len(drives) == 2 * 4  # cv and kf on 4 drives
    missing = drives[drives["new"].isna()]
    assert len(missing) == 2 and (missing["new n"] == 0).all()
    assert set(f["scope"]) == {"all", "dataset", "route type", "drive"}


def test_config_differences_are_named(base_run: Path, tmp_path: Path) -> None:
    old = load_run(base_run)
    new = load_run(_copy(base_run, tmp_path / "new", config={"horizon_s": 0.4,
                                                            "gps_profile": "consumer"}))
    lines = config_differences([old, new], ["old", "new"])
    assert any(x.startswith("horizon_s: 0.2 (old), 0.4 (new)") for x in lines), lines
    assert any(x.startswith("gps_profile:") for x in lines), lines


def test_cli_gate_fails_on_a_real_regression(base_run: Path, tmp_path: Path) -> None:
    new = _copy(base_run, tmp_path / "new", kf_scale=1.3)
    r = bench("compare", str(base_run), str(new), "--fail-if-worse", "kf:future.mean_m:5%",
              "--fail-if-worse", "cv:future.mean_m:5%")
    assert r.returncode == 1, (r.stdout, r.stderr)
    assert "Traceback" not in r.stdout + r.stderr
    failed = [x for x in r.stdout.splitlines() if x.startswith("FAILED")]
    assert len(failed) == 1 and failed[0].startswith("FAILED: kf future.mean_m"), r.stdout
    assert any(x.startswith("passed: cv future.mean_m") for x in r.stdout.splitlines())
    assert "accuracy gate failed: 1 of 2" in r.stderr
    # within a 50 % tolerance the same regression passes
    r = bench("compare", str(base_run), str(new), "--fail-if-worse", "kf:future.mean_m:50%")
    assert r.returncode == 0, (r.stdout, r.stderr)


def test_cli_table_csv_and_outputs(base_run: Path, tmp_path: Path) -> None:
    new = _copy(base_run, tmp_path / "new", kf_scale=1.3)
    out = tmp_path / "cmp"
    r = bench("compare", str(base_run), str(new), "--format", "csv", "--scope", "all,drive",
              "--out", str(out))
    assert r.returncode == 0, r.stderr
    from io import StringIO

    frame = pd.read_csv(StringIO(r.stdout.split("written:")[0]))
    assert set(frame["scope"]) == {"all", "drive"}
    kf = frame[(frame["scope"] == "all") & (frame["predictor"] == "kf")].iloc[0]
    assert kf["new"] == pytest.approx(1.3 * kf["old"])
    assert kf["delta new"] == pytest.approx(0.3 * kf["old"])
    assert kf["delta new lo"] > 0
    assert (out / "comparison.csv").is_file() and (out / "comparison.png").is_file()


def test_cli_config_mismatch_is_flagged_and_blocks_a_gate(base_run: Path, tmp_path: Path) -> None:
    new = _copy(base_run, tmp_path / "new", config={"horizon_s": 0.4})
    r = bench("compare", str(base_run), str(new))
    assert r.returncode == 0 and "note: runs differ in horizon_s" in r.stderr, r.stderr
    r = bench("compare", str(base_run), str(new), "--fail-if-worse", "kf:future.mean_m:5%")
    assert_one_error_line(r, "configurations differ", "horizon_s", "--allow-config-change")
    r = bench("compare", str(base_run), str(new), "--fail-if-worse", "kf:future.mean_m:5%",
              "--allow-config-change")
    assert r.returncode == 0, r.stderr


def test_cli_bad_input_is_one_line(base_run: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "results.json").write_text("{not json")
    cases = [
        (("compare", str(tmp_path / "nope")), ("no such file",)),
        (("compare", str(bad)), ("not readable as JSON",)),
        (("compare", str(base_run), "--metric", "future.avg"), ("--metric", "not a metric")),
        (("compare", str(base_run), "--format", "xlsx"), ("--format",)),
        (("compare", str(base_run), "--scope", "everything"), ("--scope",)),
        (("compare", str(base_run), "--fail-if-worse", "kf:future.mean_m:5%"),
         ("exactly two runs",)),
        (("compare", str(base_run), str(base_run), "--fail-if-worse", "lstm:future.mean_m:5%"),
         ("no predictor 'lstm'",)),
        (("compare", str(base_run), str(base_run), "--fail-if-worse", "kf:future.mean_m"),
         ("PREDICTOR:KIND.STAT:TOLERANCE",)),
        (("compare", str(base_run), "--out", str(base_run / "results.json")), ("--out",)),
        (("compare",), ("RUN_DIR",)),
    ]
    for args, needles in cases:
        assert_one_error_line(bench(*args), *needles)
