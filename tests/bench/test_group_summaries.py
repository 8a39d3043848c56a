"""The error figures (each kind's, by route type, speed bin, time since the last fix, the
outage scores), computed one drive at a time in two passes, equal the figures of each kind's
rows copied out and grouped: counts, quantiles and intervals to the bit, means and RMSE to
rounding; the same from a frame in memory as from parts on disk."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from posbench.aggregation.combining import Combining
from posbench.aggregation.error_figures import error_figures
from posbench.aggregation.intervals import Statistics, add_group_cis, drive_codes, outage_cis
from posbench.metrics.accuracy import (
    speed_bin_labels,
    speed_bin_order,
    summarize,
    summarize_groups,
)
from posbench.metrics.bootstrap import group_cis
from posbench.metrics.outages import (
    error_vs_since_fix,
    outage_keys,
    outage_scores,
    since_fix_checkpoint,
)
from posbench.scenarios.labels import LABELS
from posbench.scoring.part_writer import write_part
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet

STATS = Statistics(resamples=300, seed=3)


def _rows(seed: int = 0, n: int = 3000) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    drive = np.repeat([f"d{i}" for i in range(6)], n // 6)
    speed = rng.uniform(0, 35, n)
    speed[rng.random(n) < 0.05] = np.nan
    since = rng.choice([0.2, 0.5, 1.0, 2.0, 5.0, 3.3], n) + rng.normal(0, 0.03, n)
    since[rng.random(n) < 0.05] = np.nan
    df = pd.DataFrame(
        {
            "dataset": "set",
            "drive": drive,
            "kind": pd.Categorical(rng.choice(["now", "future", "other"], n)),
            "label": pd.Categorical(rng.choice([*LABELS, "elsewhere", None], n)),
            "t_query": np.tile(np.arange(n // 6) * 0.05, 6),
            "error_m": rng.exponential(size=n),
            "speed_mps": speed,
            "since_fix_s": since,
            "outage": np.where(rng.random(n) < 0.3, rng.integers(0, 4, n), -1),
        }
    )
    df.loc[rng.random(n) < 0.02, "error_m"] = np.nan
    df = df.assign(predictor="p", x_ref=0.0, y_ref=0.0, warmup=False)
    return df.assign(code=drive_codes(df))


def _figures(df: pd.DataFrame, tmp_path=None) -> dict:
    """error_figures of predictor "p" (``df``: its rows), from the frame or, given a folder,
    from one part per drive."""
    traces = df.drop(columns="code")
    ts = TraceSet(traces)
    if tmp_path is not None:
        groups = traces.groupby("drive", sort=False)
        ts = TraceSet(
            parts=[write_part(tmp_path, g, f"{i:02d}") for i, (_, g) in enumerate(groups)]
        )
    c = Combining(ts, [], STATS, ["set"], True, set(), [], False, False)
    return error_figures(c, "p")


def _per_kind(df: pd.DataFrame, keys_of, order) -> dict:
    """Each kind's rows copied out, grouped by summarize_groups and add_group_cis."""
    out = {}
    for k in KINDS:
        m = (df["kind"] == k).to_numpy()
        e = df["error_m"].to_numpy(float)[m]
        keys = keys_of(df)[m]
        out[k] = summarize_groups(e, keys, order=order)
        add_group_cis(
            out[k], e, keys, df["code"].to_numpy()[m], df["t_query"].to_numpy(float)[m], STATS
        )
    return out


def _same(a, b, path: str = "") -> None:
    """Equal to the bit; a mean or RMSE (summed per drive, then exactly) to 1e-12."""
    if isinstance(b, dict):
        assert sorted(a) == sorted(b), path
        for k in b:
            _same(a[k], b[k], f"{path}/{k}")
    elif isinstance(b, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same(x, y, f"{path}[{i}]")
    elif isinstance(b, float) and path.rsplit("/", 1)[-1] in ("mean_m", "rmse_m"):
        assert a == pytest.approx(b, rel=1e-12, nan_ok=True), path
    elif isinstance(b, float) and math.isnan(b):
        assert math.isnan(a), path
    else:
        assert json.dumps(a) == json.dumps(b), path


@pytest.mark.parametrize("where", ["frame", "parts"])
def test_route_types_and_speed_bins_are_each_kinds_groups(where, tmp_path):
    df = _rows()
    got = _figures(df, tmp_path if where == "parts" else None)
    labels = lambda d: d["label"].astype(object).to_numpy()  # noqa: E731
    _same(got["by_label"]["set"], _per_kind(df, labels, list(LABELS)))
    speeds = lambda d: speed_bin_labels(d["speed_mps"].to_numpy())  # noqa: E731
    _same(got["by_speed"], _per_kind(df, speeds, [*speed_bin_order(), "unknown"]))


def test_the_outage_figures_are_those_of_every_now_query():
    df = _rows(1)
    m = (df["kind"] == "now").to_numpy()
    e, codes = df["error_m"].to_numpy(float)[m], df["code"].to_numpy()[m]
    t, since = df["t_query"].to_numpy(float)[m], df["since_fix_s"].to_numpy(float)[m]
    since_fix = error_vs_since_fix(e, since)
    add_group_cis(since_fix, e, since_fix_checkpoint(since), codes, t, STATS)
    ids = outage_keys(codes, df["outage"].to_numpy()[m])
    scores = outage_scores(e, t, ids)
    scores["ci95"] = outage_cis(e, t, ids, STATS)
    got = _figures(df)["outages"]
    assert scores["outages"] > 0 and since_fix["1s"]["count"] > 0
    _same(got, {"since_fix": since_fix, "scores": scores})


def test_group_intervals_of_some_groups_are_those_of_all():
    rng = np.random.default_rng(5)
    e, keys = rng.exponential(size=900), rng.choice(["a", "b", "c"], 900)
    clusters, t = rng.integers(0, 7, 900), np.arange(900) * 0.1
    every = group_cis(e, keys, clusters, t, n_resamples=200)
    some = group_cis(e, keys, clusters, t, n_resamples=200, only={"a", "c"})
    assert list(some) == ["a", "c"]
    _same({k: every[k] for k in some}, some)


def test_each_kinds_figures_are_its_rows_grouped():
    """kind_summaries: each kind's rows, intervals as add_group_cis drew them over the
    kinds; a kind of one drive gets its block bootstrap (the query times read)."""
    df = _rows(2)
    one = df[df["drive"] == "d0"]
    for rows in (df, one):
        kind = rows["kind"].astype(object).to_numpy()
        e = rows["error_m"].to_numpy(float)
        want = {k: summarize(e[kind == k]) for k in KINDS}
        add_group_cis(
            want, e, kind, rows["code"].to_numpy(), rows["t_query"].to_numpy(float), STATS
        )
        got = _figures(rows)
        _same({k: got["entry"][k] for k in KINDS}, want)
        _same(got["by_dataset"]["set"], want)
    assert _figures(one)["entry"]["now"]["ci95"]["block_len"] is not None
