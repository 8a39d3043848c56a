"""``hybrid``: the ``kf`` bank as prior plus a learned residual, applied only as far as it
has earned it (numpy + onnxruntime, no torch).

The prior is the ``kf`` itself, :class:`posbench.predictors.kalman.kf.KalmanBank`, run inside
the hybrid on every observation (fixes with their stated sigma, IMU, wheel speed) with
the parameters the network was trained with (model.json ``prior.params[condition]``, the
kf's tuning for that GPS condition at training time; see
:func:`~posbench.predictors.hybrid.model_info.prior_params`).

On each real GPS fix whose window holds >= 4 fixes spanning >= 2 s, one *network step*:

1. the ``lstm``'s input window (:class:`posbench.predictors.lstm.fused.FusedStep`: cubics through
   the fixes and the IMU, 8 grid points 200 ms apart ending at the fix, features in the
   heading frame; psi [rad] = heading of the fixes' cubic at the fix);
2. the prior input: for H = (0.2, 0.4, 0.6, 0.8) s, ``kf.position_at(t_fix + h) - grid[7]``
   rotated by -psi (heading frame: x along the heading, y to the left) [m], shape (4, 2);
3. the network (inputs ``features`` [1, 8, 6], ``prior`` [1, 4, 2]) answers ``correction``
   [1, 4, 4]: per horizon (dx, dy) [m, heading frame] to ADD to ``kf.position_at(t_fix +
   h)`` and (log var along the heading, log var across) [log m^2] of that residual.

Steps 2 and 3, the input box below and the knots of the correction are one compiled call
(:mod:`posbench.predictors.hybrid.step_kernel`), the prior's positions at the four horizons
another (:meth:`KalmanBank.positions_at <posbench.predictors.kalman.kf.KalmanBank.positions_at>`).

Answers, with h = t - t_fix of the newest network step:
``position_at(t) = kf.position_at(t) + g a(h) R(psi) corr(h)``, corr linearly
interpolated over the knots h = 0 (correction 0), 0.2, 0.4, 0.6, 0.8 s and held at its
0.8 s value beyond; ``covariance_at(t) = kf.covariance_at(t) + g R(psi) diag(var(h))
R(psi)^T`` with the log variances interpolated the same way between the knots 0.2-0.8 s
(held beyond), and the variance rising linearly from 0 at h = 0 to its 0.2 s value.

The gate (:mod:`posbench.predictors.hybrid.gate`, model.json ``gate``): ``a(h)`` is a
shrinkage per horizon fitted on held-out development drives; a window outside the box
of the training inputs takes no correction; ``g`` in [0, 1] is the drive's own evidence
that the correction predicts the fixes better than the prior does (0 until it has
earned it). ``gate=False`` applies the network's correction as it is (for inspection).

GPS outages: no network step runs between real fixes, so an outage is bridged by the
kf's own dead reckoning (its constant-acceleration state, kept current by IMU and wheel
speed updates) plus the correction held at its 0.8 s value. This differs from ``lstm``,
which feeds its own predictions back as pseudo-fixes. A real fix arriving more than
:data:`RESTART_GAP_S` after the previous one restarts the fix history (start-up again).

Fallback to the prior alone (correction 0, the kf's covariance):

- start-up: before the first window of >= 4 fixes spanning >= 2 s (and after a restart);
  a real fix that yields no window clears the previous step's correction;
- a window outside the training inputs' box, or a network output (or its variance)
  that is not finite;
- no evidence yet, or evidence that the correction does not help (g = 0);
- standstill: the wheel/CAN speed (else the speed of the window's cubic at the fix) below
  0.15 km/h (:data:`posbench.predictors.lstm.predictor.STILL_SPEED_MPS`), decided at query time.

Frames and units: positions [m] local ENU, times [s], covariances [m^2] ENU.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from posbench.predictors.base import GpsCondition, ModelFileSeams, Predictor
from posbench.predictors.hybrid import step_kernel
from posbench.predictors.hybrid.core import HybridCore
from posbench.predictors.hybrid.gate import EvidenceGate, envelope_arrays
from posbench.predictors.hybrid.model_info import (
    BUNDLED_TEXT,
    HORIZONS,
    INPUTS,
    N_H,
    OUTPUT,
    bundled_model,
    check_net,
    load_model_info,
    prior_params,
)
from posbench.predictors.hybrid.step_kernel import NO_CORE, NOT_FINITE, OUTSIDE
from posbench.predictors.kalman.kf import KalmanBank
from posbench.predictors.lstm.core_net import has_core
from posbench.predictors.lstm.features import N_FEATURES
from posbench.predictors.lstm.fused import FusedStep
from posbench.predictors.lstm.history import FIX_CAP, ImuHistory, RowBuffer, fit_fused_window
from posbench.predictors.lstm.predictor import RESTART_GAP_S, STILL_SPEED_MPS
from posbench.predictors.lstm.resample import DT, GRID_OFFSETS
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.scenarios.errors import DataError

_NAN2 = (math.nan, math.nan)
H1, H2, H3, H4 = HORIZONS


class HybridPredictor(ModelFileSeams, Predictor):
    """``kf`` prior + learned residual (ONNX) at 0.2-0.8 s; see the module doc.

    Args:
        model: a ``model.onnx`` with its ``model.json`` alongside, or a folder holding both
            (as ``bench train`` writes it); default: the bundled model.
        gps_condition: the run's GPS condition (``none``, ``rtk``, ``consumer``, ``native``;
            passed by :func:`posbench.predictors.registry.create`): picks the prior's kf parameters
            from model.json (fallback ``native``, then the kf's defaults).
        gate: apply the gate (module doc; default). False: the network's correction as it
            is, for inspection (``--set hybrid.gate=false``).
    """

    name = "hybrid"
    bundled_text = BUNDLED_TEXT

    def __init__(
        self,
        model: str | None = None,
        gps_condition: GpsCondition | None = None,
        gate: bool = True,
    ) -> None:
        self.bundled = not model
        self.model_path = Path(model) if model else bundled_model()
        if self.model_path.is_dir():  # a folder written by training
            self.model_path = self.model_path / "model.onnx"
        if not self.model_path.is_file():
            raise DataError(self.model_path, "ONNX model file not found")
        self.info = load_model_info(self.model_path)
        self.gps_condition = gps_condition
        self.prior_condition, self.prior_params = prior_params(self.info, gps_condition)
        try:
            self.kf = KalmanBank(**self.prior_params)
        except (TypeError, DataError) as exc:
            raise DataError(
                self.model_path.with_suffix(".json"),
                f"prior.params[{self.prior_condition!r}] is not a kf "
                f"configuration: {str(exc).splitlines()[0]}",
            ) from None
        shape = (self.info.get("input_shapes") or {}).get(INPUTS[0]) or [None]
        batch_dim = shape[0] if isinstance(shape[0], str) else None
        self.net = OnnxModel(
            self.model_path, output=self.info.get("output", OUTPUT), batch_dim=batch_dim
        )
        check_net(self.model_path, self.net)
        #: the network's compiled core (model.json "core"; :mod:`posbench.predictors.hybrid.core`),
        #: or None: the full graph through onnxruntime (a model copied without its core file)
        self.core = (
            HybridCore(self.model_path, self.info["core"], self.info, self.net)
            if has_core(self.model_path, self.info)
            else None
        )
        pinv = np.linalg.pinv(np.vander(np.append(GRID_OFFSETS, DT), 4, increasing=True))
        self._fused = FusedStep(self.net, "heading", pinv)
        self.gate = bool(gate)
        g = self.info.get("gate") or {}
        shrink = g.get("shrink", [1.0] * N_H) if self.gate else [1.0] * N_H
        #: shrinkage per knot (index 0 = h 0, unused)
        self._shrink = np.array([0.0, *(float(a) for a in shrink)])
        self._box = envelope_arrays(g) if self.gate and "feature_min" in g else None
        self._pos = np.zeros((N_H, 2))  # the prior's positions at the horizons [m, ENU]
        self._knots = np.zeros((4, N_H + 1))  # network_step's answer
        self._args = self._kernel_args()
        self.evidence = EvidenceGate()
        self.reset()

    def config(self) -> dict:
        return {
            "model": str(self.model_path),
            "gps_condition": self.gps_condition,
            "gate": self.gate,
            "prior": {
                "predictor": "kf",
                "condition": self.prior_condition,
                "params": self.kf.config(),
            },
            "architecture": self.info.get("architecture"),
            "core": self.core is not None,
            "command": self.info.get("command"),
        }

    # ------------------------------------------------------------------ seams
    def last_step(self) -> tuple[float, float] | None:
        """(t_fix [s], psi [rad]) of the network step behind the current corrections, or
        None while the hybrid answers as its prior (start-up, a fix without a window, a
        non-finite network output). At standstill the correction is 0 whatever this says."""
        if not self._has:
            return None
        return self._t_fix, math.atan2(self._cs[1], self._cs[0])

    # ------------------------------------------------------------------ state
    def warm_up(self) -> None:
        """The prior's start-up work (its kernels, and its positions at four times) and the
        network step's kernel, before a run's clock starts."""
        self.kf.warm_up()
        probe = KalmanBank(**self.prior_params)
        probe.observe_gps(0.0, 0.0, 0.0)
        probe.positions_at(HORIZONS, self._pos)
        self._fused.warm_up()
        self._network_step(0.0, 0.0, 1.0, 0.0)

    def reset(self) -> None:
        self.kf.reset()
        self._fix = RowBuffer(FIX_CAP, 3)  # t, x, y of real fixes
        self._imu = ImuHistory()
        self._t_real = math.nan
        self._can_v: float | None = None
        self._gps_v = math.nan
        self.evidence.reset()
        self._clear()
        self.steps = 0
        self.outside = 0  # network steps whose window was outside the training box

    def _clear(self) -> None:
        """No correction: answers are the prior's."""
        self._has = False
        self._t_fix = math.nan
        self._cs = (1.0, 0.0)
        self._kx = [0.0] * (N_H + 1)  # world correction at the knots [m]: x
        self._ky = [0.0] * (N_H + 1)  # and y
        self._lva = [0.0] * (N_H + 1)  # log variances at the knots (index 0 unused): along
        self._lvc = [0.0] * (N_H + 1)  # and across

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        self.kf.observe_imu(t, ax, ay, yaw, yaw_rate)
        self._imu.add(t, ax, ay, yaw)

    def observe_speed(self, t: float, v: float) -> None:
        self.kf.observe_speed(t, v)
        if math.isfinite(v):
            self._can_v = v

    def observe_gps(self, t: float, x: float, y: float, sigma: float | None = None) -> None:
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        if self.gate and self._has:
            self._weigh_evidence(t, x, y)
        self.kf.observe_gps(t, x, y, sigma)
        fb = self._fix
        if t - self._t_real > RESTART_GAP_S:
            fb.clear()  # a long outage ends: start afresh from this fix
        self._t_real = t
        tl = fb.t
        while tl and tl[-1] >= t:  # a repeated time: the newer fix replaces the older
            fb.pop()
        fb.append((t, x, y))
        if not self._step(t):
            self._clear()

    def _weigh_evidence(self, t: float, x: float, y: float) -> None:
        """The fix at t as evidence for or against the correction (module doc, the gate)."""
        px, py = self.kf.position_at(t)
        if px != px:
            return
        cx, cy = self.correction_at(t, gated=False)
        self.evidence.observe(x - px, y - py, cx, cy)

    # ------------------------------------------------------------------ step
    def _step(self, t_end: float) -> bool:
        """The network step on the newest fix (see the module doc); False where there is
        no window or the network's answer is not finite."""
        f = self._fused
        if not fit_fused_window(f, self._fix, self._imu, t_end):
            return False
        f.features()
        psi = f.psi
        c, s = math.cos(psi), math.sin(psi)
        gx, gy = f.pts[7].tolist()
        self.kf.positions_at((t_end + H1, t_end + H2, t_end + H3, t_end + H4), self._pos)
        status = self._network_step(gx, gy, c, s)
        if status == OUTSIDE:
            self.outside += 1
            return False
        self._gps_v = f.speed
        if status == NO_CORE:  # the full graph through onnxruntime (a model without a core)
            out = np.ascontiguousarray(self.net.run_buffer(), np.float32).reshape(-1)
            if not step_kernel.output_knots(out, c, s, self._shrink, self._knots):
                return False
        elif status == NOT_FINITE:
            return False
        self._kx, self._ky, self._lva, self._lvc = self._knots.tolist()
        self._cs = (c, s)
        self._t_fix = t_end
        self._has = True
        self.steps += 1
        return True

    def _network_step(self, gx: float, gy: float, c: float, s: float) -> int:
        """:func:`~posbench.predictors.hybrid.step_kernel.network_step` on the prior's
        positions at the horizons (``_pos``), the window's last grid point (gx, gy) [m] and
        heading (cos, sin); the network's input buffers as they stand."""
        bufs = self.net.bufs
        pos, args = self._pos, self._args  # the module's kernel, compiled at its first call
        return int(step_kernel.network_step(pos, gx, gy, c, s, bufs[0][0], bufs[1][0], *args))

    def __getstate__(self) -> dict:
        """Without the kernel's arguments: they are derived (:meth:`_kernel_args`), and
        hold the core's packed weights, which the core does not pickle either."""
        return {k: v for k, v in self.__dict__.items() if k != "_args"}

    def __setstate__(self, state: dict) -> None:
        """An unpickled hybrid's kernel arguments are its own copies' (its core packs its
        weights again, aligned)."""
        self.__dict__.update(state)
        self._args = self._kernel_args()

    def _kernel_args(self) -> tuple:
        """:func:`~posbench.predictors.hybrid.step_kernel.network_step`'s arguments after
        the network's inputs: the box (placeholders where there is none) and the core
        (placeholders where the model has none), the shrinkage and the knots' buffer."""
        box = self._box
        if box is None:
            f32 = np.float32
            zf, zp = np.zeros(N_FEATURES, f32), np.zeros((N_H, 2), f32)
            box = (zf, zf, zp, zp)
        core = self.core.core if self.core is not None else None
        if core is None:
            weights = (np.zeros(0, np.float32), 0, 0.0, np.zeros(4 * N_H, np.float32))
        else:
            weights = (core.packed, core.dims.hidden, core.slope, core.output)
        return (
            self._box is not None,
            *box,
            core is not None,
            *weights,
            self._shrink,
            self._knots,
        )

    # ------------------------------------------------------------------ queries
    def _stationary(self) -> bool:
        v = self._can_v if self._can_v is not None else self._gps_v
        return v == v and abs(v) < STILL_SPEED_MPS

    def gate_weight(self) -> float:
        """The drive's evidence weight g in [0, 1] (1 with ``gate=False``)."""
        return self.evidence.weight if self.gate else 1.0

    def correction_at(self, t: float, gated: bool = True) -> tuple[float, float]:
        """The world correction (dx, dy) [m, ENU] added to the prior's answer for t [s]:
        (0, 0) where the hybrid falls back to the prior (see the module doc). ``gated``
        False: before the evidence weight g (the correction the evidence is about)."""
        if not self._has or self._stationary():
            return 0.0, 0.0
        g = self.gate_weight() if gated else 1.0
        if g == 0.0:
            return 0.0, 0.0
        u = (t - self._t_fix) / DT
        kx, ky = self._kx, self._ky
        if u >= N_H:
            return g * kx[N_H], g * ky[N_H]
        if u <= 0.0:
            return 0.0, 0.0
        k = int(u)
        f = u - k
        return g * (kx[k] + f * (kx[k + 1] - kx[k])), g * (ky[k] + f * (ky[k + 1] - ky[k]))

    def position_at(self, t: float) -> tuple[float, float]:
        px, py = self.kf.position_at(t)
        if not self._has or px != px:
            return px, py
        dx, dy = self.correction_at(t)
        return px + dx, py + dy

    def residual_variance_at(self, t: float) -> tuple[float, float]:
        """(along, across) the heading: the variance [m^2] of the learned residual at t [s],
        times the evidence weight g (0, 0 on fallback; see the module doc for the
        interpolation)."""
        if not self._has or self._stationary():
            return 0.0, 0.0
        g = self.gate_weight()
        if g == 0.0:
            return 0.0, 0.0
        va, vc = self._residual_variance(t)
        return g * va, g * vc

    def _residual_variance(self, t: float) -> tuple[float, float]:
        u = (t - self._t_fix) / DT
        la, lc = self._lva, self._lvc
        if u >= N_H:
            return math.exp(la[N_H]), math.exp(lc[N_H])
        if u <= 0.0:
            return 0.0, 0.0
        if u < 1.0:
            return u * math.exp(la[1]), u * math.exp(lc[1])
        k = int(u)
        f = u - k
        return (
            math.exp(la[k] + f * (la[k + 1] - la[k])),
            math.exp(lc[k] + f * (lc[k + 1] - lc[k])),
        )

    def covariance_at(self, t: float) -> np.ndarray | None:
        """2x2 ENU covariance [m^2]: the kf's plus the residual's, R(psi) diag(var) R(psi)^T."""
        p = self.kf.covariance_at(t)
        if p is None or not self._has:
            return p
        va, vc = self.residual_variance_at(t)
        if va == 0.0 and vc == 0.0:
            return p
        c, s = self._cs
        cc, ss, cs = c * c, s * s, c * s * (va - vc)
        p[0, 0] += cc * va + ss * vc
        p[1, 1] += ss * va + cc * vc
        p[0, 1] += cs
        p[1, 0] += cs
        return p
