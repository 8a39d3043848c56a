"""GPS dropouts: which fixes a simulated receiver loses, and the outage windows they leave.

Everything here is seeded and deterministic. Times are seconds from the drive's start.

Dropouts (:func:`apply_dropouts`, profiles listed in :data:`DROPOUT_PROFILES`)
    ``"none"``        keep every fix;
    ``"random:p"``    lose each fix independently with probability p (0 <= p < 1);
    ``"outages"``     outages of 0.5, 1, 2 and 5 s (:data:`OUTAGE_LENGTHS_S`), in random
                      order at seeded random non-overlapping times, each preceded and
                      followed by >= 10 s of normal reception (the first starts >= 10 s
                      into the stream); the set is repeated ``floor(T / (2 (sum L + 10 n)))``
                      times (at least once) on long streams of duration T; when turn times
                      are given, half of the outages (rounded up) are centred on a turn
                      time where one fits. Lengths that no longer fit are left out: the
                      returned outage list says which were placed;
    ``"outage:L"``    like ``"outages"`` with the single length L seconds;
    ``"outage-lengths"`` outages of the lengths the GNSS/INS field reports, 1, 2, 5, 10, 30
                      and 60 s (:data:`FIELD_OUTAGE_LENGTHS_S`), placed by
                      :func:`packed_outage_windows`: longest first, each length the
                      stream still has room for (the same >= 10 s of reception before each
                      outage, the last ending >= 1 s before the stream does), so a short
                      drive gets its short lengths and only a long drive a 60 s one; the
                      set is repeated on long streams as for ``"outages"``.
    Every fix stamped inside an outage window [a, a + L] is removed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from posbench.scenarios.drive import GpsStream
from posbench.scenarios.errors import DataError

DROPOUT_PROFILES = ("none", "random:p", "outages", "outage:L", "outage-lengths")
OUTAGE_LENGTHS_S = (0.5, 1.0, 2.0, 5.0)
#: the profile whose outages are the lengths the GNSS/INS field reports errors after
FIELD_OUTAGES = "outage-lengths"
#: its lengths [s] (error after 10, 30 and 60 s of GNSS outage is what IMU bridging reports)
FIELD_OUTAGE_LENGTHS_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0)
OUTAGE_SEPARATION_S = 10.0


def _free_intervals(lo: float, hi: float, forbidden: list[tuple[float, float]]) -> np.ndarray:
    """[lo, hi] minus the union of open ``forbidden`` intervals, as an (k, 2) array."""
    if hi < lo:
        return np.empty((0, 2))
    out = []
    cur = lo
    for a, b in sorted(forbidden):
        if b <= cur:
            continue
        if a > cur:
            out.append((cur, min(a, hi)))
        cur = max(cur, b)
        if cur >= hi:
            break
    if cur <= hi:
        out.append((cur, hi))
    arr = np.asarray([(a, b) for a, b in out if b >= a], dtype=float)
    return arr.reshape(-1, 2)


def _sample_in(free: np.ndarray, rng: np.random.Generator) -> float:
    """A uniform point in a union of closed intervals (length-weighted)."""
    w = free[:, 1] - free[:, 0]
    if w.sum() <= 0:
        return float(free[rng.integers(free.shape[0]), 0])
    k = int(np.searchsorted(np.cumsum(w), rng.random() * w.sum(), side="right"))
    k = min(k, free.shape[0] - 1)
    return float(free[k, 0] + rng.random() * w[k])


def outage_windows(
    t_start: float,
    t_end: float,
    lengths: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    t_turns: np.ndarray | None = None,
    min_sep_s: float = OUTAGE_SEPARATION_S,
    repeat: bool = True,
) -> np.ndarray:
    """Seeded non-overlapping outage windows, shape (k, 2) of [start, end] [s], sorted.

    Each window is preceded by >= ``min_sep_s`` of reception (from ``t_start`` or the
    previous window) and followed by >= ``min_sep_s`` before the next one, and ends
    >= 1 s before ``t_end``. With ``repeat`` the length set is repeated
    ``max(1, floor(T / (2 (sum(lengths) + min_sep_s n))))`` times. With ``t_turns``
    (times of turning, [s]) the first half (rounded up) of the shuffled outages are
    centred on a random turn time where that fits. Lengths that do not fit are skipped.
    """
    length_set = np.asarray(lengths, dtype=float)
    span = float(t_end) - float(t_start)
    reps = 1
    if repeat and length_set.size:
        reps = max(1, int(span // (2.0 * (length_set.sum() + min_sep_s * length_set.size))))
    todo = rng.permutation(np.tile(length_set, reps))
    n_turn = int(np.ceil(todo.size / 2)) if t_turns is not None and np.size(t_turns) else 0
    turns = np.sort(np.asarray(t_turns, dtype=float)) if n_turn else np.empty(0)
    placed: list[tuple[float, float]] = []
    for i, length in enumerate(todo):
        lo, hi = t_start + min_sep_s, t_end - 1.0 - length
        forbidden = [(a - min_sep_s - length, b + min_sep_s) for a, b in placed]
        free = _free_intervals(lo, hi, forbidden)
        if free.size == 0:
            continue
        start = None
        if i < n_turn:
            cand = turns - length / 2.0
            k = np.searchsorted(free[:, 0], cand, side="right") - 1
            ok = (k >= 0) & (cand <= free[np.maximum(k, 0), 1])
            if np.any(ok):
                start = float(rng.choice(cand[ok]))
        if start is None:
            start = _sample_in(free, rng)
        placed.append((start, start + float(length)))
    return np.asarray(sorted(placed), dtype=float).reshape(-1, 2)


def packed_outage_windows(
    t_start: float,
    t_end: float,
    lengths: Sequence[float] | np.ndarray,
    rng: np.random.Generator,
    min_sep_s: float = OUTAGE_SEPARATION_S,
    repeat: bool = True,
) -> np.ndarray:
    """Seeded non-overlapping outage windows of as many of ``lengths`` [s] as fit, shape
    (k, 2) of [start, end] [s], sorted.

    Each window is preceded by >= ``min_sep_s`` of reception (from ``t_start`` or the
    previous window) and the last ends >= 1 s before ``t_end``, as in
    :func:`outage_windows`. The lengths are taken longest first (a long outage fits fewer
    drives than a short one), each kept while the kept ones and their separations still
    fit into the span; with ``repeat`` the set is taken ``max(1, floor(T / (2 (sum(lengths)
    + min_sep_s n))))`` times (as :func:`outage_windows` repeats it). The kept windows are
    then shuffled and the spare time is spread over the gaps at random (uniform spacings),
    so that where a length falls along the drive does not depend on its length.
    """
    length_set = np.sort(np.asarray(lengths, dtype=float))[::-1]
    span = float(t_end) - float(t_start) - 1.0
    reps = 1
    if repeat and length_set.size:
        reps = max(1, int((span + 1.0) // (2.0 * (length_set.sum() + min_sep_s * length_set.size))))
    kept: list[float] = []
    used = 0.0
    for length in np.tile(length_set, reps):
        if used + min_sep_s + length <= span:
            kept.append(float(length))
            used += min_sep_s + length
    if not kept:
        return np.empty((0, 2))
    order = rng.permutation(len(kept))
    spare = span - used
    cuts = np.sort(rng.random(len(kept))) * spare  # spare time before each window, cumulative
    placed, t = [], float(t_start)
    prev_cut = 0.0
    for i, k in enumerate(order):
        t += min_sep_s + (cuts[i] - prev_cut)
        prev_cut = cuts[i]
        placed.append((t, t + kept[k]))
        t += kept[k]
    return np.asarray(placed, dtype=float).reshape(-1, 2)


def parse_dropouts(profile: str) -> tuple[str, float]:
    bad = DataError(
        None,
        f"unknown dropout profile {profile!r}; use 'none', 'random:p' "
        f"(0 <= p < 1), 'outages', 'outage:L' (L > 0 seconds) or '{FIELD_OUTAGES}'",
    )
    if profile in ("none", "outages", FIELD_OUTAGES):
        return profile, float("nan")
    for kind in ("random", "outage"):
        if profile.startswith(kind + ":"):
            try:
                val = float(profile[len(kind) + 1 :])
            except ValueError:
                raise bad from None
            if (kind == "random" and 0.0 <= val < 1.0) or (
                kind == "outage" and 0.0 < val and np.isfinite(val)
            ):
                return kind, val
            raise bad
    raise bad


def _outage_bounds(t_kept: np.ndarray, a: np.ndarray, b: np.ndarray) -> list[tuple[float, float]]:
    """(last kept fix before a, first kept fix after b - or b itself if none) per window."""
    if a.size == 0:
        return []
    n = t_kept.size
    i = np.searchsorted(t_kept, a, side="left") - 1
    j = np.searchsorted(t_kept, b, side="right")
    padded = np.concatenate([t_kept, [np.nan]])  # index n -> nan
    before = np.where(i >= 0, padded[np.where(i >= 0, i, n)], a)
    after = np.where(j < n, padded[np.minimum(j, n)], b)
    return [(float(p), float(q)) for p, q in zip(before, after, strict=True)]


def apply_dropouts(
    gps: GpsStream, profile: str, seed: int, t_turns: np.ndarray | None = None
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """Remove fixes by a dropout profile (see module doc).

    Returns:
        (thinned stream, outages) where each outage is (t of the last fix before it [s],
        t of the first fix after it [s], or the outage's end when no fix follows). For
        ``"random:p"`` an outage is each maximal run of lost fixes.
    """
    kind, val = parse_dropouts(profile)
    if kind == "none" or len(gps) == 0:
        return gps, []
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xD50]))
    t = gps.t
    if kind == "random":
        lost = rng.random(t.size) < val
        if not lost.any():
            return gps, []
        edges = np.diff(np.concatenate([[0], lost.astype(np.int8), [0]]))
        s, e = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        keep = ~lost
        out = [
            (
                float(t[i - 1]) if i > 0 else float(t[i]),
                float(t[j + 1]) if j + 1 < t.size else float(t[j]),
            )
            for i, j in zip(s, e, strict=True)
        ]
        return gps.take(keep), out
    if kind == FIELD_OUTAGES:
        win = packed_outage_windows(float(t[0]), float(t[-1]), FIELD_OUTAGE_LENGTHS_S, rng)
        return drop_windows(gps, win)
    lengths = OUTAGE_LENGTHS_S if kind == "outages" else (val,)
    win = outage_windows(float(t[0]), float(t[-1]), lengths, rng, t_turns)
    return drop_windows(gps, win)


def drop_windows(
    gps: GpsStream, windows: np.ndarray
) -> tuple[GpsStream, list[tuple[float, float]]]:
    """Remove fixes stamped inside closed windows [a, b] (k, 2); return stream and outages."""
    windows = np.asarray(windows, dtype=float).reshape(-1, 2)
    t = gps.t
    inside = np.zeros(t.size, dtype=bool)
    if windows.size:
        i0 = np.searchsorted(t, windows[:, 0], side="left")
        i1 = np.searchsorted(t, windows[:, 1], side="right")
        delta = np.zeros(t.size + 1, dtype=np.int64)
        np.add.at(delta, i0, 1)
        np.add.at(delta, i1, -1)
        inside = np.cumsum(delta[:-1]) > 0
    thin = gps.take(~inside)
    return thin, _outage_bounds(thin.t, windows[:, 0], windows[:, 1])
