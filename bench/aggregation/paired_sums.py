"""The paired comparison from per-drive sums: a predictor against the baseline without
holding either's rows.

With several drives, the paired comparison's figures (the difference of mean errors, its
cluster-bootstrap interval, the wins: :func:`~posbench.metrics.bootstrap.paired_summary`)
need only each drive's sums of both errors over the queries both answered, and how many
(:func:`~posbench.metrics.bootstrap.paired_from_sums`). So the two predictors' scored rows
are read one drive at a time, paired (:func:`pair_rows`), reduced to sums per query kind
and per kind and route type, and let go: what is held is a few numbers per drive. A group
that has a single drive is resampled in blocks of its queries; its drive is read again.

The figures are those of every paired row compared at once (the predictor's rows matched
with the baseline's on data set, drive, kind and query time, each group through
:func:`~posbench.metrics.bootstrap.paired_summary`), to the bit: each drive's sums are
accumulated in its queries' order, as the cluster bootstrap sums a cluster, and the drives
are numbered in the order they first appear in the predictor's rows. (Queries are assumed
unique per drive, kind and time, as replay writes them.)
"""

from __future__ import annotations

import copy
import functools
from collections.abc import Callable, Collection, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from posbench.aggregation.intervals import Statistics
from posbench.metrics.bootstrap import paired_from_sums, paired_summary
from posbench.scenarios.labels import LABELS
from posbench.scoring.schema import KINDS
from posbench.scoring.trace_parts import text_values
from posbench.scoring.trace_set import TraceSet

#: the columns read of each predictor
COLUMNS = ("dataset", "drive", "kind", "t_query", "error_m", "label")
#: a drive: (data set, drive name)
Drive = tuple[str, str]


def drive_rows(traces: TraceSet, name: str) -> Iterator[tuple[Drive, pd.DataFrame]]:
    """Predictor ``name``'s scored rows, one drive at a time, in their order (on disk, one
    part read at a time)."""
    for piece in traces.pieces(name, COLUMNS):
        ds, ds_names = pd.factorize(piece["dataset"])
        dr, dr_names = pd.factorize(piece["drive"])
        width = len(dr_names) + 1
        codes, firsts = pd.factorize(ds.astype(np.int64) * width + dr)
        for i, key in enumerate(firsts.tolist()):
            rows = piece[codes == i] if len(firsts) > 1 else piece
            drive = (str(ds_names[key // width]), str(dr_names[key % width]))
            yield drive, rows.reset_index(drop=True)


def pair_rows(rows: pd.DataFrame, base: pd.DataFrame) -> pd.DataFrame:
    """One drive's rows of a predictor with the baseline's error of the same query beside
    (``error_base``): row by row when both list the same queries, else matched on kind and
    query time (the predictor's order)."""
    same = (
        len(rows) == len(base)
        and np.array_equal(rows["t_query"].to_numpy(), base["t_query"].to_numpy())
        and np.array_equal(text_values(rows["kind"]), text_values(base["kind"]))
    )
    if same:
        return rows.assign(error_base=base["error_m"].to_numpy())
    b = base[["kind", "t_query", "error_m"]].rename(columns={"error_m": "error_base"})
    b = b.astype({"kind": str})
    return rows.astype({"kind": str}).merge(b, on=["kind", "t_query"], how="inner", sort=False)


def _sum(values: np.ndarray) -> float:
    """The sum in the values' order, one addition after another: how the cluster bootstrap
    (``np.bincount`` with weights) sums a cluster."""
    return float(np.bincount(np.zeros(values.size, dtype=np.intp), weights=values, minlength=1)[0])


@dataclass
class PairedSums:
    """Per drive (in order of first appearance) and per group (a kind, or a kind and route
    type of :data:`LABELS`), the sums of the baseline's and the predictor's errors [m] over
    the queries both answered, and how many."""

    drives: list[Drive] = field(default_factory=list)
    #: per drive: (KINDS, 1 + len(LABELS), 3) - column 0 the kind, 1.. its route types;
    #: the last axis: sum of the baseline's errors, sum of the predictor's, count
    sums: list[np.ndarray] = field(default_factory=list)

    def add(self, drive: Drive, pairs: pd.DataFrame) -> None:
        """One drive's paired rows (:func:`pair_rows`)."""
        a = pairs["error_base"].to_numpy(dtype=float)
        b = pairs["error_m"].to_numpy(dtype=float)
        ok = np.isfinite(a) & np.isfinite(b)
        kind = text_values(pairs["kind"], as_str=True)
        label = text_values(pairs["label"], as_str=True) if "label" in pairs else None
        out = np.zeros((len(KINDS), 1 + len(LABELS), 3))
        for i, k in enumerate(KINDS):
            mk = ok & (kind == k)
            out[i, 0] = (_sum(a[mk]), _sum(b[mk]), mk.sum())
            for j, lab in enumerate(LABELS):
                m = mk & (label == lab) if label is not None else np.zeros_like(mk)
                out[i, 1 + j] = (_sum(a[m]), _sum(b[m]), m.sum())
        self.drives.append(drive)
        self.sums.append(out)


def paired_sums(traces: TraceSet, name: str, baseline: str) -> PairedSums:
    """:class:`PairedSums` of predictor ``name`` against ``baseline``, reading both one
    drive at a time, side by side (a drive whose rows come in consecutive pieces is joined
    first). The baseline's drives that the predictor lacks are let go as its next drive is
    found; one that comes out of order is read on its own."""
    out = PairedSums()
    waiting: dict[Drive, pd.DataFrame] = {}  # the baseline's drives read, not yet paired
    base_rows = _joined(drive_rows(traces, baseline))
    for drive, rows in _joined(drive_rows(traces, name)):
        while drive not in waiting:
            nxt = next(base_rows, None)
            if nxt is None:
                break
            waiting[nxt[0]] = nxt[1]
        if drive in waiting:
            before = list(waiting)[: list(waiting).index(drive)]
            base = waiting.pop(drive)
            for key in before:  # listed before this drive: the predictor has none of them
                del waiting[key]
        else:
            base = _drive_of(traces, baseline, drive)
        out.add(drive, pair_rows(rows, base))
    return out


def _drive_of(traces: TraceSet, name: str, drive: Drive) -> pd.DataFrame:
    """Predictor ``name``'s scored rows of ``drive``, read on their own (none: no rows)."""
    found = [r for d, r in drive_rows(_one_drive(traces, drive[1]), name) if d == drive]
    if not found:
        return pd.DataFrame({c: pd.Series(dtype=float) for c in ("kind", "t_query", "error_m")})
    return pd.concat(found, ignore_index=True)


def _joined(
    pieces: Iterator[tuple[Drive, pd.DataFrame]],
) -> Iterator[tuple[Drive, pd.DataFrame]]:
    """Consecutive pieces of the same drive as one."""
    held: tuple[Drive, list[pd.DataFrame]] | None = None
    for drive, rows in pieces:
        if held is not None and held[0] == drive:
            held[1].append(rows)
            continue
        if held is not None:
            yield held[0], pd.concat(held[1], ignore_index=True)
        held = (drive, [rows])
    if held is not None:
        yield held[0], pd.concat(held[1], ignore_index=True)


def group_entry(
    sums: PairedSums,
    keep: Sequence[int],
    kind: int,
    column: int,
    one_drive: Callable[[int], pd.DataFrame],
    stats: Statistics,
) -> dict[str, Any]:
    """:func:`~posbench.metrics.bootstrap.paired_summary`'s entry of one group (``kind``,
    and ``column``: 0 for the kind, 1 + j for route type j) over the drives ``keep``
    (indices into ``sums.drives``): from their sums with several drives; with one, from its
    paired rows (``one_drive(drive_index)``: the rows of :func:`pair_rows`)."""
    with_queries = [i for i in keep if sums.sums[i][kind, column, 2] > 0]
    if len(with_queries) == 1:
        pairs = one_drive(with_queries[0])
        m = text_values(pairs["kind"], as_str=True) == KINDS[kind]
        if column > 0 and "label" in pairs:
            m &= text_values(pairs["label"], as_str=True) == LABELS[column - 1]
        elif column > 0:
            m[:] = False
        rows = pairs[m]
        r = paired_summary(
            rows["error_base"].to_numpy(dtype=float),
            rows["error_m"].to_numpy(dtype=float),
            np.zeros(len(rows), dtype=np.int64),
            rows["t_query"].to_numpy(dtype=float),
            n_resamples=stats.resamples,
            seed=stats.seed,
            level=stats.level,
        )
    else:
        cell = np.array([sums.sums[i][kind, column] for i in with_queries]).reshape(-1, 3)
        r = paired_from_sums(
            cell[:, 0],
            cell[:, 1],
            cell[:, 2].astype(np.int64),
            n_resamples=stats.resamples,
            seed=stats.seed,
            level=stats.level,
        )
    return dict(r)


def rereader(
    traces: TraceSet, name: str, baseline: str, sums: PairedSums
) -> Callable[[int], pd.DataFrame]:
    """``one_drive`` of :func:`group_entry`: drive ``i`` of ``sums``'s paired rows, read
    again (:func:`drive_pairs`); the last drive read is kept, so the groups of one drive
    (its kinds and route types, overall and by data set) read it once, not once each."""

    @functools.lru_cache(maxsize=1)
    def again(i: int) -> pd.DataFrame:
        return drive_pairs(traces, name, baseline, sums.drives[i])

    return again


def drive_pairs(traces: TraceSet, name: str, baseline: str, drive: Drive) -> pd.DataFrame:
    """One drive's paired rows (:func:`pair_rows`), read again."""
    return pair_rows(_drive_of(traces, name, drive), _drive_of(traces, baseline, drive))


def _one_drive(traces: TraceSet, drive: str) -> TraceSet:
    """The traces of the parts that hold ``drive`` (all of them in memory)."""
    if traces.in_memory is not None:
        return traces
    return TraceSet(parts=traces.parts_with(drive))


def drive_indices(
    sums: PairedSums, without: Collection[str] = (), dataset: str | None = None
) -> list[int]:
    """The drives of ``sums`` (indices), less those named in ``without``, of ``dataset``
    only given it."""
    return [
        i
        for i, (ds, dr) in enumerate(sums.drives)
        if dr not in without and (dataset is None or ds == dataset)
    ]


def paired_groups(
    sums: PairedSums,
    keep: Sequence[int],
    datasets: Sequence[str],
    one_drive: Callable[[int], pd.DataFrame],
    stats: Statistics,
) -> dict[str, Any]:
    """The paired comparison over the drives ``keep`` of ``sums``: ``{"overall": {kind:
    entry}, "by_dataset": {ds: {kind: entry}}, "by_label": {ds: {kind: {label: entry}}}}``
    (entries: :func:`~posbench.metrics.bootstrap.paired_summary`'s; a data set whose drives
    are all of ``keep`` gets the overall entry)."""
    out: dict[str, Any] = {"overall": {}, "by_dataset": {}, "by_label": {}}
    for i, k in enumerate(KINDS):
        out["overall"][k] = group_entry(sums, keep, i, 0, one_drive, stats)
    for ds in datasets:
        mine = [j for j in keep if sums.drives[j][0] == ds]
        out["by_dataset"][ds], out["by_label"][ds] = {}, {}
        for i, k in enumerate(KINDS):
            if mine == list(keep):  # every drive is this data set's: the overall entry
                out["by_dataset"][ds][k] = copy.deepcopy(out["overall"][k])
            else:
                out["by_dataset"][ds][k] = group_entry(sums, mine, i, 0, one_drive, stats)
            out["by_label"][ds][k] = {
                lab: group_entry(sums, mine, i, 1 + j, one_drive, stats)
                for j, lab in enumerate(LABELS)
            }
    return out
