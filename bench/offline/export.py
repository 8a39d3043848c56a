"""A saved run's tracks as files other tools read: TUM trajectories (evo, the TUM RGB-D
tools) or CSV, one file per drive and track (``bench export``).

Per drive of the run (not the skipped ones) and per kind of query, the files hold exactly the
queries the run scored (:func:`posbench.scoring.schema.scored_mask`: past the drive's warm-up,
with a reference), the rows report.md's and results.json's figures are over:

=====================================  ========================================================
file (stem; ``.tum`` or ``.csv``)      rows
=====================================  ========================================================
``DRIVE.reference``                    the reference position at each scored ``now`` query
``DRIVE.reference.future``             the reference position at each scored ``future`` query
``DRIVE.PREDICTOR.now``                the predictor's answer to each scored ``now`` query it
                                       answered (a query it left unanswered - ``missing`` in
                                       the figures - has no row)
``DRIVE.PREDICTOR.future``             the same for the ``future`` queries
=====================================  ========================================================

``DRIVE`` and ``PREDICTOR`` are the names made file-safe (:func:`posbench.naming.unique_file_safe`:
characters other than letters, digits, ``.``, ``_``, ``-`` become ``_``; the drive ids are
those ``bench queries`` gives the same drives). Each file is sorted by time.

Time: ``t_query`` [s] on the drive's clock as in ``traces.parquet`` (from the drive's
t = 0; a saved run keeps no Unix epoch, and drive-relative times stay exact as floats). For
the drives of a ``bench queries`` folder whose manifest ``t0_s`` is 0 (the synthetic drives,
most recordings) that is also the queries folder's clock, so a ``now`` track is a valid
answers file for ``bench score``. Positions: metres in the drive's local ENU frame.

Why two reference files: a ``future`` query time (fix time + horizon) can fall on a ``now``
query time (every now-step) or a few 1e-16 s from it; one file holding both would repeat a
timestamp (evo rejects a trajectory whose stamps are not strictly increasing) or hold two
stamps far closer than evo's association window (0.01 s), where its nearest-time match could
pick the other kind's row. One reference per kind associates every answer with its own query
exactly: ``evo_ape tum DRIVE.reference.tum DRIVE.kf.now.tum`` and ``evo_ape tum
DRIVE.reference.future.tum DRIVE.kf.future.tum`` (no alignment, translation part: evo's
default) give that drive's ``now`` and ``future`` figures of results.json (mean, median,
RMSE, max) to float rounding.

CSV files have the header ``t,x,y,drive,kind`` (reference) or ``t,x,y,drive,predictor,kind,
t_issue,error_m`` (predictor; ``t_issue`` [s] when the query was asked, ``error_m`` [m] the
error the run scored); ``drive`` and ``predictor`` as the run names them; floats as their
``repr`` (exact).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from posbench.naming import unique_file_safe
from posbench.offline.tum import RUN_CLOCK_COMMENT
from posbench.saved_run.run import Run
from posbench.scoring.schema import scored_mask

#: what ``bench export --format`` takes
FORMATS = ("tum", "csv")
REFERENCE = "reference"
#: the kinds of query in the order their files are written
EXPORT_KINDS = ("now", "future")


@dataclass
class Track:
    """One exported track: the rows of one drive, one kind, the reference or one predictor's
    answers. ``t`` [s] drive time of the query, ``x``, ``y`` [m] ENU; for a predictor also
    ``t_issue`` [s] and ``error_m`` [m]."""

    drive: str
    kind: str
    predictor: str | None  # None: the reference
    stem: str
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    t_issue: np.ndarray | None = None
    error_m: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass
class Exported:
    """What :func:`export_run` wrote: the files, per predictor track written the reference
    file to compare it with (``pairs``: reference, track), the drives with files (names), the
    tracks left out because they have no row (stems) and the drives skipped by the run."""

    files: list[Path] = field(default_factory=list)
    pairs: list[tuple[Path, Path]] = field(default_factory=list)
    drives: list[str] = field(default_factory=list)
    empty: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)


def track_stem(drive_id: str, predictor_id: str | None, kind: str) -> str:
    """The file stem of a track (see the module docstring)."""
    if predictor_id is None:
        return f"{drive_id}.{REFERENCE}" + ("" if kind == "now" else f".{kind}")
    return f"{drive_id}.{predictor_id}.{kind}"


def run_tracks(run: Run) -> tuple[list[Track], list[str]]:
    """Every track of ``run`` (per drive in run order: the now reference, the future
    reference, then per predictor its now and future tracks) and the drives the run skipped."""
    res = run.results
    drives = res.get("drives", [])
    ids = dict(
        zip([d["name"] for d in drives], unique_file_safe([d["name"] for d in drives]), strict=True)
    )
    preds = run.predictors
    pids = dict(zip(preds, unique_file_safe(preds, empty="predictor"), strict=True))
    skipped = [d["name"] for d in drives if d.get("skipped")]
    wanted = [d["name"] for d in drives if not d.get("skipped")]
    tr = run.traces if wanted else pd.DataFrame()
    if tr.empty:
        return [], skipped
    tr = tr.loc[
        scored_mask(tr),
        ["drive", "predictor", "kind", "t_issue", "t_query", "x", "y", "x_ref", "y_ref", "error_m"],
    ]
    drive = tr["drive"].astype(str).to_numpy()
    pred = tr["predictor"].astype(str).to_numpy()
    kind = tr["kind"].astype(str).to_numpy()
    tracks: list[Track] = []
    for name in wanted:
        mine = drive == name
        for k in EXPORT_KINDS:
            rows = tr.loc[mine & (kind == k)]
            ref = rows.drop_duplicates("t_query").sort_values("t_query", kind="stable")
            tracks.append(
                Track(
                    name,
                    k,
                    None,
                    track_stem(ids[name], None, k),
                    ref["t_query"].to_numpy(float),
                    ref["x_ref"].to_numpy(float),
                    ref["y_ref"].to_numpy(float),
                )
            )
        for p in preds:
            for k in EXPORT_KINDS:
                m = mine & (kind == k) & (pred == p)
                rows = tr.loc[m]
                rows = rows[rows["x"].notna() & rows["y"].notna()].sort_values(
                    "t_query", kind="stable"
                )
                tracks.append(
                    Track(
                        name,
                        k,
                        p,
                        track_stem(ids[name], pids[p], k),
                        rows["t_query"].to_numpy(float),
                        rows["x"].to_numpy(float),
                        rows["y"].to_numpy(float),
                        rows["t_issue"].to_numpy(float),
                        rows["error_m"].to_numpy(float),
                    )
                )
    return tracks, skipped


def _comments(track: Track, run: Run) -> list[str]:
    who = (
        "reference position"
        if track.predictor is None
        else f"predictor {track.predictor}'s answers"
    )
    return [
        f"posbench export of {run.folder}: {who}, {track.kind} queries scored ({len(track)} rows)",
        f"drive: {track.drive}",
        RUN_CLOCK_COMMENT,
        "timestamp: t_query [s] from the drive's t = 0; x east, y north [m] in the drive's "
        "local ENU frame; z = 0; identity quaternion (no orientation)",
    ]


def _csv(track: Track) -> pd.DataFrame:
    cols: dict[str, object] = {"t": track.t, "x": track.x, "y": track.y, "drive": track.drive}
    if track.predictor is not None:
        cols["predictor"] = track.predictor
    cols["kind"] = track.kind
    if track.predictor is not None:
        cols["t_issue"] = track.t_issue
        cols["error_m"] = track.error_m
    return pd.DataFrame(cols)


def export_run(
    run: Run, out: Path, fmt: str = "tum", on_file: Callable[[Path], None] | None = None
) -> Exported:
    """Write ``run``'s tracks into folder ``out`` (made if missing) as ``fmt`` (tum or csv;
    layout in the module docstring); a track without rows is not written (its stem is in
    :attr:`Exported.empty`). Files of the same names there are replaced, others left alone.

    Raises:
        ValueError: an unknown ``fmt``.
        DataError: the run's traces cannot be read.
    """
    from posbench.offline.tum import write_tum

    if fmt not in FORMATS:
        raise ValueError(f"unknown export format {fmt!r} (one of {', '.join(FORMATS)})")
    tracks, skipped = run_tracks(run)
    done = Exported(skipped=skipped)
    out.mkdir(parents=True, exist_ok=True)
    reference: dict[tuple[str, str], Path] = {}
    for track in tracks:
        if not len(track):
            done.empty.append(track.stem)
            continue
        path = out / f"{track.stem}.{fmt}"
        if track.predictor is None:
            reference[(track.drive, track.kind)] = path
        elif (track.drive, track.kind) in reference:
            done.pairs.append((reference[(track.drive, track.kind)], path))
        if track.drive not in done.drives:
            done.drives.append(track.drive)
        if fmt == "tum":
            write_tum(path, track.t, track.x, track.y, _comments(track, run))
        else:
            _csv(track).to_csv(path, index=False)  # floats as repr: exact
        done.files.append(path)
        if on_file:
            on_file(path)
    return done
