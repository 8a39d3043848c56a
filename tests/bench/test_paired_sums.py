"""The paired comparison from per-drive sums equals the one computed on every paired row at
once: matched queries, drives of one data set, a group with one drive (block bootstrap,
its drive read again), the held-out drives, traces in memory and in parts."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from posbench.aggregation.intervals import Statistics, drive_codes
from posbench.aggregation.paired_sums import (
    drive_indices,
    paired_groups,
    paired_sums,
    rereader,
)
from posbench.metrics.bootstrap import paired_summary
from posbench.scenarios.labels import LABELS
from posbench.scoring.part_writer import write_part
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_set import TraceSet

STATS = Statistics(resamples=300, seed=2)
KEYS = ["dataset", "drive", "kind", "t_query"]


def _traces(seed: int = 0) -> pd.DataFrame:
    """Two predictors over four drives of two data sets (``other`` has one drive); kf lacks
    some of cv's queries, and some errors are NaN."""
    rng = np.random.default_rng(seed)
    frames = []
    for d, (ds, drive) in enumerate([("set", "a"), ("set", "b"), ("other", "c"), ("set", "d")]):
        n = 120 + 40 * d
        keys = pd.DataFrame(
            {
                "dataset": ds,
                "drive": drive,
                "kind": np.where(np.arange(n) % 3 == 0, "future", "now"),
                "t_query": np.arange(n) * 0.05,
                "label": rng.choice([*LABELS[:3], None], n),
                "x_ref": 0.0,
                "y_ref": 0.0,
                "warmup": np.arange(n) < 5,
            }
        )
        for p, scale in (("cv", 0.06), ("kf", 0.05)):
            rows = keys.assign(predictor=p, error_m=rng.gamma(2.0, scale, n))
            if p == "kf":
                rows = rows[~((rows["drive"] == "b") & (rows["t_query"] > 4.0))]
                rows.loc[rows.index[::17], "error_m"] = np.nan
            frames.append(rows)
    return pd.concat(frames, ignore_index=True)


def _reference(traces: pd.DataFrame, datasets, without=()) -> dict:
    """Every paired row at once: the predictor's scored rows matched with the baseline's on
    data set, drive, kind and query time, each group through paired_summary."""
    scored = traces[~traces["warmup"] & ~traces["drive"].isin(without)]
    df = scored[scored["predictor"] == "kf"]
    base = scored[scored["predictor"] == "cv"][[*KEYS, "error_m"]]
    both = df.merge(base.rename(columns={"error_m": "error_base"}), on=KEYS, sort=False)
    codes = drive_codes(both)
    e, eb = both["error_m"].to_numpy(), both["error_base"].to_numpy()
    t, kind = both["t_query"].to_numpy(), both["kind"].to_numpy()
    ds, label = both["dataset"].to_numpy(), both["label"].to_numpy()

    def entry(m):
        return paired_summary(
            eb[m], e[m], codes[m], t[m], n_resamples=STATS.resamples, seed=STATS.seed
        )

    out = {"overall": {}, "by_dataset": {}, "by_label": {}}
    for k in KINDS:
        out["overall"][k] = entry(kind == k)
    for name in datasets:
        out["by_dataset"][name] = {k: entry((kind == k) & (ds == name)) for k in KINDS}
        out["by_label"][name] = {
            k: {lab: entry((kind == k) & (ds == name) & (label == lab)) for lab in LABELS}
            for k in KINDS
        }
    return out


@pytest.mark.parametrize("where", ["memory", "parts"])
def test_the_comparison_from_sums_is_the_one_on_every_row(where, tmp_path):
    traces = _traces()
    if where == "memory":
        ts = TraceSet(traces)
    else:
        ts = TraceSet(
            parts=[
                write_part(tmp_path, rows, f"p{i}")
                for i, (_, rows) in enumerate(traces.groupby("drive", sort=False))
            ]
        )
    sums = paired_sums(ts, "kf", "cv")
    assert sums.drives == [("set", "a"), ("set", "b"), ("other", "c"), ("set", "d")]
    again = rereader(ts, "kf", "cv", sums)
    datasets = ["other", "set"]
    got = paired_groups(sums, drive_indices(sums), datasets, again, STATS)
    want = _reference(traces, datasets)
    assert json.dumps(got, sort_keys=True) == json.dumps(want, sort_keys=True)
    assert got["by_dataset"]["other"]["now"]["block_len"] is not None  # one drive
    assert got["overall"]["now"]["drives"] == 4
    held = paired_groups(sums, drive_indices(sums, without={"a", "b"}), datasets, again, STATS)
    want_held = _reference(traces, datasets, without={"a", "b"})
    assert json.dumps(held, sort_keys=True) == json.dumps(want_held, sort_keys=True)
    assert held["by_dataset"]["set"]["future"]["drives"] == 1


def test_drives_the_predictor_lacks_or_that_come_out_of_order(tmp_path):
    """kf lacks drive c; the baseline's parts come in another order than kf's (one part
    per drive and predictor): the figures are still those of every paired row."""
    traces = _traces(1)
    traces = traces[~((traces["predictor"] == "kf") & (traces["drive"] == "c"))]
    parts = []
    for p, order in (("kf", ["a", "b", "d"]), ("cv", ["d", "a", "c", "b"])):
        for drive in order:
            rows = traces[(traces["predictor"] == p) & (traces["drive"] == drive)]
            parts.append(write_part(tmp_path, rows, f"{p}-{drive}"))
    ts = TraceSet(parts=parts)
    sums = paired_sums(ts, "kf", "cv")
    assert [d for _, d in sums.drives] == ["a", "b", "d"]
    again = rereader(ts, "kf", "cv", sums)
    got = paired_groups(sums, drive_indices(sums), ["other", "set"], again, STATS)
    want = _reference(traces, ["other", "set"])
    assert json.dumps(got, sort_keys=True) == json.dumps(want, sort_keys=True)
