"""A filter bank whose members are rows of one array: the selection around the kernels.

The ``kf`` and ``ekf`` banks run their members (and the members' shadows) as rows stepped by
compiled kernels (:mod:`~posbench.predictors.kalman.ca_rows`,
:mod:`~posbench.predictors.kalman.ctra_rows`).
:class:`RowBank` is what both do around their kernels (the behaviour of the tests'
member-object ``ModelBank``, tests/reference_filters): the
one-fix-ahead scores (kept by the kernels), the shadows (rows ``n..2n-1``, copies of
the members' rows) and their horizon scores, and which member answers a query.

A fix's answer comes first. Work the answer to the fix does not depend on waits until
just before the next observation (:meth:`RowBank._catch_up`), or until a query that
depends on it (one at least the shortest horizon after the fix): scoring the shadows
that this fix ends a horizon of, a subclass's work after a fix (the kf's heading tracker
and bias estimator, which only IMU and speed updates read), and starting new shadows.
The answers are those of ModelBank (the parity tests); the work moves off the fix step
(the kf's fix step p99 ~13 -> ~6 us on a synthetic drive).

Units: seconds, metres, ENU.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from posbench.predictors._geometry import COV_SCALE_RANGE, check_config
from posbench.predictors._kernels import warm_up_once
from posbench.predictors.base import Predictor
from posbench.predictors.kalman.gnss_noise import GnssNoise
from posbench.predictors.kalman.inputs import FlatNames, OptionDoc

#: a kernel filling ``out`` with the shadows' distances [m] to a fix (t, x, y) and saying
#: whether every one is finite: ``(S, n, t, x, y, out) -> bool``
ShadowDistances = Callable[[np.ndarray, int, float, float, float, np.ndarray], bool]

#: the horizons [s] after a fix at which the shadows score the members (outages)
HORIZONS_S = (1.0, 3.0)


class RowBank(Predictor):
    """Selection, shadows and answering of a bank of rows (module docstring). A subclass
    sets ``labels``, ``horizons_s``, ``memory_fixes``, ``horizon_memory``, ``cov_scale``,
    ``_n`` (members), ``_gnss`` and :attr:`_distances`, calls :meth:`_reset_bank` with its
    rows in ``reset`` and wraps its kernels in :meth:`_fix_begins` / :meth:`_fix_ends`;
    every ``observe_*`` starts with ``if self._due: self._catch_up()``."""

    #: Huber k of the fix likelihood (``ModelBank``'s default)
    huber_k = 3.0
    #: the shadows' distance kernel
    _distances: ShadowDistances

    #: the flat option names of the inputs, and the bank's default inputs
    flat_names: FlatNames
    bank_inputs: dict[str, Any]
    #: the inputs the members take (a subclass composes them)
    inputs: dict[str, Any]

    labels: tuple[str, ...]
    horizons_s: tuple[float, ...]
    memory_fixes: float
    horizon_memory: float
    cov_scale: float
    _n: int
    _gnss: GnssNoise

    def _set_selection(
        self,
        memory_fixes: float,
        cov_scale: float,
        horizons_s: Sequence[float],
        horizon_memory: float,
    ) -> None:
        """Check and keep the selection's options, the same for every bank: the scores'
        memory in fixes, the covariance scale, the horizons [s] the shadows score at and
        their scores' memory."""
        check_config(
            self.name,
            memory_fixes=(memory_fixes, 1.0, 1e6),
            cov_scale=(cov_scale, *COV_SCALE_RANGE),
            horizon_memory=(horizon_memory, 1.0, 1e6),
            **{f"horizons_s[{i}]": (h, 1e-3, 3600.0) for i, h in enumerate(horizons_s)},
        )
        self.memory_fixes = float(memory_fixes)
        self.cov_scale = float(cov_scale)
        self.horizons_s = tuple(sorted(float(h) for h in horizons_s))
        self.horizon_memory = float(horizon_memory)

    def _reset_bank(self, rows: np.ndarray) -> None:
        """Forget the selection; ``rows`` (2n rows: members, then shadows) new."""
        n, nh = self._n, len(self.horizons_s)
        self._S = rows
        self._keep = 1.0 - 1.0 / self.memory_fixes
        self._keep_h = 1.0 - 1.0 / self.horizon_memory
        self.scores = np.zeros(n)
        self.best = 0
        #: per horizon: summed distances [m] of each member's shadows (lower is better)
        self.horizon_scores = np.zeros((nh, n))
        #: per horizon: the member answering queries at least that far after a fix
        self.horizon_best = [0] * nh
        self._horizon_seen = [False] * nh
        self._dist = np.empty(n)
        self._gnss.reset()
        self._t_fix = math.nan  # time [s] of the newest fix
        #: the shadows: running since the fix at ``_shadow_t0`` [s] (NaN: none); the next
        #: horizon they are scored at; the fix new shadows start at (NaN: none pending)
        self._shadow_t0 = math.nan
        self._next_h = 0
        self._shadow_due = math.nan
        #: the shadows' scoring a fix left for later: (t, x, y, first and end horizon)
        self._score_due: tuple[float, float, float, int, int] | None = None
        #: whether any work is left for before the next observation (:meth:`_catch_up`)
        self._due = False

    def warm_up(self) -> None:
        """Load the kernels before a run's clock starts, on a bank of the same options
        (:func:`~posbench.predictors._kernels.warm_up_once`)."""
        warm_up_once(lambda: type(self)(**self.config()))

    @property
    def selected(self) -> str:
        """Label of the member answering now."""
        return self.labels[self.best]

    @property
    def _shadows_on(self) -> bool:
        return self._shadow_t0 == self._shadow_t0

    # -- the work a fix leaves for later -------------------------------------------------
    def _catch_up(self) -> None:
        """Before the next observation: score the shadows a fix ended a horizon of, the
        subclass's work after a fix (:meth:`_after_fix_work`), start new shadows (copies of
        the members' rows)."""
        if self._score_due is not None:
            self._score_pending()
        self._after_fix_work()
        if self._shadow_due == self._shadow_due:
            n = self._n
            self._S[n:] = self._S[:n]
            self._start_shadow_helpers()
            self._shadow_t0 = self._shadow_due
            self._next_h = 0
            self._shadow_due = math.nan
        self._due = False

    def _after_fix_work(self) -> None:
        """A subclass's work a fix left for after its answer (none here)."""

    def _start_shadow_helpers(self) -> None:
        """A subclass's shadows' copies of what is not a row (none here)."""

    def _score_pending(self) -> None:
        """Score the shadows by the fix that ended their horizons ``first..end-1``
        (:meth:`ModelBank._score_shadows`); their rows are as they were at that fix."""
        pending = self._score_due
        assert pending is not None
        self._score_due = None
        t, x, y, first, end = pending
        if not self._distances(self._S, self._n, t, x, y, self._dist):
            return  # a shadow did not answer: no horizon is scored
        k = self._keep_h
        for i in range(first, end):
            sc = k * self.horizon_scores[i] + self._dist
            self.horizon_scores[i] = sc
            self.horizon_best[i] = int(np.argmin(sc))
            self._horizon_seen[i] = True

    # -- around a fix --------------------------------------------------------------------
    def _fix_begins(self, t: float, x: float, y: float) -> None:
        """A finite fix, before the members take it: the horizons it ends for the running
        shadows are scored after its answer; after the longest, the shadows stop."""
        t0, hs = self._shadow_t0, self.horizons_s
        if not hs or not t - t0 >= hs[self._next_h]:  # also none running (NaN)
            return
        first = self._next_h
        while self._next_h < len(hs) and t - t0 >= hs[self._next_h]:
            self._next_h += 1
        self._score_due = (t, x, y, first, self._next_h)
        self._due = True
        if self._next_h == len(hs):
            self._shadow_t0 = math.nan

    def _fix_ends(self, t: float) -> None:
        """A finite fix taken: the newest; new shadows start at it when none run."""
        self._t_fix = t
        if self.horizons_s and not self._shadows_on:
            self._shadow_due = t
            self._due = True

    # -- answers ---------------------------------------------------------------------------
    def answering(self, t: float) -> int:
        """Index of the member that answers a query at t [s]: the horizon choice of the
        largest horizon at most ``t`` - (newest fix) that has been scored, else the
        one-fix-ahead choice (``ModelBank.answering``)."""
        gap = t - self._t_fix
        hs = self.horizons_s
        if not (hs and gap >= hs[0]):
            return self.best
        if self._score_due is not None:
            self._score_pending()
        for i in range(len(hs) - 1, -1, -1):
            if gap >= hs[i] and self._horizon_seen[i]:
                return self.horizon_best[i]
        return self.best

    # -- options ---------------------------------------------------------------------------
    @classmethod
    def flat_options(cls) -> dict[str, Any]:
        """The flat option names and their defaults (for ``bench predictors`` and
        ``--set`` checks)."""
        return cls.flat_names.flatten(cls.bank_inputs, cls.bank_inputs)

    @classmethod
    def flat_option_types(cls) -> dict[str, Any]:
        """The flat option names and their declared types (``--set`` parses by them)."""
        return cls.flat_names.types(cls.bank_inputs)

    @classmethod
    def flat_option_docs(cls) -> dict[str, OptionDoc]:
        """What each flat option means, its unit and range, as the input types declare
        them (``bench predictors NAME``, the Predictor options page)."""
        return cls.flat_names.docs()

    def _flat_config(self) -> dict[str, Any]:
        """The inputs' options by their flat names, as ``config()`` gives them."""
        return self.flat_names.flatten(self.inputs, self.bank_inputs)

    def _selection_config(self) -> dict[str, Any]:
        """The selection's options, as ``config()`` gives them."""
        return {
            "memory_fixes": self.memory_fixes,
            "cov_scale": self.cov_scale,
            "horizons_s": list(self.horizons_s),
            "horizon_memory": self.horizon_memory,
        }

    def fix_variance(self, sigma: float | None) -> float:
        """R per axis [m^2] of a fix stating ``sigma``, as the members weigh it."""
        return self._gnss.parts(sigma)[0]

    @property
    def slow_variance(self) -> float:
        """The slow part [m^2] per axis of the newest fix's stated error, which
        ``covariance_at`` adds unscaled
        (:class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`)."""
        return self._gnss.slow_var

    def _bank_covariance(self, pxx: float, pxy: float, pyy: float) -> np.ndarray:
        """The answering member's position covariance (its own part ``pxx, pxy, pyy``
        [m^2], scale 1, plus the slow part of the newest fix), then the bank's
        ``cov_scale`` of its own part (:meth:`ModelBank.covariance_at`)."""
        s = self._gnss.slow_var
        P = np.array(((1.0 * pxx + s, 1.0 * pxy + 0.0), (1.0 * pxy + 0.0, 1.0 * pyy + s)))
        k = self.cov_scale
        slow = (1.0 - k) * s
        out = k * P
        out[0, 0] += slow
        out[1, 1] += slow
        return out
