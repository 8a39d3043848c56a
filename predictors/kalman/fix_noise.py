"""The noise of fixes that state no accuracy, estimated from the fixes alone.

A receiver that states nothing (the paper's route pickles, comma2k19's u-blox log, exact
simulated fixes) leaves a filter to assume a fix noise; assumed wrong by 30x it either
smooths exact fixes into lag or chases noisy ones. Estimating it from the filter's own
innovations (covariance matching) feeds the filter's error back into the estimate: a
filter that follows the noise sees its innovations as motion. So the estimate here
never looks at a filter: each fix is compared with the quadratic through the three
before it (Lagrange extrapolation to its time). Any constant-acceleration motion drops
out exactly; white fix noise of per-axis variance ``s2`` gives a residual of variance
``s2 (1 + sum L_i^2)`` (``L_i`` the extrapolation weights), so each fix yields the
sample ``|r|^2 / (2 (1 + sum L_i^2))``. Samples are averaged with an exponential memory of
``memory`` fixes, each clipped at ``clip`` x the current estimate (a jump of the source,
a manoeuvre's jerk over a long gap), floored at ``floor_var`` [m^2]. Before
``warmup`` samples the estimate is the filter's assumed variance.

Each fix is one compiled call (:func:`observe_fix`, numba: ~0.6 us against ~3 us in plain
Python, paid once per fix by every filter that estimates its fix noise).
"""

from __future__ import annotations

import numpy as np

from posbench.predictors._kernels import kernel
from posbench.predictors.kalman.copying import copy_attrs

#: the state array: the last three fixes ``(t, x, y)`` (oldest first), how many are held,
#: the running mean of the samples [m^2] and their count
_FIXES, _HELD, _MEAN, _COUNT = 0, 9, 10, 11


@kernel
def observe_fix(
    st: np.ndarray,
    t: float,
    x: float,
    y: float,
    memory: float,
    clip: float,
    warmup: int,
) -> bool:
    """:meth:`FixNoise.observe` on its state array ``st``; whether a sample was taken."""
    held = int(st[_HELD])
    if held > 0 and not t > st[3 * (held - 1)]:
        return False
    if held < 3:
        st[3 * held] = t
        st[3 * held + 1] = x
        st[3 * held + 2] = y
        st[_HELD] = held + 1
        return False
    t0, x0, y0 = st[0], st[1], st[2]
    t1, x1, y1 = st[3], st[4], st[5]
    t2, x2, y2 = st[6], st[7], st[8]
    l0 = (t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2))
    l1 = (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2))
    l2 = (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1))
    rx = x - (l0 * x0 + l1 * x1 + l2 * x2)
    ry = y - (l0 * y0 + l1 * y1 + l2 * y2)
    sample = (rx * rx + ry * ry) / (2.0 * (1.0 + l0 * l0 + l1 * l1 + l2 * l2))
    n = int(st[_COUNT])
    if n >= warmup:
        sample = min(sample, clip * st[_MEAN])
        st[_MEAN] += (sample - st[_MEAN]) / memory
    else:  # the plain mean of the first samples
        st[_MEAN] += (sample - st[_MEAN]) / (n + 1)
    st[_COUNT] = n + 1
    for k in range(6):
        st[k] = st[k + 3]
    st[6] = t
    st[7] = x
    st[8] = y
    return True


class FixNoise:
    """Per-axis fix variance [m^2] from the fix stream (module docstring).

    Args:
        initial_var: the variance assumed before ``warmup`` samples [m^2].
        memory: exponential memory, in fixes.
        floor_var: the smallest variance returned [m^2] (1 mm: numerical safety).
        clip: a sample counts at most this many times the current estimate.
        warmup: samples before the estimate replaces ``initial_var``.
    """

    def __init__(
        self,
        initial_var: float,
        memory: float = 30.0,
        floor_var: float = 1e-6,
        clip: float = 9.0,
        warmup: int = 5,
    ) -> None:
        self.initial_var = float(initial_var)
        self.memory = float(memory)
        self.floor_var = float(floor_var)
        self.clip = float(clip)
        self.warmup = int(warmup)
        self.reset()

    #: every instance attribute, for :func:`~posbench.predictors.kalman.copying.copy_attrs`
    _ATTRS = (
        "initial_var",
        "memory",
        "floor_var",
        "clip",
        "warmup",
        "_st",
        "_n",
        "var",
    )

    def __deepcopy__(self, memo: dict) -> FixNoise:
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new._st = self._st.copy()
        return new

    def reset(self) -> None:
        self._st = np.zeros(12)  # the last three fixes, the running mean (observe_fix)
        self._n = 0  # samples so far
        self.var = self.initial_var

    @property
    def samples(self) -> int:
        """How many fixes have given a sample so far (the first three give none)."""
        return self._n

    def observe(self, t: float, x: float, y: float) -> None:
        """A fix at t [s], (x, y) [m]; a repeated time stamp is ignored."""
        if observe_fix(self._st, t, x, y, self.memory, self.clip, self.warmup):
            self._n += 1
            if self._n >= self.warmup:
                self.var = max(self._st[_MEAN].item(), self.floor_var)
