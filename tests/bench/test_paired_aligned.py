"""The paired comparison from rows aligned once: the held-out comparison cut from the full
alignment is the one computed from the two frames less the training drives, and the
baseline's frame is not needed for it."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from posbench.aggregation.intervals import (
    Statistics,
    align,
    drive_codes,
    paired_aligned,
    paired_results,
)


def _frames(seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    rng = np.random.default_rng(seed)
    rows = []
    for d, drive in enumerate(["a", "b", "c", "d"]):
        n = 200 + 50 * d
        rows.append(
            pd.DataFrame(
                {
                    "dataset": "set",
                    "drive": drive,
                    "kind": np.where(np.arange(n) % 3 == 0, "future", "now"),
                    "t_query": np.arange(n) * 0.05,
                    "label": np.where(np.arange(n) % 5 == 0, "turn", "straight"),
                }
            )
        )
    keys = pd.concat(rows, ignore_index=True)
    keys = keys.assign(code=drive_codes(keys))
    df = keys.assign(error_m=rng.gamma(2.0, 0.05, len(keys)))
    base = keys.drop(columns="label").assign(error_m=rng.gamma(2.0, 0.06, len(keys)))
    return df, base


def test_the_held_out_rows_cut_from_the_full_alignment_give_the_same_figures():
    df, base = _frames()
    stats = Statistics(resamples=300)
    full = align(df, base)
    assert full.same
    cut = full.without(["b"])
    keep_df, keep_base = df[df["drive"] != "b"], base[base["drive"] != "b"]
    direct = paired_results(keep_df, keep_base, ["set"], stats)
    assert json.dumps(paired_aligned(cut, ["set"], stats)) == json.dumps(direct)
    assert direct["overall"]["now"]["queries"] == int((keep_df["kind"] == "now").sum())
    assert direct["overall"]["future"]["drives"] == 3


def test_other_lists_of_queries_are_matched_and_cannot_be_cut():
    df, base = _frames(1)
    base = base[~((base["drive"] == "c") & (base["t_query"] > 5.0))]  # fewer queries
    base = base.assign(code=drive_codes(base))
    aligned = align(df, base)
    assert not aligned.same and len(aligned.rows) == len(base)
    with pytest.raises(ValueError, match="same queries"):
        aligned.without(["a"])
    stats = Statistics(resamples=300)
    assert json.dumps(paired_aligned(aligned, ["set"], stats)) == json.dumps(
        paired_results(df, base, ["set"], stats)
    )
