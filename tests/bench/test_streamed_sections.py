"""The track-error and uncertainty sections read the traces one part (drive) at a time and
hold no predictor's rows: their figures are those of the whole rows (counts, quantiles and
intervals to the bit; means to rounding), from parts on disk as from a frame in memory."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from posbench.aggregation.track import track_section
from posbench.aggregation.uncertainty import uncertainty_section
from posbench.config import RunConfig
from posbench.metrics.calibration import calibration_of, log_det, mahalanobis_sq
from posbench.metrics.track_errors import inward_cross, track_summary
from posbench.replay.runner import run
from posbench.scenarios.synthetic import generate_drive
from posbench.scoring.part_writer import write_part
from posbench.scoring.records import all_traces
from posbench.scoring.schema import COV_COLUMNS, scored_mask
from posbench.scoring.trace_set import TraceSet

MEANS = ("mean", "nees", "loglik")


@pytest.fixture(scope="module")
def traces():
    drives = [generate_drive(seed=s, route="mixed", duration_s=60.0) for s in (1, 2, 3)]
    return all_traces(run(drives, RunConfig(predictors=("cv", "kf"))))


def _same(got, want, path=""):
    """Equal to the bit, but means (keys naming one) to 1e-12 relative."""
    if isinstance(want, dict):
        assert list(got) == list(want), path
        for k in want:
            _same(got[k], want[k], f"{path}/{k}")
    elif isinstance(want, list | tuple):
        assert len(got) == len(want), path
        for i, (a, b) in enumerate(zip(got, want, strict=True)):
            _same(a, b, f"{path}[{i}]")
    elif want is None or isinstance(want, str | int):
        assert got == want, path
    elif isinstance(want, float) and math.isnan(want):
        assert isinstance(got, float) and math.isnan(got), path
    elif any(m in path.rsplit("/", 1)[-1] for m in MEANS):
        assert got == pytest.approx(want, rel=1e-12), path
    else:
        assert got == want, path


def _sources(traces, tmp_path):
    parts = [
        write_part(tmp_path, g, f"{i:03d}")
        for i, (_, g) in enumerate(traces.groupby("drive", sort=False))
    ]
    return {"frame": TraceSet(traces), "parts": TraceSet(parts=parts)}


def _scored(traces, name, kind):
    m = scored_mask(traces) & (traces.predictor == name).to_numpy()
    return traces[m & (traces.kind == kind).to_numpy()]


def test_track_figures_are_the_whole_rows_figures(traces, tmp_path):
    for source, ts in _sources(traces, tmp_path).items():
        got = track_section(ts, ["cv", "kf"])
        for name in ("cv", "kf"):
            for kind in ("future", "now"):
                g = _scored(traces, name, kind)
                cols = (g.along_m, g.cross_m, inward_cross(g.cross_m, g.yaw_rate_ref), g.error_m)
                want = track_summary(*(np.asarray(c, dtype=float) for c in cols))
                _same(got["predictors"][name][kind], want, f"{source}/{name}/{kind}")
                turn = (g.label == "turn").to_numpy()
                want = track_summary(*(np.asarray(c, dtype=float)[turn] for c in cols))
                _same(got["by_label"][name][kind]["turn"], want, f"{source}/turn")


def test_uncertainty_figures_are_the_whole_rows_figures(traces, tmp_path):
    for source, ts in _sources(traces, tmp_path).items():
        got = uncertainty_section(ts, ["cv", "kf"])
        reports = {
            n for n in ("cv", "kf") if np.isfinite(traces.cov_xx[traces.predictor == n]).any()
        }
        assert got["none"] == [n for n in ("cv", "kf") if n not in reports]
        for kind in ("future", "now"):
            g = _scored(traces, "kf", kind)
            err = g[["x", "y"]].to_numpy(float) - g[["x_ref", "y_ref"]].to_numpy(float)
            cov = g[list(COV_COLUMNS)].to_numpy(float)
            d2, ld = mahalanobis_sq(err, cov), log_det(cov)
            drives = pd.factorize(g.drive)[0]
            want = calibration_of(d2, ld, clusters=drives, times=g.t_query.to_numpy())
            _same(got["predictors"]["kf"][kind], want, f"{source}/{kind}")
            assert got["predictors"]["kf"][kind]["nees_ci95"] is not None
            one = (g.drive == g.drive.iloc[0]).to_numpy()  # one drive: the block bootstrap
            ts_one = TraceSet(traces[traces.drive == g.drive.iloc[0]])
            alone = uncertainty_section(ts_one, ["kf"])["predictors"]["kf"][kind]
            want = calibration_of(d2[one], ld[one], times=g.t_query.to_numpy()[one])
            _same(alone, want, f"{source}/{kind}/one drive")
            turn = (g.label == "turn").to_numpy()
            want = calibration_of(d2[turn], ld[turn], with_ci=False)
            _same(got["by_label"]["kf"][kind]["turn"], want, f"{source}/{kind}/turn")


def test_seed_figures_are_those_of_the_rows_joined(traces, tmp_path):
    """A seed's figures (bench run --seeds) read one drive at a time, from parts or a frame:
    each predictor's summaries overall and per data set as summarize gives them on its
    scored rows joined (means to rounding), and the paired difference as
    paired_mean_difference gives it."""
    from posbench.aggregation.seeds import seed_figures
    from posbench.metrics.accuracy import summarize
    from posbench.metrics.seeds import paired_mean_difference

    scored = traces[scored_mask(traces)]
    want: dict = {"predictors": {}, "paired": {"kf": {}}}
    for name in ("cv", "kf"):
        mine = scored[scored["predictor"] == name]
        kind = mine["kind"].astype(str).to_numpy()
        e = mine["error_m"].to_numpy(float)
        want["predictors"][name] = {k: summarize(e[kind == k]) for k in ("future", "now")}
    for k in ("future", "now"):
        a, b = (
            scored.loc[(scored["predictor"] == n) & (scored["kind"] == k), "error_m"].to_numpy()
            for n in ("cv", "kf")
        )
        want["paired"]["kf"][k] = paired_mean_difference(a, b)

    def same(got: dict, summary: dict) -> None:  # means and RMSE to rounding
        assert list(got) == list(summary)
        for key, value in summary.items():
            close = key in ("mean_m", "rmse_m")
            assert got[key] == (pytest.approx(value, rel=1e-12) if close else value), key

    for source in _sources(traces, tmp_path).values():
        got = seed_figures(source, ["cv", "kf"], "cv", 7)
        assert got["seed"] == 7 and list(got["by_dataset"]) == ["synthetic"]
        for name in ("cv", "kf"):
            for k in ("future", "now"):
                same(got["predictors"][name][k], want["predictors"][name][k])
                same(got["by_dataset"]["synthetic"][name][k], want["predictors"][name][k])
        for k in ("future", "now"):
            assert got["paired"]["kf"][k] == pytest.approx(want["paired"]["kf"][k], rel=1e-9)
