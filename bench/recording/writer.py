"""Write a benchmark run to a Rerun file (``.rrd``): one recording per drive.

Needs the ``viz`` extra (rerun-sdk); rerun is imported only inside
:func:`write_recording`. Everything is sent column-wise (``send_columns``), so a
10-minute drive with several predictors writes in about a second.

**One drive at a time.** Each drive is its own recording (application id and recording id
``<dataset>/<drive>``, recording name the same), with its own default blueprint
(:mod:`posbench.recording.blueprint`) and its own timeline ``time``: drive time [s] (``duration``),
the drive's own t. The viewer lists the drives separately in its source panel; pick one
there. (Each recording is written to a file of its own, then ``rerun rrd merge`` joins them:
the supported way to hold several recordings in one file.)

**North up.** rerun's 2-D views draw y downwards; every 2-D position is logged as
(x, -y) so that north (map, around view) and left (vehicle frame) point up on screen.
Entity values are therefore (east, -north) [m] and (along, -cross) [m].

Layout, per drive under ``drives/<drive>/`` (names sanitised to ``[A-Za-z0-9_.-]``):

- ``info``: static text with the run's reference, notes and warnings (or why it was skipped);
- ``map/truth``: static line strip(s) of the reference track (truth or the fix cubic), split
  at gaps; ``map/track_error``: the same track in short segments coloured by the current
  position error of one predictor (``--rerun-color-by``), scale in ``colour_scale``;
- ``map/fixes/received``, ``map/fixes/dropped``: one point per fix at its time;
- ``map/<predictor>/future``: the future point, logged at its query time
  ``t_query = t_issue + horizon`` so it lines up with the track position it is scored
  against; ``map/<predictor>/now``: the current-position answer at each "now" query time;
  ``map/<predictor>/ellipse_future``, ``map/<predictor>/ellipse_now``: for a predictor that
  reports covariance (``covariance_at``), the 95 % ellipse around each answer
  (:func:`posbench.metrics.ellipses.ellipse_outlines`, 24 segments, radius sqrt(5.991) in the
  covariance's eigenbasis), in its colour, at the answer's time; a query without a
  covariance holds an empty row (the ellipse is cleared); no entity for a predictor
  without uncertainty;
- ``around/...``: positions relative to the reference at the time shown, so the view's origin
  is the vehicle: ``around/reference`` (0, 0), ``around/road`` (the reference from
  2 s before to 1 s after), ``around/fixes`` (the last 5 received fixes),
  ``around/<predictor>/error`` (an arrow from the reference to the current-position answer,
  its tip the answer) and ``around/<predictor>/future`` (the future point, relative to the
  reference at its query time);
- ``vehicle_frame/<predictor>``: each current-position error as (along, cross) in the
  reference's heading frame (ahead to the right, left up; :mod:`posbench.metrics.track_errors`),
  ``vehicle_frame/axes`` the axes through (0, 0);
- ``errors/<predictor>/future``, ``errors/<predictor>/now``: Euclidean error [m];
  ``along/<predictor>/...``, ``cross/<predictor>/...``: along-track (+ ahead) and cross-track
  (+ left) error [m] time series;
- ``labels``: a text log entry each time the scenario label changes;
- ``outages``: a 1/0 step series (1 between the last fix before and the first fix after
  an outage).

Rows whose position is NaN are not logged in the 2-D views; error series are logged for
every query, NaN (not scorable) included. The traces are read one drive and predictor at a
time, in pieces of at most :data:`~posbench.recording.traces.PIECE_ROWS` rows, each logged and
flushed to the file before the next is read (:mod:`posbench.recording.traces`); what the
drive-wide views need (the reference at the 'now' queries, the colouring errors, the labels)
is gathered meanwhile, a few columns.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from posbench.recording.blueprint import blueprint
from posbench.recording.layout import (
    DROPPED_RGB,
    RECEIVED_RGB,
    TRUTH_RGB,
    application_id,
    change_points,
    drive_paths,
    finite_runs,
    outage_steps,
    predictor_color,
    recording_ids,
    sanitise,
    screen,
)
from posbench.recording.reference_views import around_view, track_colours
from posbench.recording.sender import Sender
from posbench.recording.traces import PIECE_ROWS, drive_source, predictor_pieces
from posbench.scoring.schema import COV_COLUMNS

if TYPE_CHECKING:
    import pandas as pd

    from posbench.scoring.records import DriveRun
    from posbench.scoring.trace_set import TraceSet


VIZ_HINT = "rerun recordings need the viz extra: pip install 'posbench-harness[viz]'"


class _Gathered:
    """What the drive-wide views need of a drive's traces, gathered from the pieces as they
    are logged: the 'now' queries' times [s], reference positions [m] and labels of the
    first predictor that has any (the queries and labels are the same for all; a drive
    without 'now' rows: the first predictor's rows), the colouring predictor's 'now' times
    and errors [m], and the span of the query times [s]."""

    def __init__(self, color_by: str | None) -> None:
        self.color_by = color_by
        self.ref_of: str | None = None  # the predictor whose 'now' rows give the reference
        self.ref: list[pd.DataFrame] = []
        self.first_rows: list[pd.DataFrame] = []  # the first predictor's rows, for labels
        self.first: str | None = None
        self.colour: list[pd.DataFrame] = []
        self.t0, self.t1 = np.inf, -np.inf

    def add(self, pred: str, piece: pd.DataFrame, now: pd.DataFrame | None) -> None:
        t = piece["t_query"].to_numpy(np.float64)
        t = t[np.isfinite(t)]
        if t.size:
            self.t0, self.t1 = min(self.t0, float(t.min())), max(self.t1, float(t.max()))
        if self.first in (None, pred):
            self.first = pred
            self.first_rows.append(piece[["t_query", "label"]])
        if now is None or now.empty:
            return
        if self.ref_of in (None, pred):
            self.ref_of = pred
            self.ref.append(now[["t_query", "x_ref", "y_ref", "label"]])
        if pred == self.color_by:
            self.colour.append(now[["t_query", "error_m"]])

    def now_reference(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Times [s] and reference positions [m] of the 'now' queries (None: none)."""
        if not self.ref:
            return None
        g = _in_time_order(self.ref)
        return g["t_query"].to_numpy(np.float64), g[["x_ref", "y_ref"]].to_numpy(np.float64)

    def labels(self) -> pd.DataFrame | None:
        """Query times [s] and labels, in time order: of the 'now' queries, else of the
        first predictor's rows (None: no rows)."""
        rows = self.ref or self.first_rows
        return _in_time_order(rows) if rows else None

    def colour_rows(self) -> pd.DataFrame | None:
        """The colouring predictor's 'now' times [s] and errors [m] (None: none)."""
        return _in_time_order(self.colour) if self.colour else None


def _in_time_order(pieces: list[pd.DataFrame]) -> pd.DataFrame:
    import pandas as pd

    rows = pd.concat(pieces, ignore_index=True) if len(pieces) > 1 else pieces[0]
    return rows.sort_values("t_query", kind="stable")


class _Writer(Sender):
    """Sends one drive to a recording stream."""

    def __init__(self, rr: Any, rec: Any, predictors: Sequence[str], color_by: str | None) -> None:
        super().__init__(rr, rec)
        self.predictors = list(predictors)
        self.pred_parts = [sanitise(p) for p in predictors]
        self.color_by = (
            color_by if color_by is not None else (self.predictors[0] if self.predictors else None)
        )

    def drive(self, root: str, run: DriveRun, source: TraceSet | None) -> None:
        """Send drive ``run`` under ``root``; ``source``: the traces it reads its rows from,
        one predictor and piece at a time (:func:`~posbench.recording.traces.drive_source`;
        None: none)."""
        rr, rec = self.rr, self.rec
        info = [
            f"drive: {run.name}",
            f"dataset: {run.dataset}",
            f"reference: {run.reference or '-'}",
            f"duration: {run.duration_s:.1f} s",
            f"fixes received: {run.gps_count}",
        ]
        info += [f"note: {n}" for n in run.notes] + [f"warning: {w}" for w in run.warnings]
        if run.skipped:
            info.append(f"SKIPPED: {run.skipped}")
        rec.log(f"{root}/info", rr.TextDocument("\n".join(info)), static=True)
        if run.skipped:
            return
        run = run.with_fixes_and_track()  # read back here when the worker wrote them to disk
        if run.track is not None and len(run.track):
            strips = finite_runs(run.track[["x", "y"]].to_numpy(np.float64))
            if strips:
                rec.log(
                    f"{root}/map/truth",
                    rr.LineStrips2D([screen(s) for s in strips], colors=[TRUTH_RGB], radii=[0.15]),
                    static=True,
                )
        received: tuple[np.ndarray, np.ndarray] | None = None  # the received fixes' t, xy
        if run.fixes is not None and len(run.fixes):
            f = run.fixes
            t, xy = f["t"].to_numpy(np.float64), f[["x", "y"]].to_numpy(np.float64)
            rcv = f["received"].to_numpy(bool)
            self.points(f"{root}/map/fixes/received", t[rcv], xy[rcv], RECEIVED_RGB, 0.35)
            self.points(f"{root}/map/fixes/dropped", t[~rcv], xy[~rcv], DROPPED_RGB, 0.5)
            received = t[rcv], xy[rcv]
        if source is None:
            return
        gathered = _Gathered(self.color_by)
        for i, (pred, part) in enumerate(zip(self.predictors, self.pred_parts, strict=True)):
            color = predictor_color(i)
            for piece in predictor_pieces(run, source, pred, PIECE_ROWS):
                kinds = {
                    kind: g.sort_values("t_query", kind="stable")
                    for kind, g in piece.groupby("kind", sort=False, observed=True)
                }
                for kind, radius in (("future", 0.4), ("now", 0.25)):
                    g = kinds.get(kind)
                    if g is not None and not g.empty:
                        self._answers(root, pred, part, kind, radius, color, g)
                gathered.add(pred, piece, kinds.get("now"))
                rec.flush()  # the piece written out before the next is read
        if gathered.first is None:
            return  # no traces
        around_view(self, root, run, gathered.now_reference(), received)
        track_colours(self, root, run, gathered.colour_rows(), self.color_by)
        rec.log(
            f"{root}/vehicle_frame/axes",
            rr.LineStrips2D(
                [[[-100.0, 0.0], [100.0, 0.0]], [[0.0, -100.0], [0.0, 100.0]]],
                colors=[TRUTH_RGB],
                radii=[0.003],
                labels=["along (ahead ->)", "cross (left up)"],
            ),
            static=True,
        )
        self._labels(root, gathered.labels())
        self._outages(root, run, gathered.t0, gathered.t1)

    def _answers(
        self,
        root: str,
        pred: str,
        part: str,
        kind: str,
        radius: float,
        color: tuple[int, int, int],
        g: pd.DataFrame,
    ) -> None:
        """One piece of ``pred``'s answers to the ``kind`` queries (``g``, in time order):
        on the map, as error series, about the reference and in the vehicle frame."""
        t = g["t_query"].to_numpy(np.float64)
        xy = g[["x", "y"]].to_numpy(np.float64)
        ref = g[["x_ref", "y_ref"]].to_numpy(np.float64)
        self.points(f"{root}/map/{part}/{kind}", t, xy, color, radius)
        if all(c in g for c in COV_COLUMNS):
            self.ellipses(
                f"{root}/map/{part}/ellipse_{kind}",
                t,
                xy,
                g[list(COV_COLUMNS)].to_numpy(np.float64),
                color,
            )
        self.series(
            f"{root}/errors/{part}/{kind}",
            t,
            g["error_m"].to_numpy(np.float64),
            f"{pred} {kind}",
            color,
            kind,
        )
        if kind == "future":  # the current answer is the tip of its error arrow
            self.points(f"{root}/around/{part}/future", t, xy - ref, color, 0.09)
        if "along_m" in g and "cross_m" in g:
            along = g["along_m"].to_numpy(np.float64)
            cross = g["cross_m"].to_numpy(np.float64)
            self.series(
                f"{root}/along/{part}/{kind}", t, along, f"{pred} {kind} along", color, kind
            )
            self.series(
                f"{root}/cross/{part}/{kind}", t, cross, f"{pred} {kind} cross", color, kind
            )
            if kind == "now":
                self.points(
                    f"{root}/vehicle_frame/{part}",
                    t,
                    np.column_stack([along, cross]),
                    color,
                    0.02,
                )
        if kind == "now":
            self.arrows(f"{root}/around/{part}/error", t, xy - ref, color)

    def _labels(self, root: str, rows: pd.DataFrame | None) -> None:
        """Label changes along the query times of ``rows`` (:meth:`_Gathered.labels`;
        labels depend only on time)."""
        if rows is None or rows.empty:
            return
        rr = self.rr
        lab = rows["label"].astype(str).to_numpy()
        idx = change_points(lab)
        if idx.size:
            rr.send_columns(
                f"{root}/labels",
                indexes=[self.time_column(rows["t_query"].to_numpy(np.float64)[idx])],
                columns=rr.TextLog.columns(text=lab[idx], level=["INFO"] * idx.size),
                recording=self.rec,
            )

    def _outages(self, root: str, run: DriveRun, t0: float, t1: float) -> None:
        """The outage step series over the query times ``t0``-``t1`` [s] and the outages."""
        rr = self.rr
        span = np.concatenate([[t0, t1], np.asarray(run.outages, dtype=float).ravel()])
        span = span[np.isfinite(span)]
        if span.size == 0:
            return
        t0, t1 = float(span.min()), float(span.max())
        t, v = outage_steps(run.outages, t0, t1)
        self.rec.log(
            f"{root}/outages",
            rr.SeriesLines(
                colors=[DROPPED_RGB],
                names=["GPS outage (1 = in outage)"],
                interpolation_mode=rr.components.InterpolationMode.StepAfter,
            ),
            static=True,
        )
        self.scalars(f"{root}/outages", t, v)


def merge_rrd(parts: Sequence[Path], path: Path) -> None:
    """Join .rrd files into ``path`` with ``rerun rrd merge`` (each recording stays its own).

    Runs the rerun CLI of this Python environment with its home folder in a temporary
    folder (the CLI writes analytics settings there), and no network is needed.

    Raises:
        RuntimeError: the merge failed (its last error line).
    """
    if len(parts) == 1:
        shutil.copyfile(parts[0], path)
        return
    with tempfile.TemporaryDirectory(prefix="posbench-rerun-home-") as home:
        env = {**os.environ, "HOME": home, "RERUN_ANALYTICS": "0"}
        p = subprocess.run(
            [sys.executable, "-m", "rerun_cli", "rrd", "merge", *map(str, parts), "-o", str(path)],
            capture_output=True,
            text=True,
            env=env,
        )
    if p.returncode != 0:
        lines = [ln for ln in p.stderr.splitlines() if ln.strip()] or ["no message"]
        raise RuntimeError(f"rerun rrd merge failed: {lines[-1]}")


def write_recording(
    path: Path,
    runs: Sequence[DriveRun],
    predictors: Sequence[str],
    color_by: str | None = None,
    traces: TraceSet | None = None,
) -> None:
    """Write ``runs`` to the Rerun file ``path``, one recording per drive (no viewer starts).

    Args:
        path: output ``.rrd`` file (its folder must exist).
        runs: the runner's per-drive results; skipped drives get only an ``info`` entry.
        predictors: predictors to include, in display (colour) order; ones absent from a
            drive's traces are left out of that drive.
        color_by: the predictor whose current-position error colours the overview map's
            track (default: the first of ``predictors``).
        traces: the run's traces, read one drive and predictor at a time, in pieces
            (:func:`~posbench.recording.traces.predictor_pieces`); None: each run's own
            (held, or in its parts).

    Raises:
        ImportError: rerun-sdk (the ``viz`` extra) is not installed.
        RuntimeError: joining the drives' recordings failed.
    """
    try:
        import rerun as rr
        import rerun.blueprint as rrb
    except ImportError:
        raise ImportError(VIZ_HINT) from None
    roots = drive_paths([r.name for r in runs])
    with tempfile.TemporaryDirectory(prefix="posbench-rrd-") as tmp:
        parts = []
        for i, (root, rid, run) in enumerate(zip(roots, recording_ids(runs), runs, strict=True)):
            part = Path(tmp) / f"{i:05d}.rrd"
            rec = rr.RecordingStream(application_id(rid), recording_id=rid)
            rec.save(part, default_blueprint=blueprint(rrb, root))
            rec.send_recording_name(rid)
            _Writer(rr, rec, predictors, color_by).drive(root, run, drive_source(run, traces))
            rec.flush()
            rec.disconnect()
            parts.append(part)
        if parts:
            merge_rrd(parts, Path(path))
        else:  # no drive: an empty recording, so the file exists
            rec = rr.RecordingStream("posbench")
            rec.save(Path(path))
            rec.flush()
            rec.disconnect()
