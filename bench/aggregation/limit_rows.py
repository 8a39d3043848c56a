"""The bound's rows of every drive, read one drive at a time into compact columns.

Each replayed drive's bound (:func:`posbench.replay.limit.drive_limit`) is a frame of
:data:`~posbench.replay.limit.LIMIT_COLUMNS`, held or spilled to a Parquet part. Joined as
frames, with the data set and drive per row and copies per group, they held several hundred
bytes a scored query: at 64 drive hours, 2.2 GB in the process that summarises them. Here
each drive's frame is read, turned into numbers (kinds and route types as small integer
codes, drives as bootstrap cluster codes) and dropped: about 30 bytes a query.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from posbench.aggregation.row_columns import RowColumns, extend_codes
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import text_values


@dataclass(frozen=True)
class BoundRows:
    """Every scored drive's bound rows (one per scored query, in drive order) as compact
    columns: what the section reads, about 30 bytes a query where the joined frame held
    several hundred (text per row, copies per group).

    ``limit_m``, ``limit_imu_m``: the bound [m] fixes only and with the IMU (NaN: none);
    ``t_query``: the query's time [s]; ``kind``: index into :data:`KINDS` (-1: another);
    ``label``: index into ``labels`` (route type; -1: none); ``drive``: the bootstrap
    cluster, one per (data set, drive) in order of first appearance (as
    :func:`~posbench.aggregation.intervals.drive_codes` numbers them); per drive code, its
    (data set, drive) (``drives``), its data set (``drive_dataset``, index into
    ``datasets``) and the row ranges that are its (``spans``, one per run), each with the
    standard deviation of its run's measured slow floor (``spans_slow_sd_m2`` [m^2],
    ``limit_info["slow_var_sd_m2"]``: 0 if none)."""

    limit_m: np.ndarray
    limit_imu_m: np.ndarray
    t_query: np.ndarray
    kind: np.ndarray
    label: np.ndarray
    labels: list[object]
    drive: np.ndarray
    drives: list[tuple[str, str]]
    drive_dataset: np.ndarray
    datasets: list[str]
    spans: list[list[slice]]
    spans_slow_sd_m2: list[list[float]]

    def __len__(self) -> int:
        return int(self.limit_m.size)

    def slow_sd_m2(self) -> np.ndarray:
        """Per row, the standard deviation [m^2] of its run's measured slow floor."""
        out = np.empty(len(self))
        for spans, sds in zip(self.spans, self.spans_slow_sd_m2, strict=True):
            for span, sd in zip(spans, sds, strict=True):
                out[span] = sd
        return out

    def label_text(self, rows: np.ndarray | slice) -> np.ndarray:
        """The route type of ``rows`` as an object array (one shared string per type; None
        where a row has none)."""
        table = np.array([*self.labels, None], dtype=object)
        taken: np.ndarray = table[self.label[rows]]  # -1 (none): the last entry
        return taken


def _row_count(r: DriveRun) -> int:
    """How many bound rows run ``r`` has, from its held frame or its part's metadata."""
    if r.limit is not None:
        return len(r.limit)
    import pyarrow.parquet as pq

    return int(pq.read_metadata(r.limit_part).num_rows)


def bound_rows(runs: Sequence[DriveRun]) -> BoundRows | None:
    """Every drive's bound rows read one drive at a time into :class:`BoundRows` (None when
    no drive has any): the columns are allocated once, at their final size."""
    mine = [r for r in runs if r.has_limit and not r.skipped]
    n = sum(_row_count(r) for r in mine)
    if n == 0:
        return None
    columns = RowColumns(
        {
            "limit_m": np.float64,
            "limit_imu_m": np.float64,
            "t_query": np.float64,
            "kind": np.int8,
            "label": np.int16,
            "drive": np.int32,
        },
        n,
    )
    labels: list[object] = []
    label_index: dict[object, int] = {}
    datasets: list[str] = []
    drive_index: dict[tuple[str, str], int] = {}
    drive_dataset: list[int] = []
    spans: list[list[slice]] = []
    spans_sd: list[list[float]] = []
    kinds = pd.Index(KINDS)
    for r in mine:
        rows = r.load_limit()
        if rows is None or rows.empty:
            continue
        key = (r.dataset, r.name)
        if key not in drive_index:
            drive_index[key] = len(drive_index)
            if r.dataset not in datasets:
                datasets.append(r.dataset)
            drive_dataset.append(datasets.index(r.dataset))
            spans.append([])
            spans_sd.append([])
        code = drive_index[key]
        spans[code].append(slice(columns.rows, columns.rows + len(rows)))
        spans_sd[code].append(float(r.limit_info.get("slow_var_sd_m2") or 0.0))
        columns.add(
            limit_m=rows["limit_m"].to_numpy(dtype=float),
            limit_imu_m=rows["limit_imu_m"].to_numpy(dtype=float),
            t_query=rows["t_query"].to_numpy(dtype=float),
            kind=kinds.get_indexer(text_values(rows["kind"], as_str=True)),
            label=extend_codes(rows["label"], labels, label_index),
            drive=np.full(len(rows), code, dtype=np.int32),
        )
        del rows
    return BoundRows(
        limit_m=columns.take("limit_m"),
        limit_imu_m=columns.take("limit_imu_m"),
        t_query=columns.take("t_query"),
        kind=columns.take("kind"),
        label=columns.take("label"),
        labels=labels,
        drive=columns.take("drive"),
        drives=list(drive_index),
        drive_dataset=np.asarray(drive_dataset, dtype=np.int16),
        datasets=datasets,
        spans=spans,
        spans_slow_sd_m2=spans_sd,
    )
