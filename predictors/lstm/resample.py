"""Cubic resampling of irregular GPS fixes and IMU samples onto the paper's fixed grid.

The network sees ``N_STEPS = 8`` samples ``DT = 0.2`` s apart ending at the newest
fix (grid times ``t_end - 1.4, ..., t_end``). They come from a third-order least-squares
polynomial (the paper's regression, closed form here) fitted through the most recent
fixes that cover at least ``MIN_SPAN_S = 2`` s (about 10 fixes at 5 Hz); the IMU
channels are fitted with a cubic over the same time span and evaluated at the same times.

Times are seconds; every fit works on the shifted, scaled time
``s = (t - t_ref) / scale`` with ``t_ref`` the newest fix and ``scale`` the span, so the
normal equations stay well conditioned whatever the absolute time. Where the sample
times are fixed (the grid itself, the final 8-grid-points + prediction fit) the
pseudo-inverse is precomputed once (:class:`FixedGridFit`): a fit is then one small
matrix product (~2 us). The batched functions (``*_batch``) do the same for many
windows at once (training); the tests check they equal the single-window path.
"""

from __future__ import annotations

import numpy as np

N_STEPS = 8
DT = 0.2
MIN_SPAN_S = 2.0
DEGREE = 3
#: grid times relative to the newest fix [s]: -1.4, -1.2, ..., 0
GRID_OFFSETS = (np.arange(N_STEPS) - (N_STEPS - 1)) * DT
#: IMU accelerations with a magnitude above this [m/s^2] are sensor glitches (the aslan
#: routes hold rare values of several hundred m/s^2): they are left out of the fits.
ACCEL_GLITCH = 30.0


def powers(s: np.ndarray | float, degree: int = DEGREE) -> np.ndarray:
    """Vandermonde rows 1, s, ..., s^degree for scaled times s: shape s.shape + (degree+1,).

    Built by repeated products (``s ** arange`` costs ~10x more on the hot path).
    """
    s = np.asarray(s, dtype=float)
    if degree == 3 and s.ndim == 1:
        V = np.empty((s.size, 4))
        V[:, 0] = 1.0
        V[:, 1] = s
        s2 = s * s
        V[:, 2] = s2
        V[:, 3] = s2 * s
        return V
    V = np.empty(s.shape + (degree + 1,))
    V[..., 0] = 1.0
    if degree >= 1:
        V[..., 1] = s
    for k in range(2, degree + 1):
        np.multiply(V[..., k - 1], s, out=V[..., k])
    return V


try:  # the gufunc behind np.linalg.solve, without its ~30 us of Python-side checks
    from numpy.linalg import _umath_linalg

    def _solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            x = _umath_linalg.solve(a, b, signature="dd->d")
        if not np.isfinite(x).all():
            raise np.linalg.LinAlgError("singular normal equations")
        return x
except (ImportError, AttributeError):  # pragma: no cover - other NumPy layouts
    _solve = np.linalg.solve


def fit_poly(
    t: np.ndarray, values: np.ndarray, t_ref: float, scale: float, degree: int = DEGREE
) -> np.ndarray:
    """Closed-form least-squares polynomial through (t, values) in s = (t - t_ref) / scale.

    The normal equations come from one product ``V.T @ [V | values]`` (V the Vandermonde
    rows 1, s, .., s^degree), solved by LU; singular ones fall back to ``lstsq``.

    Args:
        t: sample times [s], shape (n,).
        values: shape (n, k).
        t_ref, scale: time origin [s] and scale [s] of the fit.
        degree: the degree; reduced to n - 1 when fewer points are given.
    Returns:
        coefficients (DEGREE + 1, k), lowest power first (zero-padded above the degree used).
    """
    n = t.shape[0]
    deg = min(degree, n - 1)
    out = np.zeros((DEGREE + 1, values.shape[1]))
    if deg < 0:
        return out
    m = deg + 1
    b = np.empty((n, m + values.shape[1]))
    b[:, 0] = 1.0
    if m > 1:
        s = b[:, 1]
        np.subtract(t, t_ref, out=s)
        s /= scale
        for j in range(2, m):
            np.multiply(b[:, j - 1], s, out=b[:, j])
    b[:, m:] = values
    g = b[:, :m].T @ b
    try:
        out[:m] = _solve(g[:, :m], g[:, m:])
    except np.linalg.LinAlgError:
        out[:m] = np.linalg.lstsq(b[:, :m], values, rcond=None)[0]
    return out


def eval_poly(coef: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Values of the polynomial(s) ``coef`` (DEGREE+1, k) at scaled times s: shape
    s.shape + (k,)."""
    return powers(s) @ coef


def deriv_poly(coef: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """First derivative d/ds of ``coef`` at scaled times s (divide by ``scale`` for per-second)."""
    s = np.asarray(s, dtype=float)[..., None]
    return (3.0 * coef[3] * s + 2.0 * coef[2]) * s + coef[1]


class FixedGridFit:
    """Least-squares cubic through samples at fixed times, with a precomputed pseudo-inverse.

    ``times`` [s] are relative to ``t_ref`` = 0 and divided by ``scale``. ``fit(Y)`` returns
    the coefficients (DEGREE+1, k) for values Y (n, k): one (4 x n) @ (n x k) product.
    """

    def __init__(self, times: np.ndarray, scale: float = 1.0, degree: int = DEGREE) -> None:
        self.times = np.asarray(times, dtype=float)
        self.scale = float(scale)
        V = powers(self.times / self.scale, degree)
        pinv = np.linalg.pinv(V)
        self.pinv = np.zeros((DEGREE + 1, self.times.size))
        self.pinv[: degree + 1] = pinv

    def fit(self, values: np.ndarray) -> np.ndarray:
        """Coefficients (DEGREE+1, k) in s = t / scale."""
        return self.pinv @ values


def window_start(t: np.ndarray, end: int, min_span: float = MIN_SPAN_S) -> int:
    """Index of the oldest fix of the shortest run ending at ``end`` that spans >= min_span [s].

    Returns 0 when the whole history is shorter (then the span is less than min_span).
    """
    j = int(np.searchsorted(t, t[end] - min_span, side="right")) - 1
    return max(j, 0)


def window_starts(t: np.ndarray, ends: np.ndarray, min_span: float = MIN_SPAN_S) -> np.ndarray:
    """Vectorised :func:`window_start` for many window ends."""
    j = np.searchsorted(t, t[ends] - min_span, side="right") - 1
    return np.maximum(j, 0)


def resample_positions(
    t: np.ndarray, xy: np.ndarray, start: int, end: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Cubic through fixes ``start..end`` (inclusive) evaluated on the grid ending at t[end].

    Returns (positions (8, 2) [m], coef (4, 2) in s = (t - t[end]) / scale, scale [s]).
    """
    tt = t[start : end + 1]
    t_end = float(t[end])
    span = t_end - float(tt[0])
    scale = span if span > 0 else 1.0
    coef = fit_poly(tt, xy[start : end + 1], t_end, scale)
    return eval_poly(coef, GRID_OFFSETS / scale), coef, scale


def resample_imu(t_imu: np.ndarray, vals: np.ndarray, t0: float, t_end: float) -> np.ndarray | None:
    """IMU channels (n, k) fitted with a cubic over [t0, t_end] and evaluated on the grid.

    Glitches (|ax| or |ay| > ACCEL_GLITCH, columns 0 and 1) are left out. Returns (8, k)
    or ``None`` when fewer than 4 good samples fall in the span.
    """
    i0 = int(np.searchsorted(t_imu, t0, side="left"))
    i1 = int(np.searchsorted(t_imu, t_end, side="right"))
    tt = t_imu[i0:i1]
    vv = vals[i0:i1]
    good = (np.abs(vv[:, 0]) <= ACCEL_GLITCH) & (np.abs(vv[:, 1]) <= ACCEL_GLITCH)
    if not good.all():
        tt, vv = tt[good], vv[good]
    if tt.size < DEGREE + 1:
        return None
    scale = max(t_end - t0, 1e-3)
    coef = fit_poly(tt, vv, t_end, scale)
    return eval_poly(coef, GRID_OFFSETS / scale)


# ----------------------------------------------------------------- batched (training) path


def fit_poly_batch(s: np.ndarray, values: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Masked least-squares cubics for many windows at once.

    Args:
        s: scaled times (B, M) (padding entries arbitrary but finite).
        values: (B, M, k).
        mask: (B, M) bool, True for real samples (each row needs >= 4).
    Returns:
        coefficients (B, DEGREE+1, k).
    """
    w = mask.astype(float)
    V = powers(np.where(mask, s, 0.0))  # (B, M, 4)
    Vw = V * w[..., None]
    G = np.einsum("bmi,bmj->bij", Vw, V)
    rhs = np.einsum("bmi,bmk->bik", Vw, np.where(mask[..., None], values, 0.0))
    return np.linalg.solve(G, rhs)


def eval_poly_batch(coef: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Evaluate (B, 4, k) coefficients at scaled times s (B, q): shape (B, q, k)."""
    s = s[..., None]
    c = coef[:, None]
    return ((c[..., 3, :] * s + c[..., 2, :]) * s + c[..., 1, :]) * s + c[..., 0, :]


def gather_windows(
    t: np.ndarray, vals: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pad the runs ``lo[b] .. hi[b]-1`` of (t, vals) into (B, M) arrays with a mask."""
    counts = hi - lo
    m = int(counts.max()) if counts.size else 0
    idx = lo[:, None] + np.arange(max(m, 1))[None, :]
    mask = idx < hi[:, None]
    idx = np.minimum(idx, t.size - 1)
    return t[idx], vals[idx], mask


def resample_positions_batch(
    t: np.ndarray,
    xy: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    extra_offsets: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched :func:`resample_positions`: positions (B, 8 [+extra], 2), coef (B, 4, 2), scale (B,).

    ``extra_offsets`` [s, relative to each window's newest fix] are evaluated after the grid
    (e.g. +0.2 for the plain cubic extrapolation baseline).
    """
    t_end = t[ends]
    span = t_end - t[starts]
    scale = np.where(span > 0, span, 1.0)
    tw, vw, mask = gather_windows(t, xy, starts, ends + 1)
    s = (tw - t_end[:, None]) / scale[:, None]
    coef = fit_poly_batch(s, vw, mask)
    offs = GRID_OFFSETS if extra_offsets is None else np.concatenate([GRID_OFFSETS, extra_offsets])
    pos = eval_poly_batch(coef, offs[None, :] / scale[:, None])
    return pos, coef, scale


def resample_imu_batch(
    t_imu: np.ndarray, vals: np.ndarray, t0: np.ndarray, t_end: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Batched :func:`resample_imu`: (B, 8, k) values and a (B,) validity flag."""
    good = (np.abs(vals[:, 0]) <= ACCEL_GLITCH) & (np.abs(vals[:, 1]) <= ACCEL_GLITCH)
    tg, vg = t_imu[good], vals[good]
    lo = np.searchsorted(tg, t0, side="left")
    hi = np.searchsorted(tg, t_end, side="right")
    ok = (hi - lo) >= DEGREE + 1
    out = np.zeros((t0.size, N_STEPS, vals.shape[1]))
    if not ok.any() or tg.size == 0:
        return out, ok
    scale = np.maximum(t_end - t0, 1e-3)
    tw, vw, mask = gather_windows(tg, vg, lo[ok], hi[ok])
    s = (tw - t_end[ok, None]) / scale[ok, None]
    coef = fit_poly_batch(s, vw, mask)
    out[ok] = eval_poly_batch(coef, GRID_OFFSETS[None, :] / scale[ok, None])
    return out, ok


def centred_cubic_batch(
    t: np.ndarray, xy: np.ndarray, tq: np.ndarray, half: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's reference ("truth by cubic"): a cubic through the real fixes within
    +-``half`` s of each query time (past AND future), evaluated there.

    Returns positions (Q, 2) [m] and a validity flag (needs >= 2 fixes on each side).
    """
    lo = np.searchsorted(t, tq - half, side="left")
    hi = np.searchsorted(t, tq + half, side="right")
    mid = np.searchsorted(t, tq, side="left")
    ok = ((mid - lo) >= 2) & ((hi - mid) >= 2) & ((hi - lo) >= DEGREE + 1)
    out = np.full((tq.size, 2), np.nan)
    if not ok.any():
        return out, ok
    tw, vw, mask = gather_windows(t, xy, lo[ok], hi[ok])
    s = (tw - tq[ok, None]) / half
    coef = fit_poly_batch(s, vw, mask)
    out[ok] = coef[:, 0, :]
    return out, ok
