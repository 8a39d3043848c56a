"""GPS outlier gate shared by all predictors: reject fixes that imply impossible motion.

A fix is judged against the last two *accepted* fixes (t0, p0), (t1, p1):

- speed: ``|p - p1| / (t - t1) > speed_limit`` -> rejected;
- acceleration: the constant-velocity prediction ``p1 + v (t - t1)``, with
  ``v = (p1 - p0) / (t1 - t0)``, misses ``p`` by more than what a physical acceleration
  and the fix noise allow: ``accel_limit * dt * (dt + dt_prev) / 2`` (the position
  change of a velocity change ``accel_limit * (dt + dt_prev) / 2`` over ``dt``) plus
  ``n_sigma`` standard deviations of the miss caused by fix noise alone
  (per axis ``sigma * sqrt(2 + 2 (dt / dt_prev)^2)``: p, p1 and the velocity's two fixes).

``sigma`` is the fix-to-fix noise [m per axis], estimated online from the accepted fixes
(an exponentially weighted mean of their squared normalised misses) and never below
``pos_sigma``: 2-cm RTK noise is judged with ``pos_sigma`` (default 5 cm, so it is
never rejected), 0.5-m consumer noise with what it shows after a few fixes.

A rejected fix is a dropout for the predictor behind the gate. After ``max_consecutive``
rejections in a row the next fix is accepted anyway and becomes the new anchor (its
velocity history is forgotten), so a genuine jump (a receiver re-converging, a first fix
that was itself the outlier) is followed within a few fixes. A fix whose time is not
after the anchor's, or with non-finite values, is not judged (passed on unchanged).

Why this catches the paper's jumps: the routes repeat a fix unchanged (a stale position
stamped ~0.16 s later) and the next real fix follows 20-40 ms after it; between those two
the implied speed is 40-90 m/s. The stale fix is the impossible one (a 9 m/s car
stopping dead in 0.16 s is ~50 m/s^2); it is rejected and the next fix, judged against
the fix before the stale one, is consistent. Units: s, m (ENU), m/s, m/s^2.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from posbench.predictors._geometry import check_config
from posbench.predictors.base import Predictor, accepts_sigma

#: EWMA weight of one accepted fix in the noise estimate
NOISE_ALPHA = 0.05
#: intervals [s] longer than this do not update the noise estimate (motion dominates)
NOISE_MAX_DT = 1.0
#: normalised squared misses are clipped at this many times the current variance...
NOISE_CLIP = 3.0
#: ...which biases an Exp(1) mean to 1 - e^-3; divided out
WINSOR_MEAN = 1.0 - math.exp(-NOISE_CLIP)
#: a fix within this distance [m] of the anchor is a repeat of it (a stale solution)
REPEAT_TOL = 1e-3
#: slack [m] beyond the acceleration allowance before a repeat is rejected
REPEAT_SLACK = 0.05


class FixGate:
    """Decides, fix by fix, whether a GNSS fix is physically plausible (pure, O(1) per fix).

    Args:
        speed_limit: largest plausible speed [m/s] between accepted fixes.
        accel_limit: largest plausible horizontal acceleration [m/s^2].
        pos_sigma: floor of the fix-to-fix noise [m per axis] (the estimate never goes below).
        n_sigma: allowance for noise, in standard deviations of the miss.
        max_consecutive: after this many rejections in a row, the next fix is accepted and
            re-anchors the gate.
        warmup: the first this many fixes of a drive that can be judged only train the noise
            estimate (running mean) and are judged by speed alone.
    """

    def __init__(
        self,
        speed_limit: float = 60.0,
        accel_limit: float = 15.0,
        pos_sigma: float = 0.05,
        n_sigma: float = 4.0,
        max_consecutive: int = 3,
        warmup: int = 10,
    ) -> None:
        check_config(
            "gate",
            speed_limit=(speed_limit, 0.1, 1e4),
            accel_limit=(accel_limit, 0.1, 1e4),
            pos_sigma=(pos_sigma, 1e-4, 1e3),
            n_sigma=(n_sigma, 0.5, 100.0),
            max_consecutive=(max_consecutive, 1, 10_000),
            warmup=(warmup, 0, 10_000),
        )
        self.speed_limit = float(speed_limit)
        self.accel_limit = float(accel_limit)
        self.pos_sigma = float(pos_sigma)
        self.n_sigma = float(n_sigma)
        self.max_consecutive = int(max_consecutive)
        self.warmup = int(warmup)
        self.reset()

    def config(self) -> dict[str, Any]:
        return {
            "speed_limit": self.speed_limit,
            "accel_limit": self.accel_limit,
            "pos_sigma": self.pos_sigma,
            "n_sigma": self.n_sigma,
            "max_consecutive": self.max_consecutive,
            "warmup": self.warmup,
        }

    def reset(self) -> None:
        """Forget all fixes and counts (a new drive)."""
        self._t0 = self._x0 = self._y0 = math.nan  # accepted fix before the newest
        self._t1 = self._x1 = self._y1 = math.nan  # newest accepted fix (the anchor)
        self._var = self.pos_sigma**2  # fix-to-fix noise variance estimate [m^2]
        self._n_noise = 0  # noise updates so far
        self.run = 0  # current run of consecutive rejections
        self.rejected = 0
        self.accepted = 0
        self.resets = 0  # anchors forced after max_consecutive rejections

    @property
    def sigma(self) -> float:
        """Current fix-noise estimate [m per axis] (>= pos_sigma)."""
        return max(self.pos_sigma, math.sqrt(self._var))

    def _accept(self, t: float, x: float, y: float, keep_history: bool = True) -> bool:
        if keep_history:
            self._t0, self._x0, self._y0 = self._t1, self._x1, self._y1
        else:
            self._t0 = self._x0 = self._y0 = math.nan
        self._t1, self._x1, self._y1 = t, x, y
        self.run = 0
        self.accepted += 1
        return True

    def _reject(self) -> bool:
        self.run += 1
        self.rejected += 1
        return False

    def check(self, t: float, x: float, y: float) -> bool:
        """True if the fix (t [s], x, y [m]) is accepted; updates the gate's state."""
        if not (math.isfinite(t) and math.isfinite(x) and math.isfinite(y)):
            return True
        if self._t1 != self._t1:  # first fix
            return self._accept(t, x, y)
        dt = t - self._t1
        if not dt > 0.0:
            return True
        if self.run >= self.max_consecutive:
            self.resets += 1
            return self._accept(t, x, y, keep_history=False)
        dx, dy = x - self._x1, y - self._y1
        if math.hypot(dx, dy) > self.speed_limit * dt:
            return self._reject()
        dtp = self._t1 - self._t0
        if not dtp > 0.0:  # no velocity yet (second fix, or just re-anchored)
            return self._accept(t, x, y)
        r = dt / dtp
        mx = dx - (self._x1 - self._x0) * r
        my = dy - (self._y1 - self._y0) * r
        miss2 = mx * mx + my * my
        c2 = 2.0 + 2.0 * r * r  # noise variance of the miss per axis, in units of sigma^2
        accel_allow = self.accel_limit * dt * (dt + dtp) * 0.5
        warm = self._n_noise >= self.warmup
        if dx * dx + dy * dy <= REPEAT_TOL * REPEAT_TOL:
            # the receiver repeated its last solution: no noise of its own, so it is
            # judged on whether the car could have stood still since the anchor
            if warm and miss2 > (accel_allow + REPEAT_SLACK) ** 2:
                return self._reject()
            return self._accept(t, x, y)
        allow = accel_allow + self.n_sigma * self.sigma * math.sqrt(c2)
        if warm and miss2 > allow * allow:
            return self._reject()
        if dt <= NOISE_MAX_DT and dtp <= NOISE_MAX_DT:
            # E[miss^2] = 2 c2 sigma^2 for a 2-D miss of pure noise; q / sigma^2 ~ Exp(1)
            q = miss2 / (2.0 * c2)
            self._n_noise += 1
            if warm:  # winsorised: one large miss moves the estimate by a bounded step
                self._var += NOISE_ALPHA * (
                    min(q, NOISE_CLIP * self._var) / WINSOR_MEAN - self._var
                )
            else:
                self._var += (q - self._var) / self._n_noise
        return self._accept(t, x, y)


class GatedPredictor(Predictor):
    """Any predictor behind a :class:`FixGate`: rejected fixes never reach it, so it bridges
    them exactly as it bridges a missing fix. Everything else is forwarded unchanged.

    The gate's own: ``observe_gps`` (judged), ``reset`` (gate and predictor), ``config``
    (with the gate's), ``rejected``, ``gate`` and ``inner``. Every other attribute reads
    through to the wrapped predictor (``__getattr__``: its ``last_step``, ``steps``, ...),
    and so do the optional :class:`~posbench.predictors.base.Predictor` methods the gate does not
    override (``training_drives``, ``model_description``, new ones alike). Setting an
    attribute the wrapped predictor has (``gated.stage_timer = hook``) sets it there.
    ``observe_imu``, ``observe_speed`` and ``position_at`` are the wrapped predictor's
    bound methods (no hop on the hot path).

    ``gate.rejected`` counts the rejections since the last :meth:`reset`.
    """

    #: the names stored on the gate itself (everything else may be the wrapped predictor's)
    _OWN = frozenset(
        {"inner", "gate", "name", "observe_imu", "observe_speed", "position_at", "_inner_sigma"}
    )

    def __init__(self, inner: Predictor, gate: FixGate | None = None) -> None:
        self.inner = inner
        self.gate = gate if gate is not None else FixGate()
        self.name = inner.name  # type: ignore[misc]  # instance attribute shadows the ClassVar
        self.observe_imu = inner.observe_imu  # type: ignore[method-assign]  # hot path: no hop
        self.observe_speed = inner.observe_speed  # type: ignore[method-assign]
        self.position_at = inner.position_at  # type: ignore[method-assign]
        self._inner_sigma = accepts_sigma(inner.observe_gps)  # forward the fix accuracy?

    def __getattr__(self, key: str) -> Any:
        """Only for names the gate lacks: the wrapped predictor's attribute. Special names
        (``__setstate__``, ``__deepcopy__``, ...) and a gate without ``inner`` yet (being
        unpickled) raise AttributeError, so pickle and copy treat the gate as itself."""
        inner = self.__dict__.get("inner")
        if inner is None or (key.startswith("__") and key.endswith("__")):
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {key!r}")
        return getattr(inner, key)

    def __setattr__(self, key: str, value: object) -> None:
        """The gate's own names (and any the wrapped predictor lacks) are set on the gate;
        a name the wrapped predictor has is set there."""
        if key in self._OWN or hasattr(type(self), key) or key in self.__dict__:
            object.__setattr__(self, key, value)
            return
        inner = self.__dict__.get("inner")
        if inner is not None and hasattr(inner, key):
            setattr(inner, key, value)
        else:
            object.__setattr__(self, key, value)

    @property
    def rejected(self) -> int:
        """Fixes rejected since the last reset."""
        return self.gate.rejected

    def reset(self) -> None:
        self.gate.reset()
        self.inner.reset()

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        """Judge the fix; pass an accepted one on, with ``sigma`` [m] when the wrapped
        predictor's observe_gps takes it (three-argument predictors get t, x, y only)."""
        if self.gate.check(t, x, y):
            if self._inner_sigma:
                self.inner.observe_gps(t, x, y, sigma=sigma)
            else:
                self.inner.observe_gps(t, x, y)

    def position_at(self, t: float) -> tuple[float, float]:  # replaced per instance
        return self.inner.position_at(t)

    def config(self) -> dict[str, Any]:
        return {**self.inner.config(), "gate": self.gate.config()}


def _forward(key: str) -> Callable[..., Any]:
    """A GatedPredictor method calling the wrapped predictor's method ``key``."""

    def method(self: GatedPredictor, *args: object, **kwargs: object) -> object:
        return getattr(self.inner, key)(*args, **kwargs)

    method.__name__ = key
    method.__qualname__ = f"GatedPredictor.{key}"
    method.__doc__ = getattr(Predictor, key).__doc__
    return method


# the base's optional methods the gate inherits but does not override would answer for the
# gate itself (a model-less default): forward them, the ones added later included
for _key, _value in vars(Predictor).items():
    if callable(_value) and not _key.startswith("_") and _key not in vars(GatedPredictor):
        setattr(GatedPredictor, _key, _forward(_key))
