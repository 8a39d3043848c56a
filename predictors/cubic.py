"""Third-order polynomial regression of signals against time (the paper's fit).

The paper fits ``p(t) = c0 + c1 t + c2 t^2 + c3 t^3`` iteratively (L-BFGS, ~2 ms).
It is a linear least-squares problem: here it is solved in closed form on
times shifted to a reference ``t_ref`` and divided by ``scale`` (conditioning),
``s = (t - t_ref) / scale``. :func:`fit_cubic_lbfgs` keeps the iterative fit for
comparison. Times in seconds; values in any unit (metres, m/s^2, rad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEGREE = 3


@dataclass(frozen=True)
class CubicFit:
    """Coefficients ``coef`` (4, k) for k channels in the scaled time s = (t - t_ref) / scale."""

    coef: np.ndarray
    t_ref: float
    scale: float

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        """Values at times t [s]: shape (len(t), k) (or (k,) for a scalar t)."""
        s = (np.asarray(t, dtype=float) - self.t_ref) / self.scale
        c = self.coef
        return ((c[3] * s[..., None] + c[2]) * s[..., None] + c[1]) * s[..., None] + c[0]

    def derivative(self, t: np.ndarray | float) -> np.ndarray:
        """First derivative with respect to t [unit/s] at times t."""
        s = (np.asarray(t, dtype=float) - self.t_ref) / self.scale
        c = self.coef
        return ((3 * c[3] * s[..., None] + 2 * c[2]) * s[..., None] + c[1]) / self.scale


def vandermonde(s: np.ndarray, degree: int = DEGREE) -> np.ndarray:
    """Columns 1, s, s^2, ... s^degree for scaled times s."""
    return np.vander(np.asarray(s, dtype=float), degree + 1, increasing=True)


def _prepare(
    t: np.ndarray, values: np.ndarray, t_ref: float | None, scale: float | None
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Times and values as float arrays ((n,), (n, k)) and the time origin / scale [s]
    (defaults: the first time; the span of t, or 1 s if it is zero)."""
    t = np.asarray(t, dtype=float)
    y = np.asarray(values, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    t_ref = float(t[0]) if t_ref is None else float(t_ref)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    scale = (span if span > 0 else 1.0) if scale is None else float(scale)
    return t, y, t_ref, scale


def fit_cubic(
    t: np.ndarray,
    values: np.ndarray,
    t_ref: float | None = None,
    scale: float | None = None,
    degree: int = DEGREE,
) -> CubicFit:
    """Closed-form least-squares polynomial fit.

    Args:
        t: sample times [s], shape (n,), n >= 1.
        values: shape (n,) or (n, k).
        t_ref: time origin of the scaled axis (default: the first time).
        scale: time scale [s] (default: the span of t, or 1 if zero).
        degree: polynomial degree, reduced to n - 1 when fewer points are given.
    """
    t, y, t_ref, scale = _prepare(t, values, t_ref, scale)
    deg = min(degree, t.size - 1)
    V = vandermonde((t - t_ref) / scale, deg)
    coef, *_ = np.linalg.lstsq(V, y, rcond=None)
    if deg < DEGREE:
        coef = np.vstack([coef, np.zeros((DEGREE - deg, y.shape[1]))])
    return CubicFit(coef, t_ref, scale)


def fit_cubic_lbfgs(
    t: np.ndarray, values: np.ndarray, t_ref: float | None = None, scale: float | None = None
) -> CubicFit:
    """The paper's iterative fit: minimise the squared residual with L-BFGS-B
    (analytic gradient), per channel. Slow (~ms); kept for latency comparison."""
    from scipy.optimize import minimize

    t, y, t_ref, scale = _prepare(t, values, t_ref, scale)
    V = vandermonde((t - t_ref) / scale)
    coefs = []
    for k in range(y.shape[1]):
        yk = y[:, k]

        def loss(c: np.ndarray, yk: np.ndarray = yk) -> tuple[float, np.ndarray]:
            r = V @ c - yk
            return float(r @ r), 2.0 * (V.T @ r)

        res = minimize(
            loss,
            np.zeros(DEGREE + 1),
            jac=True,
            method="L-BFGS-B",
            options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 500},
        )
        coefs.append(res.x)
    return CubicFit(np.stack(coefs, axis=1), t_ref, scale)
