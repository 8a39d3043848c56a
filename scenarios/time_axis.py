"""Checks of a drive's time axis at load: the unit of its times, gaps inside a stream, and
the span of the whole drive (pure numpy; times in seconds).

Why: the arrays the data check and the replay build are sized by a drive's time *span*, not
by its number of samples (the data check's 10 Hz reference grid, the replay's 0.1 s
reference grid and its "now" queries every 0.05 s). One wrong stamp (half a file shifted by
ten years) or a column in milliseconds read as seconds (an hour of fixes read as a 42-day
drive) would size them in gigabytes from a file of kilobytes. So every loader checks, and
refuses with one line (:class:`~posbench.scenarios.errors.DataError`) naming where:

- **unit** (:func:`check_rate`): a stream of at least :data:`MIN_STEPS_FOR_RATE` steps whose
  median step lies outside :data:`STEP_RANGE_S` for its kind (a GPS fixing every 200 s, an
  IMU sampling every second) is not in the unit the format says. The line names the unit the
  times evidently have, e.g. ``t looks like milliseconds, not seconds (the gps stream's
  median step is 200, a 5 Hz stream in milliseconds; ...); give t in seconds``. Such times
  are refused, never read in the guessed unit: a guess that is wrong by a factor of 1000
  would be silently wrong everywhere after, while the fix is one division by the user, who
  knows the unit.
- **gap** (:func:`check_gaps`): two consecutive samples of one stream more than
  :data:`MAX_GAP_S` apart; the line names the sample where the gap starts (CSV line, bag
  topic and message index, data file) and the one after it.
- **span** (:func:`check_span`): the streams of one drive together spanning more than
  :data:`MAX_SPAN_S`, e.g. streams on different clocks (a GPS in Unix time beside an IMU
  in seconds since boot). :class:`~posbench.scenarios.drive.Drive` checks this for every
  drive, however it was made.

A drive that passes has at most :data:`MAX_SPAN_S` x 20 Hz = 576 000 "now" queries and a
10 Hz reference grid of at most 288 000 points (2.3 MB a float64 column), whatever its
stamps; :func:`grid_size` guards the grids themselves against any input.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from posbench.scenarios.errors import DataError

#: the longest gap [s] between consecutive samples of one stream (1 h): far beyond any GNSS
#: outage on a road (the longest road tunnels take ~15 min to drive through) and the largest
#: gap in the shared real data (1.0 s, an aslan route's fixes); a longer pause is two
#: recordings in one file, or a wrong stamp
MAX_GAP_S = 3600.0
#: the longest span [s] of one drive, all streams together (8 h, a working day at the wheel):
#: public drive recordings last seconds to 1-2 h. It bounds every array sized by the span
#: (see the module notes); the replay's cost grows with it too (a "now" query every 0.05 s
#: for each predictor): a default ``bench run`` of an 8 h drive of 961 fixes (a 36 kB file)
#: peaks at 1.4 GB resident (24 h: 3.7 GB)
MAX_SPAN_S = 8 * 3600.0
#: the most points [-] any grid over a drive's span may hold: MAX_SPAN_S at 100 Hz
#: (2.9 M points, 23 MB a float64 column); :func:`grid_size` refuses more
MAX_GRID_POINTS = int(MAX_SPAN_S * 100)
#: steps [-] a stream needs before its median step says anything about its unit
MIN_STEPS_FOR_RATE = 8
#: the plausible median step [s] of each kind of stream, (fastest, slowest): GNSS receivers
#: and reference systems fix at 1000 Hz .. one fix per 30 s (vehicles: 1-25 Hz); IMUs sample
#: at 20 kHz .. 2 Hz (vehicles: 10-1000 Hz; a slower one cannot follow a car); wheel and
#: CAN speed at 10 kHz .. one sample per 5 s (OBD-II polling: ~1 Hz)
STEP_RANGE_S: dict[str, tuple[float, float]] = {
    "gps": (1e-3, 30.0),
    "truth": (1e-3, 30.0),
    "imu": (5e-5, 0.5),
    "speed": (1e-4, 5.0),
}
#: time units [s] a column may evidently be in, named as the message names them
UNITS_S: dict[str, float] = {
    "nanoseconds": 1e-9,
    "microseconds": 1e-6,
    "milliseconds": 1e-3,
    "seconds": 1.0,
}


def duration_text(s: float) -> str:
    """A duration [s] as a person reads it: ``"75 s"``, ``"12.5 min"``, ``"3652.5 days"``."""
    a = abs(float(s))
    if a < 120:
        return f"{s:.3g} s"
    if a < 3600:
        return f"{s / 60:.3g} min"
    if a < 2 * 86400:
        return f"{s / 3600:.3g} h"
    return f"{s / 86400:.1f} days"


def evident_unit(median_step: float, unit: str, kind: str) -> str | None:
    """The unit times evidently have whose median step is ``median_step`` when read in
    ``unit`` (a key of :data:`UNITS_S`): the other unit that puts the step closest (in
    ratio) to the middle of the plausible range of a ``kind`` stream; None when none puts
    it inside that range."""
    lo, hi = STEP_RANGE_S[kind]
    raw = median_step / UNITS_S[unit]  # the step in the column's own numbers
    middle = np.sqrt(lo * hi)
    fits = {
        name: abs(np.log(raw * s / middle))
        for name, s in UNITS_S.items()
        if name != unit and lo <= raw * s <= hi
    }
    return min(fits, key=lambda n: fits[n]) if fits else None


def check_rate(
    t: np.ndarray, kind: str, source: str | Path, what: str, unit: str = "seconds"
) -> None:
    """Refuse a stream whose median step is implausible for its ``kind`` (see
    :data:`STEP_RANGE_S`), saying which unit its times evidently have.

    Args:
        t: the stream's times [s], strictly increasing, as read in ``unit``.
        kind: ``gps``, ``imu``, ``speed`` or ``truth``.
        source: the file or folder, for the message.
        what: the times as the user knows them, e.g. ``"t"`` or ``"topic /imu header stamps"``.
        unit: the unit the format says the times are in (a key of :data:`UNITS_S`).
    Raises:
        DataError: the median step is outside the range of ``kind``.
    """
    if t.size <= MIN_STEPS_FOR_RATE:
        return
    med = float(np.median(np.diff(t)))
    lo, hi = STEP_RANGE_S[kind]
    if lo <= med <= hi:
        return
    raw = med / UNITS_S[unit]
    guess = evident_unit(med, unit, kind)
    plausible = f"a {kind} stream steps {lo:g} s to {hi:g} s"
    if guess is None:
        raise DataError(
            source,
            f"{what}: the {kind} stream's median step is {duration_text(med)}, implausible "
            f"for {unit} ({plausible}); give the times in {unit}",
        )
    hz = 1.0 / (raw * UNITS_S[guess])
    raise DataError(
        source,
        f"{what} looks like {guess}, not {unit} (the {kind} stream's median step is {raw:.6g},"
        f" a {hz:.3g} Hz stream in {guess}; {plausible}); give {what} in {unit}",
    )


def check_gaps(t: np.ndarray, kind: str, source: str | Path, where: Callable[[int], str]) -> None:
    """Refuse a stream with a gap longer than :data:`MAX_GAP_S` between two samples.

    Args:
        t: the stream's times [s], strictly increasing.
        kind: the stream's name for the message (``gps``, ``imu``, ...).
        source: the file or folder, for the message.
        where: names sample ``i`` of ``t`` as the user finds it in the file (``"line 151"``,
            ``"topic /fix message 7"``); called only for the message.
    Raises:
        DataError: naming where the first such gap starts and the sample after it.
    """
    if t.size < 2:
        return
    steps = np.diff(t)
    long = np.flatnonzero(steps > MAX_GAP_S)
    if long.size == 0:
        return
    i = int(long[0])
    more = f"; {long.size} such gaps in all" if long.size > 1 else ""
    raise DataError(
        source,
        f"{where(i)}: the {kind} stream's next sample ({where(i + 1)}) is "
        f"{duration_text(float(steps[i]))} later, more than the {duration_text(MAX_GAP_S)} a "
        f"stream may pause{more} (a wrong time stamp, or two recordings in one file: fix it "
        "or split the file there)",
    )


def check_stream_times(
    t: np.ndarray,
    kind: str,
    source: str | Path,
    where: Callable[[int], str],
    what: str = "times",
    unit: str = "seconds",
) -> None:
    """:func:`check_rate` then :func:`check_gaps` of one stream's times [s] (strictly
    increasing); ``what`` and ``unit`` as :func:`check_rate` takes them."""
    check_rate(t, kind, source, what, unit)
    check_gaps(t, kind, source, where)


def check_span(streams: Mapping[str, np.ndarray], source: str | Path | None) -> None:
    """Refuse a drive whose streams (name -> times [s] on one clock, sorted) together span
    more than :data:`MAX_SPAN_S`, naming each stream's first and last time.

    Raises:
        DataError: over the limit; says when the streams do not even overlap (different
            clocks) or when one stream alone is that long (split the drive).
    """
    spans = {k: (float(t[0]), float(t[-1])) for k, t in streams.items() if t.size}
    if not spans:
        return
    t0 = min(a for a, _ in spans.values())
    t1 = max(b for _, b in spans.values())
    if t1 - t0 <= MAX_SPAN_S:
        return
    each = ", ".join(f"{k} {a - t0:.6g} s to {b - t0:.6g} s" for k, (a, b) in spans.items())
    ordered = sorted(spans.values())
    ends = np.maximum.accumulate([b for _, b in ordered])
    apart = any(a > end for (a, _), end in zip(ordered[1:], ends[:-1], strict=True))
    why = (
        "the streams do not overlap in time: are they on different clocks?"
        if apart
        else "split it into drives of at most that length"
    )
    raise DataError(
        source,
        f"the drive spans {duration_text(t1 - t0)} ({each}), over the "
        f"{duration_text(MAX_SPAN_S)} allowed for one drive: {why}",
    )


def grid_size(t0: float, t1: float, step_s: float, source: str | Path | None = None) -> int:
    """The number of points of a grid from ``t0`` to ``t1`` [s] every ``step_s`` [s]
    (``np.arange(t0, t1 + step_s / 2, step_s)``), checked before anything is allocated.

    Raises:
        DataError: more than :data:`MAX_GRID_POINTS` points, or non-finite ends.
    """
    span = float(t1) - float(t0)
    if not np.isfinite(span) or step_s <= 0:
        raise DataError(source, f"cannot build a time grid from {t0!r} s to {t1!r} s")
    n = max(int(np.ceil((span + step_s / 2) / step_s)), 0)
    if n > MAX_GRID_POINTS:
        raise DataError(
            source,
            f"a {step_s:g} s grid over {duration_text(span)} would hold {n} points, over the "
            f"{MAX_GRID_POINTS} allowed (a drive spans at most {duration_text(MAX_SPAN_S)})",
        )
    return n
