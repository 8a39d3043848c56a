"""The pure part of a rerun recording (no rerun import): entity-path names and recording ids
per drive, 2-D positions on screen (north up), what the view around the vehicle shows (the
last fixes, the road ahead and behind), outage steps, and the colours (one per predictor,
the error scale). :mod:`posbench.recording.writer` logs what these compute."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from posbench.naming import file_safe, unique_file_safe

if TYPE_CHECKING:
    from posbench.scoring.records import DriveRun


N_LAST_FIXES = 5  # fixes shown around the vehicle
ROAD_S = (-2.0, 1.0)  # the stretch of reference shown around the vehicle [s], relative
ROAD_STEP_S = 0.25
# tab10, as RGB
PALETTE = np.array(
    [
        [31, 119, 180],
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [127, 127, 127],
        [188, 189, 34],
        [23, 190, 207],
    ],
    dtype=np.uint8,
)
RECEIVED_RGB = (20, 20, 20)
DROPPED_RGB = (230, 30, 30)
TRUTH_RGB = (160, 160, 160)
#: the error colour scale: green at 0, yellow at half the scale, red at and above it
SCALE_RGB = np.array([[26, 152, 80], [254, 224, 60], [215, 25, 28]], dtype=float)
NO_ERROR_RGB = (190, 190, 190)
#: line radius of the drawn 95 % ellipses: 0.75 UI points (negative: rerun's UI unit), so a
#: 2 cm ellipse stays an outline when zoomed in
ELLIPSE_RADIUS = -0.75


def sanitise(name: str) -> str:
    """An entity-path part from any name (:func:`posbench.naming.file_safe`; ``_`` for a
    name with nothing safe in it)."""
    return file_safe(name, empty="_")


def drive_paths(names: Sequence[str]) -> list[str]:
    """Entity roots ``drives/<name>`` for drive names, made unique (``_2``, ``_3``...) when two
    names sanitise to the same part (:func:`posbench.naming.unique_file_safe`)."""
    return [f"drives/{s}" for s in unique_file_safe(names, sep="_", empty="_")]


def recording_ids(runs: Sequence[DriveRun]) -> list[str]:
    """``<dataset>/<drive>`` per run, made unique (`` (2)``...) when two coincide."""
    seen: dict[str, int] = {}
    out = []
    for r in runs:
        s = f"{r.dataset}/{r.name}"
        k = seen.get(s, 0) + 1
        seen[s] = k
        out.append(s if k == 1 else f"{s} ({k})")
    return out


def application_id(recording: str) -> str:
    """The rerun application id of a drive's recording: ``posbench-<dataset>-<drive>`` with
    characters outside ``[A-Za-z0-9_-]`` as ``_`` (a blueprint belongs to an application id,
    so each drive gets its own to keep its own default layout)."""
    return "posbench-" + re.sub(r"[^A-Za-z0-9_\-]+", "_", recording.replace("/", "-"))


def screen(xy: np.ndarray) -> np.ndarray:
    """(N, 2) ENU [m] -> rerun 2-D view coordinates (x, -y) as float32 (rerun's 2-D views
    draw y downwards; this puts north up)."""
    a = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.column_stack([a[:, 0], -a[:, 1]]).astype(np.float32)


def finite_runs(xy: np.ndarray) -> list[np.ndarray]:
    """Contiguous runs of finite rows of an (N, 2) array with at least 2 points."""
    ok = np.all(np.isfinite(xy), axis=1)
    if not ok.any():
        return []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.view(np.int8), [0]])))
    return [xy[a:b] for a, b in zip(edges[::2], edges[1::2], strict=True) if b - a >= 2]


def change_points(labels: np.ndarray) -> np.ndarray:
    """Indices where a label differs from the previous one (index 0 included)."""
    if labels.size == 0:
        return np.empty(0, dtype=np.int64)
    return np.concatenate([[0], np.flatnonzero(labels[1:] != labels[:-1]) + 1])


def outage_steps(
    outages: Sequence[tuple[float, float]], t0: float, t1: float
) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and 1/0 values of a step series that is 1 inside each outage
    ``(t_last_fix, t_next_fix)`` and 0 elsewhere over ``[t0, t1]`` (plot with StepAfter)."""
    o = np.asarray(sorted(outages), dtype=float).reshape(-1, 2)
    t = np.concatenate([[t0], o.ravel(), [t1]])
    v = np.concatenate([[0.0], np.tile([1.0, 0.0], len(o)), [0.0]])
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def last_fixes(
    t_now: np.ndarray, t_fix: np.ndarray, n: int = N_LAST_FIXES
) -> tuple[np.ndarray, np.ndarray]:
    """For each time of ``t_now`` [s], the indices of the last ``n`` fixes of sorted ``t_fix``
    at or before it: (flat indices in row order, row lengths)."""
    j = np.searchsorted(t_fix, t_now, side="right")
    idx = j[:, None] - n + np.arange(n)[None, :]
    ok = idx >= 0
    return idx[ok], ok.sum(axis=1)


def road_around(
    t_now: np.ndarray,
    track_t: np.ndarray,
    track_xy: np.ndarray,
    span_s: tuple[float, float] = ROAD_S,
    step_s: float = ROAD_STEP_S,
) -> np.ndarray:
    """(K, M, 2) reference positions [m] from ``span_s[0]`` to ``span_s[1]`` around each
    time of ``t_now`` (linear between track samples, clamped at the track's ends)."""
    off = np.arange(span_s[0], span_s[1] + 1e-9, step_s)
    tt = (np.asarray(t_now, dtype=float)[:, None] + off[None, :]).ravel()
    ok = np.all(np.isfinite(track_xy), axis=1)
    x = np.interp(tt, track_t[ok], track_xy[ok, 0])
    y = np.interp(tt, track_t[ok], track_xy[ok, 1])
    return np.stack([x, y], axis=-1).reshape(len(t_now), off.size, 2)


def nice_scale(errors: np.ndarray) -> float:
    """The top of the colour scale [m]: the p95 of the finite errors rounded up to 1, 2 or 5
    times a power of ten (0.1 m when there is none)."""
    e = np.asarray(errors, dtype=float)
    e = e[np.isfinite(e)]
    if e.size == 0 or np.percentile(e, 95) <= 0:
        return 0.1
    p = float(np.percentile(e, 95))
    base = 10.0 ** np.floor(np.log10(p))
    return float(next(m * base for m in (1, 2, 5, 10) if m * base >= p - 1e-12))


def error_colours(errors: np.ndarray, top_m: float) -> np.ndarray:
    """(N, 3) uint8 colours: green at 0 m, yellow at ``top_m`` / 2, red at and above
    ``top_m`` [m]; grey for NaN."""
    e = np.asarray(errors, dtype=float)
    u = np.nan_to_num(np.clip(e / top_m, 0.0, 1.0)) * 2.0
    lo = np.clip(np.floor(u), 0, 1).astype(int)
    w = (u - lo)[:, None]
    rgb = SCALE_RGB[lo] * (1 - w) + SCALE_RGB[lo + 1] * w
    rgb[~np.isfinite(e)] = NO_ERROR_RGB
    colours: np.ndarray = np.round(rgb).astype(np.uint8)
    return colours


def predictor_color(i: int) -> tuple[int, int, int]:
    """The RGB colour (0-255) of the ``i``-th predictor, the palette repeating."""
    r, g, b = PALETTE[i % len(PALETTE)]
    return int(r), int(g), int(b)
