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
from helpers import assert_one_error_line, bench

from posbench.comparison.align import Metric, aligned, config_differences, run_labels
from posbench.comparison.gates import Gate, check_gates
from posbench.comparison.paired import paired_difference
from posbench.errors import UsageError
from posbench.saved_run.run import load_run

STATS = ("mean_m", "median_m", "rmse_m", "p95_m", "max_m")


@pytest.fixture(scope="module")
def base_run(cv_kf_run: Path) -> Path:
    """The session's cv,kf run (conftest), read only: the tests change copies of it."""
    return cv_kf_run


def _copy(
    src: Path, dst: Path, kf_scale: float = 1.0, config: dict | None = None, drop_drives: int = 0
) -> Path:
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
    for bad in (
        "lstm",
        "lstm:future.mean_m",
        "lstm:future.mean_m:5",
        "lstm:future.mean_m:x%",
        ":future.mean_m:5%",
    ):
        with pytest.raises(UsageError):
            Gate.parse(bad)


@pytest.mark.slow
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
    new = load_run(
        _copy(base_run, tmp_path / "new", config={"horizon_s": 0.4, "gps_profile": "consumer"})
    )
    lines = config_differences([old, new], ["old", "new"])
    assert any(x.startswith("horizon_s: 0.2 (old), 0.4 (new)") for x in lines), lines
    assert any(x.startswith("gps_profile:") for x in lines), lines


def test_cli_gate_fails_on_a_real_regression(base_run: Path, tmp_path: Path) -> None:
    new = _copy(base_run, tmp_path / "new", kf_scale=1.3)
    r = bench(
        "compare",
        str(base_run),
        str(new),
        "--fail-if-worse",
        "kf:future.mean_m:5%",
        "--fail-if-worse",
        "cv:future.mean_m:5%",
    )
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
    r = bench(
        "compare",
        str(base_run),
        str(new),
        "--table-format",
        "csv",
        "--scope",
        "all,drive",
        "--out",
        str(out),
    )
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
    r = bench(
        "compare",
        str(base_run),
        str(new),
        "--fail-if-worse",
        "kf:future.mean_m:5%",
        "--allow-config-change",
    )
    assert r.returncode == 0, r.stderr


def test_cli_bad_input_is_one_line(base_run: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "results.json").write_text("{not json")
    cases = [
        (("compare", str(tmp_path / "nope")), ("no such file",)),
        (("compare", str(bad)), ("not readable as JSON",)),
        (("compare", str(base_run), "--metric", "future.avg"), ("--metric", "not a metric")),
        (("compare", str(base_run), "--table-format", "xlsx"), ("--table-format",)),
        (("compare", str(base_run), "--scope", "everything"), ("--scope",)),
        (
            ("compare", str(base_run), "--fail-if-worse", "kf:future.mean_m:5%"),
            ("exactly two runs",),
        ),
        (
            ("compare", str(base_run), str(base_run), "--fail-if-worse", "lstm:future.mean_m:5%"),
            ("no predictor 'lstm'",),
        ),
        (
            ("compare", str(base_run), str(base_run), "--fail-if-worse", "kf:future.mean_m"),
            ("PREDICTOR:KIND.STAT:TOLERANCE",),
        ),
        (("compare", str(base_run), "--out", str(base_run / "results.json")), ("--out",)),
        (("compare",), ("RUN_DIR",)),
    ]
    for args, needles in cases:
        assert_one_error_line(bench(*args), *needles)


# ------------------------------------------------------------------ uncertainty
def _uncertainty_copy(src: Path, dst: Path, kf: str = "same") -> Path:
    """A copy of run ``src`` whose kf uncertainty is ``same``, ``none`` (kf reports no
    covariance: moved to ``uncertainty.none``, as a predictor without covariance_at) or
    ``pre-1.4`` (the whole ``uncertainty`` block gone, schema 1.3: a run saved before it)."""
    shutil.copytree(src, dst)
    p = dst / "results.json"
    res = json.loads(p.read_text())
    if kf == "none":
        for block in ("predictors", "by_dataset", "by_label", "by_since_fix", "curve"):
            res["uncertainty"][block].pop("kf")
        res["uncertainty"]["none"].append("kf")
    elif kf == "pre-1.4":
        del res["uncertainty"]
        res["schema_version"] = "1.3"
    p.write_text(json.dumps(res))
    return dst


def test_uncertainty_figures_side_by_side(base_run: Path, tmp_path: Path) -> None:
    from posbench.comparison.uncertainty import uncertainty_aligned

    old = load_run(base_run)
    new = load_run(_uncertainty_copy(base_run, tmp_path / "new", kf="none"))
    u = old.results["uncertainty"]
    assert set(u["predictors"]) == {"cv", "kf"}  # both report covariance in this run
    f = uncertainty_aligned(
        [old, new], ["old", "new"], ["all", "dataset", "route type", "since fix"]
    )
    assert list(f["scope"].unique()) == ["all", "dataset", "route type", "since fix"]
    for pred in ("cv", "kf"):
        for kind in ("future", "now"):
            s = u["predictors"][pred][kind]
            row = f[(f.scope == "all") & (f.predictor == pred) & (f.kind == kind)].iloc[0]
            assert row["old nees"] == pytest.approx(s["nees"])
            assert [row["old nees lo"], row["old nees hi"]] == pytest.approx(s["nees_ci95"])
            assert row["old cov95"] == pytest.approx(s["coverage"]["95"])
            assert row["old area"] == pytest.approx(s["sharpness_m2"])
            assert row["old loglik"] == pytest.approx(s["loglik"])
            assert (row["old verdict"], row["old n"]) == (s["verdict"], s["count"])
            ds = u["by_dataset"][pred][kind]["synthetic"]
            row = f[(f.scope == "dataset") & (f.predictor == pred) & (f.kind == kind)].iloc[0]
            assert row["dataset"] == "synthetic" and row["old nees"] == pytest.approx(ds["nees"])
            assert np.isnan(row["old nees lo"])  # results.json keeps no CI by data set
            assert row["old cov95"] == pytest.approx(ds["coverage"]["95"])
    # cv is unchanged in NEW; kf reports no covariance there: said so, no figure made up
    cv = f[f.predictor == "cv"]
    assert (cv["new nees"] == cv["old nees"]).all() and (
        cv["new verdict"] == cv["old verdict"]
    ).all()
    kf = f[f.predictor == "kf"]
    assert len(kf) > 4 and (kf["new verdict"] == "no uncertainty").all()
    assert kf[["new nees", "new cov95", "new area", "new loglik"]].isna().all().all()
    assert (kf["new n"] == 0).all() and kf["old nees"].notna().all()
    # a predictor without covariance in every run: one whole-run row saying so
    both = load_run(_uncertainty_copy(base_run, tmp_path / "both", kf="none"))
    f = uncertainty_aligned([both, new], ["both", "new"], ["all", "dataset"])
    kf = f[f.predictor == "kf"]
    assert len(kf) == 1 and kf.iloc[0]["kind"] == "-" and kf.iloc[0]["scope"] == "all"
    assert kf.iloc[0]["both verdict"] == kf.iloc[0]["new verdict"] == "no uncertainty"


def test_uncertainty_of_a_run_before_schema_1_4(base_run: Path, tmp_path: Path) -> None:
    from posbench.comparison.uncertainty import missing_notes, uncertainty_aligned

    old = load_run(_uncertainty_copy(base_run, tmp_path / "old13", kf="pre-1.4"))
    new = load_run(base_run)
    f = uncertainty_aligned([old, new], ["old13", "old"], ["all", "dataset"])
    assert len(f) == 8  # cv, kf x future, now x whole run, data set: from the new run
    assert (f["old13 verdict"] == "pre-1.4 run").all() and f["old13 nees"].isna().all()
    assert f["old nees"].notna().all()
    [note] = missing_notes([old, new], ["old13", "old"])
    assert note.startswith("old13 has no uncertainty figures (results.json schema 1.3")
    # only old runs: no rows, no crash
    assert uncertainty_aligned([old], ["old13"], ["all"]).empty


def test_cli_uncertainty_table_csv_and_outputs(base_run: Path, tmp_path: Path) -> None:
    from io import StringIO

    new = _uncertainty_copy(base_run, tmp_path / "new", kf="none")
    old13 = _uncertainty_copy(base_run, tmp_path / "old13", kf="pre-1.4")
    # without the option: the error table alone, as before
    r = bench("compare", str(base_run), str(new))
    assert r.returncode == 0 and "Uncertainty" not in r.stdout and "NEES" not in r.stdout
    # the terminal table: figures, "no uncertainty", "pre-1.4 run", a note for the old run
    r = bench("compare", str(old13), str(base_run), str(new), "--uncertainty")
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stdout + r.stderr
    assert "Uncertainty" in r.stdout and "NEES" in r.stdout  # headers wrap at 80 columns
    verdict = json.loads((base_run / "results.json").read_text())["uncertainty"]["predictors"][
        "cv"
    ]["future"]["verdict"]
    for needle in ("no uncertainty", "pre-1.4 run", verdict):
        assert needle in r.stdout, needle
    assert "note: old13 has no uncertainty figures (results.json schema 1.3" in r.stderr
    # CSV: the error table, an empty line, the uncertainty table, full precision
    out = tmp_path / "cmp"
    r = bench(
        "compare",
        str(base_run),
        str(new),
        "--uncertainty",
        "--table-format",
        "csv",
        "--scope",
        "all,since-fix",
        "--out",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    errors, unc = r.stdout.split("written:")[0].split("\n\n")
    assert set(pd.read_csv(StringIO(errors))["scope"]) == {"all"}
    frame = pd.read_csv(StringIO(unc), keep_default_na=False, na_values=[""])
    assert set(frame["scope"]) == {"all", "since fix"}
    res = json.loads((base_run / "results.json").read_text())["uncertainty"]
    row = frame[(frame.scope == "all") & (frame.predictor == "cv") & (frame.kind == "now")].iloc[0]
    assert row["old nees"] == pytest.approx(res["predictors"]["cv"]["now"]["nees"], rel=1e-12)
    assert row["new nees"] == row["old nees"]
    since = frame[(frame.scope == "since fix") & (frame.predictor == "kf")]
    assert (
        set(since["group"])
        <= set(res["by_since_fix"]["kf"]["now"]) | set(res["by_since_fix"]["kf"]["future"])
        and (since["new verdict"] == "no uncertainty").all()
    )
    written = pd.read_csv(out / "uncertainty_comparison.csv", keep_default_na=False, na_values=[""])
    pd.testing.assert_frame_equal(written, frame)
    assert (out / "comparison.csv").is_file()
    r = bench("compare", str(base_run), str(new), "--uncertainty", "--out", str(tmp_path / "md"))
    md = (tmp_path / "md" / "uncertainty_comparison.md").read_text()
    assert md.startswith("# Uncertainty") and "| no uncertainty |" in md


def test_cli_uncertainty_option_is_taught_and_checked(base_run: Path) -> None:
    r = bench("compare", "--help")
    assert r.returncode == 0
    text = " ".join(r.stdout.split())
    for needle in (
        "--uncertainty",
        "NEES",
        "no uncertainty",
        "pre-1.4 run",
        "since-fix",
        "uncertainty_comparison",
    ):
        assert needle in text, needle
    assert_one_error_line(
        bench("compare", str(base_run), "--scope", "all,since-fix"),
        "--scope since-fix",
        "--uncertainty",
    )
