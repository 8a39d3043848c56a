"""Write a benchmark run to a Rerun recording (``.rrd``) for interactive replay.

Needs the ``viz`` extra (rerun-sdk); rerun is imported only inside
:func:`write_recording`. Everything is sent column-wise (``send_columns``), so a
10-minute drive with several predictors writes in about a second.

Layout, per drive under ``drives/<drive>/`` (names sanitised to ``[A-Za-z0-9_.-]``):

- ``map/truth``: static line strip(s) of the reference track (truth or the fix cubic),
  split at gaps (NaN);
- ``map/fixes/received``, ``map/fixes/dropped``: one point per fix at its time
  (dropped = removed by the dropout step);
- ``map/<predictor>/future``: the future point, logged at its query time
  ``t_query = t_issue + horizon`` so it lines up with the track position it is scored against;
- ``map/<predictor>/now``: the current-position answer at each "now" query time;
- ``errors/<predictor>/future``, ``errors/<predictor>/now``: error [m] time series;
- ``labels``: a text log entry each time the scenario label changes;
- ``outages``: a 1/0 step series (1 between the last fix before and the first fix after
  an outage);
- ``info``: static text with the run's reference, notes and warnings (or why it was skipped).

Timeline ``time``: drive time [s] (``duration``), the drive's own t. Map positions are in
the drive's local frame [m] (x east, y north for ENU). Rows whose position is
NaN are not logged on the map; errors are logged for every query, NaN (not scorable) included.
The default blueprint shows the first drive: a 2-D map with a trailing 10 s of points,
error plots (with outages) and the label log.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

    from bench.runner import DriveRun

VIZ_HINT = "rerun recordings need the viz extra: pip install 'posbench[viz]'"
TIMELINE = "time"
TRAIL_S = 10.0  # how much history the default map view shows [s]

# tab10, as RGB
PALETTE = np.array([
    [31, 119, 180], [255, 127, 14], [44, 160, 44], [214, 39, 40], [148, 103, 189],
    [140, 86, 75], [227, 119, 194], [127, 127, 127], [188, 189, 34], [23, 190, 207],
], dtype=np.uint8)
RECEIVED_RGB = (20, 20, 20)
DROPPED_RGB = (230, 30, 30)
TRUTH_RGB = (160, 160, 160)

_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]+")


def sanitise(name: str) -> str:
    """An entity-path part from any name: runs of characters outside ``[A-Za-z0-9_.-]``
    become ``_``; empty names become ``_``."""
    s = _UNSAFE.sub("_", str(name)).strip("_")
    return s or "_"


def drive_paths(names: Sequence[str]) -> list[str]:
    """Entity roots ``drives/<name>`` for drive names, made unique (``_2``, ``_3``...) when two
    names sanitise to the same part."""
    seen: dict[str, int] = {}
    out = []
    for n in names:
        s = sanitise(n)
        k = seen.get(s, 0) + 1
        seen[s] = k
        out.append(f"drives/{s}" if k == 1 else f"drives/{s}_{k}")
    return out


def _finite_runs(xy: np.ndarray) -> list[np.ndarray]:
    """Contiguous runs of finite rows of an (N, 2) array with at least 2 points."""
    ok = np.all(np.isfinite(xy), axis=1)
    if not ok.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.view(np.int8), [0]])))
    return [xy[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


def _change_points(labels: np.ndarray) -> np.ndarray:
    """Indices where a label differs from the previous one (index 0 included)."""
    if labels.size == 0:
        return np.empty(0, dtype=np.int64)
    return np.concatenate([[0], np.flatnonzero(labels[1:] != labels[:-1]) + 1])


def outage_steps(outages: Sequence[tuple[float, float]], t0: float, t1: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and 1/0 values of a step series that is 1 inside each outage
    ``(t_last_fix, t_next_fix)`` and 0 elsewhere over ``[t0, t1]`` (plot with StepAfter)."""
    o = np.asarray(sorted(outages), dtype=float).reshape(-1, 2)
    t = np.concatenate([[t0], o.ravel(), [t1]])
    v = np.concatenate([[0.0], np.tile([1.0, 0.0], len(o)), [0.0]])
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def _color(i: int) -> tuple[int, int, int]:
    return tuple(int(c) for c in PALETTE[i % len(PALETTE)])


class _Writer:
    """Sends one run's drives to a recording stream."""

    def __init__(self, rr: Any, rec: Any, predictors: Sequence[str]) -> None:
        self.rr, self.rec = rr, rec
        self.predictors = list(predictors)
        self.pred_parts = [sanitise(p) for p in predictors]

    def _time(self, t: np.ndarray) -> Any:
        return self.rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=np.float64))

    def points(self, path: str, t: np.ndarray, xy: np.ndarray, color, radius: float) -> None:
        """One point per row at its time; rows with NaN time or position are left out."""
        rr = self.rr
        ok = np.isfinite(t) & np.all(np.isfinite(xy), axis=1)
        self.rec.log(path, rr.Points2D.from_fields(colors=[color], radii=[radius]), static=True)
        if ok.any():
            rr.send_columns(path, indexes=[self._time(t[ok])],
                            columns=rr.Points2D.columns(positions=xy[ok].astype(np.float32)),
                            recording=self.rec)

    def scalars(self, path: str, t: np.ndarray, v: np.ndarray) -> None:
        ok = np.isfinite(t)
        if ok.any():
            self.rr.send_columns(path, indexes=[self._time(t[ok])],
                                 columns=self.rr.Scalars.columns(scalars=v[ok]), recording=self.rec)

    def drive(self, root: str, run: DriveRun) -> None:
        rr, rec = self.rr, self.rec
        info = [f"drive: {run.name}", f"dataset: {run.dataset}",
                f"reference: {run.reference or '-'}", f"duration: {run.duration_s:.1f} s",
                f"fixes received: {run.gps_count}"]
        info += [f"note: {n}" for n in run.notes] + [f"warning: {w}" for w in run.warnings]
        if run.skipped:
            info.append(f"SKIPPED: {run.skipped}")
        rec.log(f"{root}/info", rr.TextDocument("\n".join(info)), static=True)
        if run.skipped:
            return

        if run.track is not None and len(run.track):
            strips = _finite_runs(run.track[["x", "y"]].to_numpy(np.float64))
            if strips:
                rec.log(f"{root}/map/truth", rr.LineStrips2D(strips, colors=[TRUTH_RGB],
                                                             radii=[0.15]), static=True)
        if run.fixes is not None and len(run.fixes):
            f = run.fixes
            t, xy = f["t"].to_numpy(np.float64), f[["x", "y"]].to_numpy(np.float64)
            rcv = f["received"].to_numpy(bool)
            self.points(f"{root}/map/fixes/received", t[rcv], xy[rcv], RECEIVED_RGB, 0.35)
            self.points(f"{root}/map/fixes/dropped", t[~rcv], xy[~rcv], DROPPED_RGB, 0.5)

        tr = run.traces
        if tr is None or tr.empty:
            return
        groups = {key: g for key, g in tr.groupby(["predictor", "kind"], sort=False)}
        for i, (pred, part) in enumerate(zip(self.predictors, self.pred_parts, strict=True)):
            color = _color(i)
            for kind, radius in (("future", 0.4), ("now", 0.25)):
                g = groups.get((pred, kind))
                if g is None or g.empty:
                    continue
                g = g.sort_values("t_query", kind="stable")
                t = g["t_query"].to_numpy(np.float64)
                self.points(f"{root}/map/{part}/{kind}", t, g[["x", "y"]].to_numpy(np.float64),
                            color, radius)
                epath = f"{root}/errors/{part}/{kind}"
                style = (rr.SeriesLines(colors=[color], names=[f"{pred} {kind}"], widths=[1.5])
                         if kind == "now" else
                         rr.SeriesPoints(colors=[color], names=[f"{pred} {kind}"],
                                         marker_sizes=[2.0]))
                rec.log(epath, style, static=True)
                self.scalars(epath, t, g["error_m"].to_numpy(np.float64))
        self._labels(root, tr)
        self._outages(root, run, tr)

    def _labels(self, root: str, tr: pd.DataFrame) -> None:
        """Label changes along the 'now' queries of one predictor (labels depend only on time)."""
        rr = self.rr
        now = tr[tr["kind"] == "now"]
        if now.empty:
            now = tr
        now = now[now["predictor"] == now["predictor"].iloc[0]].sort_values("t_query")
        lab = now["label"].astype(str).to_numpy()
        idx = _change_points(lab)
        if idx.size:
            rr.send_columns(f"{root}/labels",
                            indexes=[self._time(now["t_query"].to_numpy(np.float64)[idx])],
                            columns=rr.TextLog.columns(text=lab[idx], level=["INFO"] * idx.size),
                            recording=self.rec)

    def _outages(self, root: str, run: DriveRun, tr: pd.DataFrame) -> None:
        rr = self.rr
        span = np.concatenate([tr["t_query"].to_numpy(np.float64),
                               np.asarray(run.outages, dtype=float).ravel()])
        span = span[np.isfinite(span)]
        if span.size == 0:
            return
        t0, t1 = float(span.min()), float(span.max())
        t, v = outage_steps(run.outages, t0, t1)
        self.rec.log(f"{root}/outages",
                     rr.SeriesLines(colors=[DROPPED_RGB], names=["GPS outage (1 = in outage)"],
                                    interpolation_mode=rr.components.InterpolationMode.StepAfter),
                     static=True)
        self.scalars(f"{root}/outages", t, v)


def blueprint(rrb: Any, root: str) -> Any:
    """Default layout for one drive root: map | (errors + outages, label log)."""
    trail = rrb.VisibleTimeRange(TIMELINE,
                                 start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRAIL_S),
                                 end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin=f"{root}/map", name="map", time_ranges=[trail]),
            rrb.Vertical(
                rrb.TimeSeriesView(origin=root, name="errors [m]",
                                   contents=["$origin/errors/**", "$origin/outages"]),
                rrb.TextLogView(origin=f"{root}/labels", name="scenario labels"),
                row_shares=[3, 1]),
            column_shares=[3, 2]),
        collapse_panels=False)


def write_recording(path: Path, runs: Sequence[DriveRun], predictors: Sequence[str]) -> None:
    """Write ``runs`` to the Rerun file ``path`` (no viewer is started).

    Args:
        path: output ``.rrd`` file (its folder must exist).
        runs: the runner's per-drive results; skipped drives get only an ``info`` entry.
        predictors: predictors to include, in display (colour) order; ones absent from a
            drive's traces are left out of that drive.

    Raises:
        ImportError: rerun-sdk (the ``viz`` extra) is not installed.
    """
    try:
        import rerun as rr
        import rerun.blueprint as rrb
    except ImportError:
        raise ImportError(VIZ_HINT) from None
    roots = drive_paths([r.name for r in runs])
    first = next((root for root, r in zip(roots, runs, strict=True) if not r.skipped),
                 roots[0] if roots else "drives")
    rec = rr.RecordingStream("posbench")
    rec.save(Path(path), default_blueprint=blueprint(rrb, first))
    w = _Writer(rr, rec, predictors)
    for root, run in zip(roots, runs, strict=True):
        w.drive(root, run)
    rec.flush()
    rec.disconnect()
