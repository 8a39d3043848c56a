"""The views of one drive drawn about the reference: the view around the vehicle (the
reference at (0, 0), at each 'now' query the last received fixes and the road ahead and
behind, relative to the reference then) and the overview map's track coloured by one
predictor's current-position error, with its colour scale. Positions ENU metres, errors in
metres, times drive time [s]; logged through a :class:`~posbench.recording.sender.Sender`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from posbench.recording.layout import (
    RECEIVED_RGB,
    TRUTH_RGB,
    error_colours,
    last_fixes,
    nice_scale,
    road_around,
    screen,
)
from posbench.recording.sender import Sender

#: the 'now' queries whose around view is computed and logged at once
AROUND_ROWS = 1 << 13

if TYPE_CHECKING:
    import pandas as pd

    from posbench.scoring.records import DriveRun


def around_view(
    out: Sender,
    root: str,
    run: DriveRun,
    now: tuple[np.ndarray, np.ndarray] | None,
    received: tuple[np.ndarray, np.ndarray] | None,
) -> None:
    """The reference at (0, 0), and at each 'now' query time the last fixes and the road
    ahead and behind, relative to the reference then (``now``: the 'now' queries' times [s]
    and reference positions [m], None without them; ``received``: the received fixes'
    times [s] and positions [m], None without fixes)."""
    rr, rec = out.rr, out.rec
    rec.log(
        f"{root}/around/reference",
        rr.Points2D([[0.0, 0.0]], colors=[(0, 0, 0)], radii=[0.15], labels=["reference"]),
        static=True,
    )
    if now is None:
        return
    t, ref = now
    ok = np.isfinite(t) & np.all(np.isfinite(ref), axis=1)
    t, ref = t[ok], ref[ok]
    if t.size == 0:
        return
    fix_t, fix_xy = received if received is not None else (np.empty(0), np.empty((0, 2)))
    fixes = fix_t.size > 0
    track = run.track
    tt = track["t"].to_numpy(np.float64) if track is not None else np.empty(0)
    txy = track[["x", "y"]].to_numpy(np.float64) if track is not None else np.empty((0, 2))
    road = bool(np.all(np.isfinite(txy), axis=1).sum() >= 2)
    if fixes:
        out.style(
            f"{root}/around/fixes", rr.Points2D.from_fields(colors=[RECEIVED_RGB], radii=[0.1])
        )
    if road:
        out.style(
            f"{root}/around/road", rr.LineStrips2D.from_fields(colors=[TRUTH_RGB], radii=[0.05])
        )
    for a in range(0, t.size, AROUND_ROWS):  # a slice of the queries at a time
        ts, refs = t[a : a + AROUND_ROWS], ref[a : a + AROUND_ROWS]
        if fixes:
            idx, lengths = last_fixes(ts, fix_t)
            rel = fix_xy[idx] - np.repeat(refs, lengths, axis=0)
            rr.send_columns(
                f"{root}/around/fixes",
                indexes=[out.time_column(ts)],
                columns=rr.Points2D.columns(positions=screen(rel)).partition(lengths),
                recording=rec,
            )
        if road:
            strips = road_around(ts, tt, txy) - refs[:, None, :]
            k, m, _ = strips.shape
            rr.send_columns(
                f"{root}/around/road",
                indexes=[out.time_column(ts)],
                columns=rr.LineStrips2D.columns(
                    strips=screen(strips.reshape(-1, 2)).reshape(k, m, 2)
                ).partition(np.ones(k, dtype=np.int64)),
                recording=rec,
            )
        rec.flush()


def track_colours(
    out: Sender, root: str, run: DriveRun, g: pd.DataFrame | None, color_by: str | None
) -> None:
    """The reference track in segments coloured by ``color_by``'s 'now' error (``g``: its
    'now' traces, None without them), and the colour scale as text."""
    rr, rec = out.rr, out.rec
    if g is None or g.empty or run.track is None or len(run.track) < 2:
        return
    te = g["t_query"].to_numpy(np.float64)
    e = g["error_m"].to_numpy(np.float64)
    ok = np.isfinite(te) & np.isfinite(e)
    if not ok.any():
        return
    te, e = te[ok], e[ok]
    tt = run.track["t"].to_numpy(np.float64)
    xy = run.track[["x", "y"]].to_numpy(np.float64)
    mid = 0.5 * (tt[1:] + tt[:-1])
    seg_e = np.interp(mid, te, e, left=np.nan, right=np.nan)
    # no colour where the nearest answer is far (an outage of the predictor's answers)
    j = np.searchsorted(te, mid)
    near = np.minimum(
        np.abs(mid - te[np.clip(j - 1, 0, te.size - 1)]),
        np.abs(te[np.clip(j, 0, te.size - 1)] - mid),
    )
    seg_e[near > 0.5] = np.nan
    seg = np.stack([xy[:-1], xy[1:]], axis=1)
    good = np.all(np.isfinite(seg), axis=(1, 2))
    top = nice_scale(e)
    if good.any():
        strips = screen(seg[good].reshape(-1, 2)).reshape(-1, 2, 2)
        path = f"{root}/map/track_error"
        rec.log(path, rr.LineStrips2D.from_fields(radii=[0.4]), static=True)
        # one static row of all segments (indexes=[]: static), the fast columnar path
        rr.send_columns(
            path,
            indexes=[],
            columns=rr.LineStrips2D.columns(
                strips=strips, colors=error_colours(seg_e[good], top)
            ).partition([len(strips)]),
            recording=rec,
        )
    text = (
        f"Reference track coloured by the current-position (now) error of "
        f"{color_by}: green 0 m, yellow {top / 2:g} m, red >= {top:g} m "
        f"(the scale's top is the drive's p95 rounded up); grey: no answer. "
        f"Choose the predictor with --rerun-color-by."
    )
    rec.log(f"{root}/colour_scale", rr.TextDocument(text), static=True)
