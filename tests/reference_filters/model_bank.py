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

Horizons. One fix ahead is not what an outage asks: a member that predicts the next fix
best (a fixes-only filter following a receiver closely) need not be the one that
bridges seconds without fixes (an IMU-aided one). So each horizon ``h`` of
``horizons_s`` is scored by *shadows*: at a fix, a copy of every member is taken and fed
the IMU and wheel speed but no fix, exactly as the member would be in an outage; at the
first fix at least ``h`` later, each copy's answer is scored by its distance to that fix
[m] (summed with an exponential memory of ``horizon_memory`` windows). After the longest
horizon the copies are dropped and new ones start at that fix (copied at the next
observation, before the members take it: the same state, off the fix's step). A query
more than ``h`` after the newest fix (the largest such ``h``) is answered by the member
whose shadows did best at ``h``; a query nearer the fix by the likelihood's choice above.
The shadows cost about one more run of the aided members on the IMU and speed (the
copies themselves 55-75 us per window, :mod:`~posbench.predictors.kalman.copying`).
The distance, not a likelihood, scores a horizon because there the question is only
which member's answer lands nearer: the fix's noise is the same for every member.

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

import copy
import math
from collections.abc import Sequence

import numpy as np

from posbench.predictors._geometry import COV_SCALE_RANGE, check_config
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
        horizons_s: the horizons [s] members are also scored at (module docstring);
            empty: one fix ahead only.
        horizon_memory: exponential memory of the horizon scores, in scored windows.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's own
            covariance (:meth:`covariance_at`).
    """

    name = "bank"

    def __init__(
        self,
        members: Sequence[Predictor],
        labels: Sequence[str],
        memory_fixes: float = 20.0,
        huber_k: float = 3.0,
        cov_scale: float = 1.0,
        horizons_s: Sequence[float] = (),
        horizon_memory: float = 10.0,
    ) -> None:
        check_config(
            "bank",
            memory_fixes=(memory_fixes, 1.0, 1e6),
            huber_k=(huber_k, 0.1, 1e3),
            cov_scale=(cov_scale, *COV_SCALE_RANGE),
            horizon_memory=(horizon_memory, 1.0, 1e6),
            **{f"horizons_s[{i}]": (h, 1e-3, 3600.0) for i, h in enumerate(horizons_s)},
        )
        if not members or len(members) != len(labels):
            raise ValueError("ModelBank needs members and one label each")
        self.members = list(members)
        self.labels = tuple(labels)
        self.memory_fixes = float(memory_fixes)
        self.huber_k = float(huber_k)
        self.cov_scale = float(cov_scale)
        self._keep = 1.0 - 1.0 / self.memory_fixes
        self.horizons_s = tuple(sorted(float(h) for h in horizons_s))
        self.horizon_memory = float(horizon_memory)
        self._keep_h = 1.0 - 1.0 / self.horizon_memory
        self.reset()

    def reset(self) -> None:
        for m in self.members:
            m.reset()
        self.scores = [0.0] * len(self.members)
        self.best = 0
        n = len(self.members)
        #: per horizon: summed distances [m] of each member's shadows (lower is better)
        self.horizon_scores = [[0.0] * n for _ in self.horizons_s]
        #: per horizon: the member answering queries at least that far after a fix
        self.horizon_best = [0] * len(self.horizons_s)
        self._horizon_seen = [False] * len(self.horizons_s)
        #: the running shadows: (time [s] of the fix they started at, copies of the
        #: members) or None; ``_next_h``: index of the next horizon they are scored at
        self._shadow: tuple[float, list[Predictor]] | None = None
        self._next_h = 0
        #: time [s] of the fix new shadows start at, copied at the next observation
        #: (NaN: none pending)
        self._shadow_due = math.nan
        self._t_fix = math.nan  # time [s] of the newest fix

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

    def _score_shadows(self, t: float, x: float, y: float) -> None:
        """Score the running shadows at every horizon they have now run, by the fix
        (t, x, y); drop them after the longest."""
        shadow = self._shadow
        if shadow is None:
            return
        t0, copies = shadow
        hs = self.horizons_s
        if t - t0 < hs[self._next_h]:
            return
        dist = []
        for m in copies:
            px, py = m.position_at(t)
            dist.append(math.hypot(x - px, y - py))
        scored = all(d < math.inf for d in dist)  # every copy answered (no NaN)
        k = self._keep_h
        while self._next_h < len(hs) and t - t0 >= hs[self._next_h]:
            i = self._next_h
            if scored:
                sc = [k * s + d for s, d in zip(self.horizon_scores[i], dist, strict=True)]
                self.horizon_scores[i] = sc
                self.horizon_best[i] = int(np.argmin(sc))
                self._horizon_seen[i] = True
            self._next_h += 1
        if self._next_h == len(hs):
            self._shadow = None

    def _start_shadows(self) -> None:
        """Copy the members into new shadows, due since the fix at ``_shadow_due``. Done
        at the first observation after that fix, before the members take it: their state
        is still the one they had right after the fix (a copy taken then and fed this
        observation is the same), and the copy is not charged to the fix's step."""
        # the copies share among themselves what the members share
        self._shadow = (self._shadow_due, copy.deepcopy(self.members))
        self._next_h = 0
        self._shadow_due = math.nan

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        if self._shadow_due == self._shadow_due:
            self._start_shadows()
        finite = math.isfinite(x) and math.isfinite(y)
        if self.horizons_s and finite:
            self._score_shadows(t, x, y)
        for m in self.members:
            m.observe_gps(t, x, y, sigma)
        if finite:
            self._t_fix = t
            if self.horizons_s and self._shadow is None:
                self._shadow_due = t
        ll = [self._log_likelihood(m.fix_innovation) for m in self.members]  # type: ignore[attr-defined]
        if all(v == v for v in ll):  # every member scored this fix (a non-finite one: none)
            k = self._keep
            self.scores = [k * s + v for s, v in zip(self.scores, ll, strict=True)]
            self.best = int(np.argmax(self.scores))

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        if self._shadow_due == self._shadow_due:
            self._start_shadows()
        for m in self.members:
            m.observe_imu(t, ax, ay, yaw, yaw_rate)
        if self._shadow is not None:
            for m in self._shadow[1]:
                m.observe_imu(t, ax, ay, yaw, yaw_rate)

    def observe_speed(self, t: float, v: float) -> None:
        if self._shadow_due == self._shadow_due:
            self._start_shadows()
        for m in self.members:
            m.observe_speed(t, v)
        if self._shadow is not None:
            for m in self._shadow[1]:
                m.observe_speed(t, v)

    def answering(self, t: float) -> int:
        """Index of the member that answers a query at t [s]: the horizon choice of the
        largest horizon at most ``t`` - (newest fix) that has been scored, else the
        one-fix-ahead choice (module docstring)."""
        gap = t - self._t_fix
        for i in range(len(self.horizons_s) - 1, -1, -1):
            if gap >= self.horizons_s[i] and self._horizon_seen[i]:
                return self.horizon_best[i]
        return self.best

    def position_at(self, t: float) -> tuple[float, float]:
        return self.members[self.answering(t)].position_at(t)

    def covariance_at(self, t: float) -> np.ndarray | None:
        """The selected member's ``covariance_at(t)`` [m^2, ENU], its own part times
        ``cov_scale``; the slow part of the receiver's error it adds (its ``slow_variance``
        [m^2], where it has one) is the receiver's statement, not the filter's, and is not
        scaled."""
        member = self.members[self.answering(t)]
        P = member.covariance_at(t)
        if P is None:
            return None
        k = self.cov_scale
        slow = (1.0 - k) * getattr(member, "slow_variance", 0.0)
        out = k * P
        out[0, 0] += slow
        out[1, 1] += slow
        return out

    def fix_variance(self, sigma: float | None) -> float:
        """R per axis [m^2] of a fix stating ``sigma``, as the selected member weighs it."""
        return self.members[self.best].fix_variance(sigma)  # type: ignore[attr-defined]
