"""A bank of filters that lets the data choose: multiple-model adaptive estimation.

Every member (a :class:`~posbench.predictors.base.Predictor` reporting a covariance) is
fed every observation. At each fix, before the members see it, each member's answer
for the fix's time is scored by the robust log-likelihood of the fix under the member's
own prediction: ``-(rho(d) + log det S) / 2`` with innovation ``nu = z - p``, ``S = P + R``
(P the member's 2x2 position covariance at that time, R its variance for this fix),
``d = sqrt(nu' S^-1 nu)`` and Huber's ``rho(d) = d^2`` up to ``d = huber_k``, then
``2 k d - k^2`` (linear: a far outlier counts less than under a Gaussian, yet a member
that claimed to be sure and missed by far still loses more than one that claimed
little). Scores are summed with an exponential memory of
``memory_fixes`` fixes; answers come from the member with the best score.

Why: a filter's noise settings and its choice of inputs can only be right for some
data. A member that over-trusts an input (a biased or tilted raw IMU, a wheel speed with
a scale error) or assumes the wrong dynamics (motorway smoothness, city manoeuvres)
predicts fixes worse than it claims and loses the likelihood, so the inputs that do
not help on a drive are weighed down from the drive's own innovations, not from a
setting tuned elsewhere. The likelihood charges both for errors and for the spread
a member claims, so an overconfident member cannot win by claiming little; the Huber
tail keeps one multipath fix from deciding alone, and lets a jump of the source (where
every member misses) favour the members that allowed for it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from posbench.predictors._geometry import check_config
from posbench.predictors.base import Predictor

NAN2 = (math.nan, math.nan)


class ModelBank(Predictor):
    """Members run side by side; answers from the one whose predictions of the fixes
    have the highest recent likelihood (module docstring).

    Args:
        members: predictors with ``covariance_at`` (their own ``cov_scale`` 1), a
            ``fix_variance(sigma)`` (R per axis [m^2] of a fix stating sigma) and a
            ``fix_innovation`` attribute: ``(nu_x, nu_y, S_xx, S_xy, S_yy)`` of the newest
            fix before its update, set in ``observe_gps`` (None when it has none), which
            scores it without a second prediction.
        labels: one short name per member (for ``selected`` and reports).
        memory_fixes: exponential memory of the scores, in fixes.
        huber_k: Mahalanobis distance where the score turns from quadratic to linear.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's covariance.
    """

    name = "bank"

    def __init__(
        self,
        members: Sequence[Predictor],
        labels: Sequence[str],
        memory_fixes: float = 20.0,
        huber_k: float = 3.0,
        cov_scale: float = 1.0,
    ) -> None:
        check_config(
            "bank",
            memory_fixes=(memory_fixes, 1.0, 1e6),
            huber_k=(huber_k, 0.1, 1e3),
            cov_scale=(cov_scale, 1e-6, 1e6),
        )
        if not members or len(members) != len(labels):
            raise ValueError("ModelBank needs members and one label each")
        self.members = list(members)
        self.labels = tuple(labels)
        self.memory_fixes = float(memory_fixes)
        self.huber_k = float(huber_k)
        self.cov_scale = float(cov_scale)
        self._keep = 1.0 - 1.0 / self.memory_fixes
        self.reset()

    def reset(self) -> None:
        for m in self.members:
            m.reset()
        self.scores = [0.0] * len(self.members)
        self.best = 0

    @property
    def selected(self) -> str:
        """Label of the member answering now."""
        return self.labels[self.best]

    def _log_likelihood(self, innov: tuple[float, float, float, float, float] | None) -> float:
        if innov is None:
            return math.nan
        ex, ey, a, b, d = innov
        det = a * d - b * b
        if not det > 0.0:
            return math.nan
        nis = (d * ex * ex - 2.0 * b * ex * ey + a * ey * ey) / det
        k = self.huber_k
        rho = nis if nis <= k * k else 2.0 * k * math.sqrt(nis) - k * k
        return -0.5 * (rho + math.log(det))

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        for m in self.members:
            m.observe_gps(t, x, y, sigma)
        ll = [self._log_likelihood(m.fix_innovation) for m in self.members]  # type: ignore[attr-defined]
        if all(v == v for v in ll):  # every member scored this fix (a non-finite one: none)
            k = self._keep
            self.scores = [k * s + v for s, v in zip(self.scores, ll, strict=True)]
            self.best = int(np.argmax(self.scores))

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        for m in self.members:
            m.observe_imu(t, ax, ay, yaw, yaw_rate)

    def observe_speed(self, t: float, v: float) -> None:
        for m in self.members:
            m.observe_speed(t, v)

    def position_at(self, t: float) -> tuple[float, float]:
        return self.members[self.best].position_at(t)

    def covariance_at(self, t: float) -> np.ndarray | None:
        P = self.members[self.best].covariance_at(t)
        return None if P is None else self.cov_scale * P

    def fix_variance(self, sigma: float | None) -> float:
        """R per axis [m^2] of a fix stating ``sigma``, as the selected member weighs it."""
        return self.members[self.best].fix_variance(sigma)  # type: ignore[attr-defined]
