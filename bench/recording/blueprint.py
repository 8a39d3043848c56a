"""The default layout (rerun blueprint) of one drive's recording (:mod:`posbench.recording.writer`).

Three columns: the whole-drive map (overview, trailing :data:`TRAIL_S`) over the colour
scale of its error-coloured track; the view around the vehicle (north up, the reference at
(0, 0), :data:`AROUND_M` metres each way) over the errors in the vehicle frame (ahead to
the right, left up, :data:`VEHICLE_M` metres each way, trailing :data:`ERROR_TRAIL_S`);
the Euclidean, along-track and cross-track error plots over the scenario labels.

rerun 0.41 places a plot legend only inside the plot (a corner, or hidden): it sits in the
top-right corner, where these plots have the least data (errors are small most of the
time; the along/cross plots are centred on 0).
"""

from __future__ import annotations

from typing import Any

TIMELINE = "time"
TRAIL_S = 10.0  # how much history the overview map shows [s]
AROUND_M = 5.0  # the around-the-vehicle view shows +-this many metres [m]
VEHICLE_M = 1.0  # the vehicle-frame error view shows +-this many metres [m]
ERROR_TRAIL_S = 3.0  # how much history the vehicle-frame error view shows [s]


def _trail(rrb: Any, seconds: float) -> Any:
    return rrb.VisibleTimeRange(
        TIMELINE,
        start=rrb.TimeRangeBoundary.cursor_relative(seconds=-seconds),
        end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0),
    )


def _bounds(rrb: Any, half_m: float) -> Any:
    return rrb.VisualBounds2D(x_range=[-half_m, half_m], y_range=[-half_m, half_m])


def _plot(rrb: Any, root: str, name: str, contents: list[str]) -> Any:
    return rrb.TimeSeriesView(
        origin=root,
        name=name,
        contents=contents,
        plot_legend=rrb.PlotLegend(corner=rrb.Corner2D.RightTop, visible=True),
    )


def blueprint(rrb: Any, root: str) -> Any:
    """Default layout for the drive under entity root ``root`` (``drives/<drive>``)."""
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin=f"{root}/map",
                    name="map (whole drive, north up)",
                    time_ranges=[_trail(rrb, TRAIL_S)],
                ),
                rrb.TextDocumentView(origin=f"{root}/colour_scale", name="map colours"),
                row_shares=[5, 1],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(
                    origin=f"{root}/around",
                    name=f"around the vehicle (north up, +-{AROUND_M:g} m)",
                    visual_bounds=_bounds(rrb, AROUND_M),
                ),
                rrb.Spatial2DView(
                    origin=f"{root}/vehicle_frame",
                    name="errors in the vehicle frame (ahead ->, left up)",
                    visual_bounds=_bounds(rrb, VEHICLE_M),
                    time_ranges=[_trail(rrb, ERROR_TRAIL_S)],
                ),
                row_shares=[1, 1],
            ),
            rrb.Vertical(
                _plot(rrb, root, "error [m]", ["$origin/errors/**", "$origin/outages"]),
                _plot(
                    rrb, root, "along-track error [m] (+ ahead, - lagging)", ["$origin/along/**"]
                ),
                _plot(rrb, root, "cross-track error [m] (+ left, - right)", ["$origin/cross/**"]),
                rrb.TextLogView(origin=f"{root}/labels", name="scenario labels"),
                row_shares=[3, 2, 2, 1],
            ),
            column_shares=[3, 3, 3],
        ),
        collapse_panels=False,
    )
