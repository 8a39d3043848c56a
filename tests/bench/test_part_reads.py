"""Reading trace parts with little memory: a predictor's row groups read directly, and the
parts joined into columns allocated once; the frames are those of the plain reads."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from posbench.scoring.part_writer import write_part
from posbench.scoring.trace_parts import concat_parts, join_pieces, read_part


def _traces(seed: int, drive: str, predictors: tuple[str, ...], labels: list[str]) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    n = 40
    frames = []
    for p in predictors:
        frames.append(
            pd.DataFrame(
                {
                    "dataset": "set",
                    "drive": drive,
                    "predictor": p,
                    "kind": rng.choice(["future", "now"], n),
                    "label": pd.Categorical(rng.choice([*labels, None], n), categories=labels),
                    "t_query": np.arange(n) * 0.05,
                    "error_m": rng.exponential(size=n),
                    "outage": rng.integers(-1, 3, n),
                    "warmup": rng.random(n) < 0.1,
                }
            )
        )
    df = pd.concat(frames, ignore_index=True)
    return df.astype({"kind": "category", "predictor": "category"})


@pytest.fixture
def parts(tmp_path):
    """Three parts, one row group per predictor, whose route types differ in their
    categories (order and members)."""
    return [
        write_part(tmp_path, _traces(i, f"d{i}", ("cv", "kf"), labels), f"p{i}")
        for i, labels in enumerate((["turn", "straight"], ["straight"], ["roundabout", "turn"]))
    ]


def _old_read(path, columns, predictor=None, drive=None):
    """What read_part read before: pyarrow's filtered read."""
    wanted = [(c, "==", v) for c, v in (("predictor", predictor), ("drive", drive)) if v]
    table = pq.read_table(
        path,
        columns=columns,
        filters=wanted or None,
        read_dictionary=[
            c for c in ("dataset", "drive", "predictor") if columns is None or c in columns
        ],
    )
    return table.to_pandas()


def _same_values(a: pd.DataFrame, b: pd.DataFrame) -> None:
    assert list(a.columns) == list(b.columns) and len(a) == len(b)
    pd.testing.assert_frame_equal(a.astype(object), b.astype(object))


@pytest.mark.parametrize("columns", [None, ["error_m", "kind"], ["drive", "t_query", "label"]])
def test_a_predictors_rows_are_read_from_its_row_groups(parts, columns):
    for path in parts:
        for predictor, drive in (
            ("kf", None),
            ("cv", None),
            (None, "d1"),
            ("kf", "d0"),
            ("x", None),
        ):
            got = read_part(path, columns, predictor, drive)
            want = _old_read(path, columns, predictor, drive)
            _same_values(got, want)
            assert isinstance(got.index, pd.RangeIndex)


def test_a_row_group_of_several_predictors_is_read_and_filtered(tmp_path):
    """A part written in one row group (several predictors): its rows are filtered, the
    columns asked for only (the filter's own column not among them)."""
    df = _traces(7, "d7", ("cv", "kf", "ekf"), ["turn"])
    path = tmp_path / "one.parquet"
    pq.write_table(pa.Table.from_pandas(df, preserve_index=False), path)
    assert pq.ParquetFile(path).metadata.num_row_groups == 1
    got = read_part(path, ["t_query", "error_m"], "kf")
    want = df.loc[df["predictor"] == "kf", ["t_query", "error_m"]].reset_index(drop=True)
    pd.testing.assert_frame_equal(got, want)
    assert read_part(path, ["error_m"], "nobody").empty


@pytest.mark.parametrize("slack", [0, 5], ids=["exact", "loose"])
def test_pieces_joined_in_place_are_the_pieces_concatenated(parts, slack):
    """join_pieces gives concat_parts' frame: values, dtypes, categories united in the same
    order, codes' width, a fresh index."""
    pieces = [read_part(p, None, "kf") for p in parts]
    want = concat_parts(pieces)
    got = join_pieces(iter(pieces), len(want) + slack)
    pd.testing.assert_frame_equal(got, want, check_exact=True)
    for c in ("label", "kind", "predictor", "drive"):
        assert list(got[c].cat.categories) == list(want[c].cat.categories)
        assert got[c].cat.codes.dtype == want[c].cat.codes.dtype


def test_pieces_that_do_not_fit_are_concatenated(parts):
    """No bound, too small a bound, or a column whose type changes: concat_parts' frame."""
    pieces = [read_part(p, None, "kf") for p in parts]
    want = concat_parts(pieces)
    for bound in (None, 10, len(want) - 1):
        pd.testing.assert_frame_equal(join_pieces(iter(pieces), bound), want)
    changed = [*pieces[:2], pieces[2].astype({"outage": float})]
    pd.testing.assert_frame_equal(
        join_pieces(iter(changed), len(want)), concat_parts(changed), check_exact=True
    )
    assert join_pieces(iter([]), 10).empty


@pytest.mark.parametrize("one_group", [False, True], ids=["row-group-a-predictor", "one-row-group"])
def test_a_keep_chooses_the_scored_rows_before_the_frame(tmp_path, one_group):
    """read_part's keep (the scored rows: scored_of) gives the rows and columns that
    filtering the frame with scored_mask gives, whether the part's row groups each hold one
    predictor (chosen in Arrow) or several (filtered as a frame)."""
    from posbench.scoring.schema import scored_mask, scored_of

    df = _traces(3, "d3", ("cv", "kf"), ["turn"])
    rng = np.random.default_rng(3)
    df["x_ref"] = np.where(rng.random(len(df)) < 0.2, np.nan, 1.0)
    df["y_ref"] = 2.0
    if one_group:
        path = tmp_path / "one.parquet"
        pq.write_table(pa.Table.from_pandas(df, preserve_index=False), path)
    else:
        path = write_part(tmp_path, df, "p")
    cols = ["kind", "label", "error_m"]
    got = read_part(path, cols, "kf", keep=scored_of)
    mine = df[df["predictor"] == "kf"]
    want = mine.loc[scored_mask(mine), cols].reset_index(drop=True)
    assert 0 < len(got) < len(mine)
    _same_values(got, want)
