"""A receiver's error in two parts: white (fix to fix) and slow.

A GNSS receiver's stated accuracy is its *absolute* error, and most of it is slow:
multipath, the atmosphere and the receiver's own solution filter wander over seconds to
minutes, while from one fix to the next the track is far smoother than the stated sigma.
A filter that weighs each fix by the stated sigma as if it were white noise smooths a
track that needs no smoothing and lags behind it (docs: DESIGN-NOTES, "A receiver's
error is mostly slow").

The model here, per axis (ENU, m^2):

- **total** ``T``: what the fix states, ``(gps_sigma_scale * sigma)^2``; for a fix that
  states nothing, the white part alone (estimated, or ``gps_sigma^2``): nothing is known
  of its slow part, and the fixes themselves cannot show it.
- **white** ``W``: estimated from the fixes alone by
  :class:`~posbench.predictors.kalman.fix_noise.FixNoise` (each fix against the quadratic
  through the three before it; a filter's innovations would feed its own lag back). A
  receiver whose estimate ``E`` stays near its statement is white: ``W = T``. Where the
  fixes are much smoother than stated, ``W = E``. In between the weight moves linearly:
  ``W = T`` for ``E >= 0.3 T``, ``W = E`` for ``E <= 0.1 T``, linear between
  (continuous). Before :data:`SPLIT_WARMUP` fix samples the statement is taken as white.
  The margins keep a white receiver white: each sample is its variance times an
  exponential variate, so the mean of 20 falls below 0.3 of its true value with odds of
  ~1e-6, and the estimate with 30 fixes of memory (~60 samples' worth) far less.
- **slow** ``S = T - W``: the rest of the statement. A filter weighs fixes by ``W``, so it
  follows the receiver's track without lag, and carries ``S`` as a *consider* term: its
  reported position covariance is its own plus ``S I2``, since its answers share the
  receiver's slow error, which no fix can reveal. Over the 0.2-5 s a predictor answers
  for, a slow error of correlation time tau >> 5 s keeps its stationary variance, so no
  correlation time enters (it would, were the slow error a state to predict; without an
  independent truth there is nothing to estimate it from).

A receiver whose error is white (simulated ``rtk``; ``consumer``, which states only its
white part) comes out as before: ``W = T``, ``S = 0``.
"""

from __future__ import annotations

import copy

from posbench.predictors.kalman.copying import copy_attrs
from posbench.predictors.kalman.fix_noise import FixNoise

#: estimate / stated total at and above which a receiver counts as white (W = T)
WHITE_RATIO = 0.3
#: estimate / stated total at and below which the estimate is the white part (W = E)
SMOOTH_RATIO = 0.1
#: fix samples of the white estimate before a statement is split
SPLIT_WARMUP = 20
#: the range a stated per-axis accuracy [m] is taken within (:meth:`GnssNoise.parts`)
MIN_STATED_SIGMA_M = 1e-4
MAX_STATED_SIGMA_M = 1e6


def white_share(ratio: float) -> float:
    """W / T for an estimate of ``ratio`` x the stated total (module docstring): 1 at and
    above :data:`WHITE_RATIO`, ``ratio`` at and below :data:`SMOOTH_RATIO`, linear between."""
    if ratio >= WHITE_RATIO:
        return 1.0
    if ratio <= SMOOTH_RATIO:
        return ratio
    slope = (1.0 - SMOOTH_RATIO) / (WHITE_RATIO - SMOOTH_RATIO)
    return SMOOTH_RATIO + slope * (ratio - SMOOTH_RATIO)


class GnssNoise:
    """The white and slow parts of a receiver's fix error (module docstring).

    Args:
        gps_sigma: fix noise [m] per axis assumed for fixes that state none (until the
            estimator has warmed up, or always when ``memory`` is 0).
        gps_sigma_scale: a fix stating ``sigma`` [m] states a total of
            ``(gps_sigma_scale * sigma)^2`` per axis.
        memory: > 0: estimate the white part from the fixes
            (:class:`~posbench.predictors.kalman.fix_noise.FixNoise`, this many fixes of memory);
            0: no estimate (a fix's total is all white, an unstated fix ``gps_sigma^2``).
        split: split a stated total into white and slow parts (needs ``memory`` > 0);
            False: a stated total is all white (weighed as stated).
    """

    def __init__(
        self, gps_sigma: float, gps_sigma_scale: float, memory: float, split: bool = True
    ) -> None:
        self.default_var = float(gps_sigma) ** 2
        self.scale = float(gps_sigma_scale)
        self.estimator = FixNoise(self.default_var, float(memory)) if memory > 0.0 else None
        self.split_stated = bool(split) and self.estimator is not None
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = ("default_var", "scale", "estimator", "split_stated", "slow_var")

    def __deepcopy__(self, memo: dict) -> GnssNoise:
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new.estimator = copy.deepcopy(self.estimator, memo)
        return new

    def reset(self) -> None:
        if self.estimator is not None:
            self.estimator.reset()
        #: the slow part [m^2] per axis of the newest fix (0 before any)
        self.slow_var = 0.0

    def observe(self, t: float, x: float, y: float) -> None:
        """A finite fix at t [s], (x, y) [m] (ENU), before :meth:`white_var` is asked."""
        if self.estimator is not None:
            self.estimator.observe(t, x, y)

    @property
    def estimate(self) -> float:
        """The white variance [m^2] the fixes show so far (``gps_sigma^2`` before warm-up
        or without an estimator)."""
        est = self.estimator
        return self.default_var if est is None else est.var

    def parts(self, sigma: float | None) -> tuple[float, float]:
        """(white, slow) variance [m^2] per axis of a fix stating per-axis 1-sigma
        ``sigma`` [m] (None, not finite or <= 0: states none). A statement is taken within
        [:data:`MIN_STATED_SIGMA_M`, :data:`MAX_STATED_SIGMA_M`]: a receiver cannot know its
        position better than a tenth of a millimetre, and a fix stating more than a thousand
        kilometres weighs nothing either way (no square underflows or overflows)."""
        if sigma is None or not 0.0 < sigma < float("inf"):
            return self.estimate, 0.0
        s = self.scale * min(max(sigma, MIN_STATED_SIGMA_M), MAX_STATED_SIGMA_M)
        total = s * s
        est = self.estimator
        if not self.split_stated or est is None or est.samples < SPLIT_WARMUP:
            return total, 0.0
        white = total * white_share(est.var / total)
        return white, total - white

    def weigh(self, sigma: float | None) -> float:
        """The white variance [m^2] a fix stating ``sigma`` is weighed with; remembers its
        slow part as :attr:`slow_var`."""
        white, self.slow_var = self.parts(sigma)
        return white
