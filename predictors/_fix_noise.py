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
"""

from __future__ import annotations

from posbench.predictors._copying import copy_attrs


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

    #: every instance attribute, for :func:`~posbench.predictors._copying.copy_attrs`
    _ATTRS = (
        "initial_var",
        "memory",
        "floor_var",
        "clip",
        "warmup",
        "_fixes",
        "_mean",
        "_n",
        "var",
    )

    def __deepcopy__(self, memo: dict) -> FixNoise:
        new = copy_attrs(self, self._ATTRS)
        memo[id(self)] = new
        new._fixes = list(self._fixes)
        return new

    def reset(self) -> None:
        self._fixes: list[tuple[float, float, float]] = []  # the last three (t, x, y)
        self._mean = 0.0  # running mean of the samples [m^2]
        self._n = 0
        self.var = self.initial_var

    @property
    def samples(self) -> int:
        """How many fixes have given a sample so far (the first three give none)."""
        return self._n

    def observe(self, t: float, x: float, y: float) -> None:
        """A fix at t [s], (x, y) [m]; a repeated time stamp is ignored."""
        fx = self._fixes
        if fx and not t > fx[-1][0]:
            return
        if len(fx) == 3:
            (t0, x0, y0), (t1, x1, y1), (t2, x2, y2) = fx
            l0 = (t - t1) * (t - t2) / ((t0 - t1) * (t0 - t2))
            l1 = (t - t0) * (t - t2) / ((t1 - t0) * (t1 - t2))
            l2 = (t - t0) * (t - t1) / ((t2 - t0) * (t2 - t1))
            rx = x - (l0 * x0 + l1 * x1 + l2 * x2)
            ry = y - (l0 * y0 + l1 * y1 + l2 * y2)
            sample = (rx * rx + ry * ry) / (2.0 * (1.0 + l0 * l0 + l1 * l1 + l2 * l2))
            if self._n >= self.warmup:
                sample = min(sample, self.clip * self._mean)
                self._mean += (sample - self._mean) / self.memory
            else:  # the plain mean of the first samples
                self._mean += (sample - self._mean) / (self._n + 1)
            self._n += 1
            if self._n >= self.warmup:
                self.var = max(self._mean, self.floor_var)
            fx.pop(0)
        fx.append((t, x, y))
