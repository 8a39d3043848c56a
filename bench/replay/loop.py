"""Replay one prepared drive through one predictor, exactly as a vehicle would see it.

All observations (GPS fixes fed, IMU, speed) and the "now" queries are merged
into one time-ordered event list; at equal times observations come before the
query. A "future" query is asked right after its fix is observed, so the
predictor never holds an observation stamped after the time it is asked about.
Every fix step (``observe_gps`` + the future query) and every "now" query is
timed with ``perf_counter_ns``.

A predictor that reports uncertainty (:func:`reports_covariance`) is asked
``covariance_at`` right after each ``position_at``, with the same time; that call is
timed on its own (``cov_ns``), never charged to the step's or query's latency.

Fix accuracy: a predictor whose ``observe_gps`` takes ``sigma``
(:func:`posbench.predictors.base.accepts_sigma`, checked once per replay) gets each fix's stated
per-axis 1-sigma [m] (``GpsStream.accuracy``) as ``sigma=``, or ``sigma=None`` where the
stream states none or the value is not finite and positive, and at most :data:`MAX_SIGMA_M`;
others get (t, x, y) only.

:func:`replay` is the runner's loop (timed, in chunks of Python floats); :func:`events` and
:func:`feed` are the same events and calls one at a time, for checks that stop, copy or
probe a predictor between events (:mod:`posbench.predictor_tools.contract`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from time import perf_counter_ns

import numpy as np

from posbench.predictors.base import Predictor, accepts_sigma
from posbench.replay.prepare import PreparedDrive

#: event kinds, in the order they are handled at equal times
GPS, IMU, SPEED, QUERY = 0, 1, 2, 3


@dataclass
class ReplayResult:
    """Predicted positions [m] for each query, and call durations [ns]."""

    future_xy: np.ndarray  # (n_fixes, 2)
    now_xy: np.ndarray  # (n_now, 2)
    step_ns: np.ndarray  # per fix: observe_gps + future position_at
    query_ns: np.ndarray  # per now query
    #: (n_fixes + n_now, 3): cov_xx, cov_xy, cov_yy [m^2] of each answer (future rows, then
    #: now rows); NaN where the predictor gave None. None: no covariance_at at all
    cov: np.ndarray | None = None
    #: (n_fixes + n_now,) duration of each covariance_at call [ns]; None with ``cov``
    cov_ns: np.ndarray | None = None


def reports_covariance(predictor: Predictor) -> bool:
    """Whether ``predictor`` (or the predictor a gate wraps) overrides
    :meth:`~posbench.predictors.base.Predictor.covariance_at`; the base default ("no uncertainty")
    is never called."""
    inner = getattr(predictor, "inner", predictor)
    return type(inner).covariance_at is not Predictor.covariance_at


def _store_cov(out: np.ndarray, i: int, c: object) -> None:
    """Row i of ``out`` <- (xx, xy, yy) of the 2x2 covariance c (left NaN when None)."""
    if c is not None:
        m = np.asarray(c, dtype=float)
        out[i] = m[0, 0], 0.5 * (m[0, 1] + m[1, 0]), m[1, 1]


#: events converted to Python floats at a time (:func:`event_windows`): memory stays bounded
#: by this window, not by the drive's length
CHUNK_EVENTS = 1 << 16


def _event_times(prep: PreparedDrive) -> list[np.ndarray]:
    """Each event kind's times [s] (strictly increasing: :class:`~posbench.scenarios.drive.Drive`
    checks it), indexed by kind; empty for a stream the drive lacks."""
    d = prep.drive
    none = np.empty(0)
    return [
        prep.gps.t,
        d.imu.t if d.imu is not None else none,
        d.speed.t if d.speed is not None else none,
        prep.now.t_issue,
    ]


def _ordered(parts: list[tuple[int, np.ndarray, int]]) -> tuple[np.ndarray, np.ndarray]:
    """(kind, index) of the events ``(kind, times, first index)``, by time and, at equal
    times, by kind (a stable sort: a kind's events keep their order)."""
    t = np.concatenate([p[1] for p in parts])
    k = np.concatenate([np.full(p[1].size, p[0], dtype=np.int8) for p in parts])
    idx = np.concatenate([np.arange(p[2], p[2] + p[1].size) for p in parts])
    order = np.lexsort((k, t))
    return k[order], idx[order]


def build_events(prep: PreparedDrive) -> tuple[np.ndarray, np.ndarray]:
    """(kind, index) arrays of all events in replay order."""
    return _ordered([(kind, t, 0) for kind, t in enumerate(_event_times(prep))])


def event_windows(
    prep: PreparedDrive, events: int = CHUNK_EVENTS
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """:func:`build_events` in consecutive time windows of about ``events`` events each (as
    many as the drive's mean event rate puts in the window's span): the same events in the
    same order, without holding a long drive's event list. Every kind is cut at the same
    instants, so events at equal times fall in one window and keep their order."""
    times = _event_times(prep)
    total = sum(t.size for t in times)
    if total == 0:
        return
    first = min(float(t[0]) for t in times if t.size)
    last = max(float(t[-1]) for t in times if t.size)
    windows = max(1, -(-total // events))
    cuts = np.linspace(first, last, windows + 1)[1:-1]
    edges = [np.concatenate([[0], np.searchsorted(t, cuts, side="left"), [t.size]]) for t in times]
    for w in range(windows):
        parts = [
            (kind, times[kind][e[w] : e[w + 1]], int(e[w]))
            for kind, e in enumerate(edges)
            if e[w + 1] > e[w]
        ]
        if parts:
            yield _ordered(parts)


def _columns(prep: PreparedDrive) -> dict[int, list[np.ndarray | None]]:
    d = prep.drive
    cols: dict[int, list[np.ndarray | None]] = {
        GPS: [prep.gps.t, prep.gps.x, prep.gps.y, prep.gps.accuracy],
        QUERY: [prep.now.t_query],
    }
    if d.imu is not None:
        cols[IMU] = [d.imu.t, d.imu.ax, d.imu.ay, d.imu.yaw, d.imu.yaw_rate]
    if d.speed is not None:
        cols[SPEED] = [d.speed.t, d.speed.v]
    return cols


def _window(cols: list[np.ndarray | None], sel: np.ndarray) -> tuple[int, list[list[float]]]:
    """(offset, Python-float lists) of the index range ``sel`` covers in each column."""
    if sel.size == 0:
        return 0, [[] for _ in cols]
    lo, hi = int(sel.min()), int(sel.max()) + 1
    return lo, [c[lo:hi].tolist() if c is not None else [float("nan")] * (hi - lo) for c in cols]


#: the largest ``sigma`` [m] a predictor is given: 1000 km. A fix stating more tells nothing
#: of where the vehicle is, as this does; the cap keeps sigma^2 and a filter's gain finite (an
#: accuracy of 1e300 m squares to inf, and the filter's covariance to NaN)
MAX_SIGMA_M = 1e6


def fix_sigma(accuracy_m: float) -> float | None:
    """A fix's stated accuracy [m] as ``observe_gps(..., sigma=)`` takes it: None where it is
    not finite and positive (the stream states none), at most :data:`MAX_SIGMA_M`."""
    return min(accuracy_m, MAX_SIGMA_M) if 0.0 < accuracy_m < math.inf else None


def replay(
    predictor: Predictor,
    prep: PreparedDrive,
    horizon_s: float,
    probe: tuple[int, Callable[[], None]] | None = None,
) -> ReplayResult:
    """Feed every event to ``predictor`` in order; collect its answers and timings.

    Events are ordered and handled in time windows of about :data:`CHUNK_EVENTS`
    (:func:`event_windows`), converting only that window's samples to Python floats (fast
    scalar access without holding a whole long drive's events or its Python objects).
    ``probe``: (fix index, call): the call is made right after that fix's future answer (and
    its covariance), off the clock, to look into the predictor's state then."""
    cols = _columns(prep)
    n_fix, n_now = len(prep.gps), prep.now.t_query.size
    future = np.full((n_fix, 2), np.nan)
    now = np.full((n_now, 2), np.nan)
    step_ns = np.zeros(n_fix, dtype=np.int64)
    query_ns = np.zeros(n_now, dtype=np.int64)
    clock = perf_counter_ns
    with_cov = reports_covariance(predictor)
    # covariance rows and call durations; written only with_cov (else empty, returned as None)
    n_cov = n_fix + n_now if with_cov else 0
    cov = np.full((n_cov, 3), np.nan)
    cov_ns = np.zeros(n_cov, dtype=np.int64)
    covariance_at = predictor.covariance_at
    observe_gps, observe_imu = predictor.observe_gps, predictor.observe_imu
    observe_speed, position_at = predictor.observe_speed, predictor.position_at
    with_sigma = accepts_sigma(observe_gps)
    predictor.reset()
    probe_at, probe_call = probe if probe is not None else (-1, None)
    for kc, ic in event_windows(prep, CHUNK_EVENTS):
        go, (gt, gx, gy, gs) = _window(cols[GPS], ic[kc == GPS])
        sigmas = [fix_sigma(a) for a in gs] if with_sigma else []
        qo, (qt,) = _window(cols[QUERY], ic[kc == QUERY])
        if IMU in cols:
            io, (it, iax, iay, iyaw, irate) = _window(cols[IMU], ic[kc == IMU])
        if SPEED in cols:
            so, (st, sv) = _window(cols[SPEED], ic[kc == SPEED])
        for k, i in zip(kc.tolist(), ic.tolist(), strict=True):
            if k == IMU:
                j = i - io
                observe_imu(it[j], iax[j], iay[j], iyaw[j], irate[j])
            elif k == GPS:
                j = i - go
                t = gt[j]
                c0 = clock()
                if with_sigma:
                    observe_gps(t, gx[j], gy[j], sigma=sigmas[j])
                else:
                    observe_gps(t, gx[j], gy[j])
                p = position_at(t + horizon_s)
                step_ns[i] = clock() - c0
                future[i] = p
                if with_cov:
                    c0 = clock()
                    answer_cov = covariance_at(t + horizon_s)
                    cov_ns[i] = clock() - c0
                    _store_cov(cov, i, answer_cov)
                if i == probe_at:
                    probe_call()  # type: ignore[misc]
            elif k == SPEED:
                j = i - so
                observe_speed(st[j], sv[j])
            else:
                j = i - qo
                c0 = clock()
                p = position_at(qt[j])
                query_ns[i] = clock() - c0
                now[i] = p
                if with_cov:
                    c0 = clock()
                    answer_cov = covariance_at(qt[j])
                    cov_ns[n_fix + i] = clock() - c0
                    _store_cov(cov, n_fix + i, answer_cov)
    if not with_cov:
        return ReplayResult(future, now, step_ns, query_ns)
    return ReplayResult(future, now, step_ns, query_ns, cov, cov_ns)


# ------------------------------------------------------------------- one event at a time
Event = tuple[int, float, tuple[float, ...]]


def events(prep: PreparedDrive) -> list[Event]:
    """The replay's events in the runner's order as ``(kind, t, args)``: observations carry
    their values, a fix is followed by its future query (asked by :func:`feed`), a "now"
    query has ``args = ()``; a fix's args are ``(x, y, sigma)`` (sigma [m] NaN when not stated)."""
    cols = _columns(prep)
    kinds, idxs = build_events(prep)
    out: list[Event] = []
    for k, i in zip(kinds.tolist(), idxs.tolist(), strict=True):
        vals = [float(c[i]) if c is not None else math.nan for c in cols[k]]
        out.append((k, vals[0], () if k == QUERY else tuple(vals[1:])))
    return out


def feed(
    pred: Predictor,
    evs: list[Event],
    horizon_s: float,
    start: int = 0,
    stop: int | None = None,
    after: Callable[[int], None] | None = None,
) -> list[tuple[float, float, float]]:
    """Feed ``evs[start:stop]`` to ``pred`` (no ``reset()``) as :func:`replay` does, each fix
    followed by its future query ``horizon_s`` [s] ahead; ``after(i)`` is called after event
    ``i``. Returns ``(t_query, x, y)`` per answer."""
    out = []
    with_sigma = accepts_sigma(pred.observe_gps)
    for i in range(start, len(evs) if stop is None else stop):
        k, t, a = evs[i]
        if k == GPS:
            if with_sigma:
                pred.observe_gps(t, a[0], a[1], sigma=fix_sigma(a[2]))
            else:
                pred.observe_gps(t, a[0], a[1])
            x, y = pred.position_at(t + horizon_s)
            out.append((t + horizon_s, float(x), float(y)))
        elif k == IMU:
            pred.observe_imu(t, *a)
        elif k == SPEED:
            pred.observe_speed(t, *a)
        else:
            x, y = pred.position_at(t)
            out.append((t, float(x), float(y)))
        if after is not None:
            after(i)
    return out
