"""Column-wise logging to one rerun recording stream: points, 95 % ellipses, arrows and time
series, each row at its time on the drive's timeline
(:data:`~posbench.recording.blueprint.TIMELINE`, drive time [s]). Positions are ENU metres,
drawn in screen coordinates (north up, :func:`~posbench.recording.layout.screen`); rows with
a NaN time or position are left out. rerun itself is passed in (``rr``): nothing here
imports it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from posbench.metrics.ellipses import ellipse_outlines
from posbench.recording.blueprint import TIMELINE
from posbench.recording.layout import ELLIPSE_RADIUS, screen

#: an RGB colour, 0-255 per channel
Rgb = tuple[int, int, int]


class Sender:
    """Sends entities to the recording stream ``rec`` through the rerun module ``rr``."""

    def __init__(self, rr: Any, rec: Any) -> None:
        self.rr, self.rec = rr, rec
        self._styled: set[str] = set()

    def style(self, path: str, archetype: Any) -> None:
        """Log ``path``'s static style (colours, radii, names) once, however many pieces
        its rows are sent in."""
        if path not in self._styled:
            self._styled.add(path)
            self.rec.log(path, archetype, static=True)

    def time_column(self, t: np.ndarray) -> Any:
        """The timeline column of times ``t`` [s]."""
        return self.rr.TimeColumn(TIMELINE, duration=np.asarray(t, dtype=np.float64))

    def points(self, path: str, t: np.ndarray, xy: np.ndarray, color: Rgb, radius: float) -> None:
        """One point per row at its time, in screen coordinates; rows with NaN time or
        position are left out."""
        rr = self.rr
        ok = np.isfinite(t) & np.all(np.isfinite(xy), axis=1)
        self.style(path, rr.Points2D.from_fields(colors=[color], radii=[radius]))
        if ok.any():
            rr.send_columns(
                path,
                indexes=[self.time_column(t[ok])],
                columns=rr.Points2D.columns(positions=screen(xy[ok])),
                recording=self.rec,
            )

    def ellipses(
        self, path: str, t: np.ndarray, xy: np.ndarray, cov: np.ndarray, color: Rgb
    ) -> None:
        """The 95 % ellipse of each answer (centre ``xy`` [m, ENU], covariance ``cov`` (N, 3)
        (xx, xy, yy) [m^2]) as a closed line strip at its time, in screen coordinates; a
        row without a valid covariance or position holds no strip (the previous ellipse is
        cleared). Nothing is logged while no row has had one (a predictor without
        uncertainty; the rows of a drive are sent in pieces)."""
        rr = self.rr
        keep = np.isfinite(t)
        t, xy, cov = t[keep], xy[keep], cov[keep]
        outline = ellipse_outlines(cov)
        has = np.all(np.isfinite(xy), axis=1) & np.all(np.isfinite(outline), axis=(1, 2))
        if not has.any() and path not in self._styled:
            return  # none yet (a piece sent later clears the last ellipse where it has none)
        pts = outline[has] + xy[has, None, :]
        k, m, _ = pts.shape
        self.style(path, rr.LineStrips2D.from_fields(colors=[color], radii=[ELLIPSE_RADIUS]))
        rr.send_columns(
            path,
            indexes=[self.time_column(t)],
            columns=rr.LineStrips2D.columns(
                strips=screen(pts.reshape(-1, 2)).reshape(k, m, 2)
            ).partition(has.astype(np.int64)),
            recording=self.rec,
        )

    def scalars(self, path: str, t: np.ndarray, v: np.ndarray) -> None:
        ok = np.isfinite(t)
        if ok.any():
            self.rr.send_columns(
                path,
                indexes=[self.time_column(t[ok])],
                columns=self.rr.Scalars.columns(scalars=v[ok]),
                recording=self.rec,
            )

    def series(
        self, path: str, t: np.ndarray, v: np.ndarray, name: str, color: Rgb, kind: str
    ) -> None:
        """A time series: a line for ``now`` queries, points for ``future`` ones."""
        rr = self.rr
        style = (
            rr.SeriesLines(colors=[color], names=[name], widths=[1.5])
            if kind == "now"
            else rr.SeriesPoints(colors=[color], names=[name], marker_sizes=[2.0])
        )
        self.style(path, style)
        self.scalars(path, t, v)

    def arrows(self, path: str, t: np.ndarray, rel: np.ndarray, color: Rgb) -> None:
        """Arrows from (0, 0) (the reference) to each relative answer, at their times."""
        rr = self.rr
        ok = np.isfinite(t) & np.all(np.isfinite(rel), axis=1)
        self.style(
            path, rr.Arrows2D.from_fields(colors=[color], radii=[0.03], origins=[[0.0, 0.0]])
        )
        if ok.any():
            rr.send_columns(
                path,
                indexes=[self.time_column(t[ok])],
                columns=rr.Arrows2D.columns(vectors=screen(rel[ok])),
                recording=self.rec,
            )
