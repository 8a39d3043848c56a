"""How much of its network's correction the ``hybrid`` applies (numpy only, no torch).

A learned residual on top of a good filter must never cost accuracy where it has not
shown that it helps. Three factors, multiplied (each in [0, 1]):

1. **Shrinkage per horizon** (:func:`fit_shrink`), fitted once at training time on the
   *validation* rows (held-out development drives, never the rows the network was
   trained on): the least-squares factor ``a_h`` that scales the correction at horizon
   ``h``, clipped to [0, 1]. A network that over-corrects on held-out drives is scaled
   back; one whose correction does not help there is switched off.
2. **The input envelope** (:func:`input_envelope`, :func:`inside_envelope`, which the hybrid's
   step kernel calls): the box of
   the training inputs (each feature's and each prior entry's min and max over all
   training rows, raw units), widened by :data:`BOX_MARGIN` of its width on each side
   (windows at run time are not exactly the training rows: every fix, online features).
   A window outside it is data unlike the training data: the step answers as the prior
   alone.
3. **The drive's own evidence** (:class:`EvidenceGate`): at each real fix, before the
   prior takes it, the correction's effect on the prediction of that fix is one paired
   sample ``d = |z - p|^2 - |z - (p + c)|^2 = 2 (z - p) . c - |c|^2`` [m^2], with ``z``
   the fix, ``p`` the prior's prediction and ``c`` the correction (after factors 1 and 2)
   for the fix time. Where the fix noise is independent of both predictions,
   ``E[d] = |x - p|^2 - |x - p - c|^2`` for the true position ``x``: the noise cancels in
   expectation, so ``d`` is an unbiased sample of the correction's gain. The weight is
   ``clip((t - T_START) / (T_FULL - T_START), 0, 1)`` with ``t`` the exponentially
   weighted mean of ``d`` over :data:`MEMORY_FIXES` fixes divided by its standard error,
   the samples counted as ``n (1 - rho) / (1 + rho)`` for their lag-1 autocorrelation
   ``rho`` (an AR(1) correction; a receiver's slowly wandering error makes neighbouring
   samples alike); 0 until :data:`MIN_FIXES` samples exist.
   The start is at t = 1, not 0, because a receiver's error is correlated from fix to
   fix, so the samples are too, and the standard error is then too small: a correction
   that does nothing must not pass on noise, and the AR(1) correction sees only part of
   that. (Chosen on development drives, before the AR(1) correction: with the weight
   starting at t = 0, synthetic consumer-grade drives lost 4 mm; starting at t = 2, the
   paper's held-out routes kept 1.3 of their 10 mm gain; at t = 1, 0.1 mm and 7 mm.)
   Where the reference is an independent truth and the receiver's error is slow, the
   fixes cannot tell whether following them helps: the evidence is about predicting the
   fixes. So the correction is applied only as far as it has
   earned it on this drive: it starts at 0 and falls back to 0 where its fix
   predictions stop beating the prior's. Noisy fixes give weak evidence, so under a
   metre-level receiver the hybrid stays close to its prior unless its gain is large.
"""

from __future__ import annotations

import math

import numpy as np

from posbench.predictors._kernels import kernel

#: the envelope is widened by this fraction of its width on each side
BOX_MARGIN = 0.1
#: memory of the evidence [fixes] (exponential weights 1 - 1/MEMORY_FIXES)
MEMORY_FIXES = 30.0
#: samples of evidence needed before any correction is applied
MIN_FIXES = 5.0
#: the t statistic of the evidence above which the correction starts to be applied
T_START = 1.0
#: the t statistic of the evidence at which the correction is applied in full
T_FULL = 2.0


def fit_shrink(correction: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Least-squares factor per horizon, clipped to [0, 1]: ``a_h`` minimising
    ``sum |target - a_h correction|^2`` over rows and both axes.

    Args:
        correction: (B, H, 2) the network's corrections [m, heading frame].
        target: (B, H, 2) the residuals they should have been [m, heading frame].

    Returns:
        (H,) factors; 0 for a horizon whose corrections are all 0.
    """
    c = np.asarray(correction, dtype=float)
    r = np.asarray(target, dtype=float)
    num = (c * r).sum(axis=(0, 2))
    den = (c * c).sum(axis=(0, 2))
    a = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return np.clip(a, 0.0, 1.0)


def input_envelope(features: np.ndarray, prior: np.ndarray) -> dict[str, list]:
    """The box of the training inputs, raw units, for model.json's ``gate``.

    Args:
        features: (B, 8, F) the network's feature windows.
        prior: (B, H, 2) the prior inputs [m, heading frame].

    Returns:
        ``feature_min`` / ``feature_max`` (F,) over rows and steps, ``prior_min`` /
        ``prior_max`` (H, 2) over rows.
    """
    f = np.asarray(features, dtype=float).reshape(-1, np.shape(features)[-1])
    p = np.asarray(prior, dtype=float)
    return {
        "feature_min": f.min(axis=0).tolist(),
        "feature_max": f.max(axis=0).tolist(),
        "prior_min": p.min(axis=0).tolist(),
        "prior_max": p.max(axis=0).tolist(),
    }


def envelope_arrays(env: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """model.json's envelope as float32 arrays (the network inputs' dtype): feature min,
    max; prior min, max, each widened by :data:`BOX_MARGIN` of the width."""
    fmin, fmax, pmin, pmax = (
        np.asarray(env[k], dtype=float)
        for k in ("feature_min", "feature_max", "prior_min", "prior_max")
    )
    fw, pw = BOX_MARGIN * (fmax - fmin), BOX_MARGIN * (pmax - pmin)
    f32 = np.float32
    return (
        (fmin - fw).astype(f32),
        (fmax + fw).astype(f32),
        (pmin - pw).astype(f32),
        (pmax + pw).astype(f32),
    )


@kernel
def inside_envelope(
    f: np.ndarray,
    p: np.ndarray,
    fmin: np.ndarray,
    fmax: np.ndarray,
    pmin: np.ndarray,
    pmax: np.ndarray,
) -> bool:
    """Whether one window (features ``f`` (8, F), prior ``p`` (H, 2), raw units, float32)
    lies inside the box (:func:`envelope_arrays`); NaN counts as outside. Compiled: the
    hybrid's step kernel (:mod:`posbench.predictors.hybrid.step_kernel`) calls it."""
    for i in range(f.shape[0]):
        for j in range(f.shape[1]):
            v = f[i, j]
            if not (v >= fmin[j] and v <= fmax[j]):
                return False
    for i in range(p.shape[0]):
        for j in range(p.shape[1]):
            v = p[i, j]
            if not (v >= pmin[i, j] and v <= pmax[i, j]):
                return False
    return True


class EvidenceGate:
    """The drive's own evidence that the correction helps (module doc, factor 3)."""

    __slots__ = (
        "decay",
        "min_fixes",
        "t_start",
        "t_full",
        "s1",
        "s2",
        "s12",
        "w1",
        "w2",
        "last",
        "weight",
    )

    def __init__(
        self,
        memory_fixes: float = MEMORY_FIXES,
        min_fixes: float = MIN_FIXES,
        t_start: float = T_START,
        t_full: float = T_FULL,
    ) -> None:
        self.decay = 1.0 - 1.0 / memory_fixes
        self.min_fixes = min_fixes
        self.t_start = t_start
        self.t_full = t_full
        self.reset()

    def reset(self) -> None:
        """No evidence: weight 0."""
        self.s1 = self.s2 = self.s12 = self.w1 = self.w2 = 0.0
        self.last = math.nan  # the previous sample (for the lag-1 autocorrelation)
        #: the factor applied to the correction now, in [0, 1]
        self.weight = 0.0

    def observe(self, ex: float, ey: float, cx: float, cy: float) -> None:
        """One fix: ``(ex, ey)`` = fix minus the prior's prediction of it, ``(cx, cy)`` = the
        correction for the fix time [m, ENU]. A zero correction is no evidence."""
        if cx == 0.0 and cy == 0.0:
            return
        d = 2.0 * (ex * cx + ey * cy) - (cx * cx + cy * cy)
        if not math.isfinite(d):
            return
        k = self.decay
        self.s1 = k * self.s1 + d
        self.s2 = k * self.s2 + d * d
        if self.last == self.last:
            self.s12 = k * self.s12 + d * self.last
        self.last = d
        self.w1 = k * self.w1 + 1.0
        self.w2 = k * k * self.w2 + 1.0
        self.weight = self._weight()

    def _weight(self) -> float:
        w1 = self.w1
        if w1 < self.min_fixes:
            return 0.0
        mean = self.s1 / w1
        if mean <= 0.0:
            return 0.0
        var = max(self.s2 / w1 - mean * mean, 0.0)
        n_eff = w1 * w1 / self.w2
        if var > 0.0:  # samples correlated from fix to fix count as fewer (AR(1))
            rho = min(max((self.s12 / w1 - mean * mean) / var, 0.0), 0.99)
            n_eff *= (1.0 - rho) / (1.0 + rho)
        se = math.sqrt(var / n_eff)
        if se == 0.0:
            return 1.0
        t = mean / se
        return min(max((t - self.t_start) / (self.t_full - self.t_start), 0.0), 1.0)
