"""``lstm``: the paper's system as a streaming predictor (numpy + onnxruntime, no torch).

On each GPS fix (:meth:`LstmPredictor.observe_gps`) one *step* runs:

1. resample: a cubic (closed form) through the most recent fixes covering >= 2 s, evaluated
   on 8 grid times 200 ms apart ending at the fix; the IMU (ax, ay, yaw) fitted likewise
   over the same span (:mod:`posbench.predictors.lstm.resample`);
2. features (:mod:`posbench.predictors.lstm.features`, the frame recorded in model.json);
3. inference: the network's displacement to the point 200 ms after the fix;
4. current-position fit: a cubic through the 8 grid points and that prediction (fixed
   times, precomputed pseudo-inverse). :meth:`position_at` evaluates it at any t between
   the fix and the prediction; beyond, see below.

GPS dropout (the paper's feedback loop): when ``position_at`` is asked for a time past
the prediction (t > last grid time + 0.2 s) and no fix has come, the prediction becomes
the newest grid sample (stored as a pseudo-fix), the IMU is resampled from the real
samples up to then, and the next step runs; each step advances 0.2 s, so outages of
any length are bridged (at most ``MAX_BRIDGE_STEPS`` per call).

Standstill: below 0.15 km/h the position is held (the value at the moment standstill was
seen). The speed is the latest wheel/CAN speed when the drive has one
(:meth:`observe_speed`), else the speed of the fitted GPS cubic at the newest fix.

Start-up: until the fixes span 2 s there is no network input; the predictor then
extrapolates a least-squares *line* through the fixes it has (one fix: that fix), as a
short cubic would extrapolate wildly.

The steps above are the *staged* reference (``step="staged"``). By default a fix step runs
*fused* (:mod:`posbench.predictors.lstm.fused`: the same maths in few numpy calls, both cubics in
one batched solve, one onnxruntime call; within 1e-6 m of the staged step on every shared drive,
tested); bridging steps, windows of < 4 fixes and the L-BFGS fit run staged.

Public seams (for benchmarks and figures, nothing private to reach into):

- :attr:`LstmPredictor.stage_timer`: None (default; costs one ``is None`` test per stage)
  or a callable ``(stage, duration_ns)`` called once per stage of every network step a
  fix triggers (:attr:`LstmPredictor.stages`, in order: :data:`FUSED_STAGES` or
  :data:`STAGES`; bridging steps inside ``position_at`` and start-up line fits report
  nothing). :class:`StageRecorder` collects them.
- :meth:`LstmPredictor.last_step`: the newest network step as an :class:`LstmStep`
  (input grid, predicted point, times), copied.
"""

from __future__ import annotations

import math
from pathlib import Path
from time import perf_counter_ns
from typing import Literal, get_args

import numpy as np

from posbench.predictors.base import ModelFileSeams, Predictor
from posbench.predictors.lstm.core_net import CoreNet, has_core
from posbench.predictors.lstm.features import features_one
from posbench.predictors.lstm.fused import FusedStep
from posbench.predictors.lstm.history import (
    FIX_CAP,
    ImuHistory,
    RowBuffer,
    fit_fused_window,
    fit_window,
    imu_on_grid,
)
from posbench.predictors.lstm.model_info import (
    BUNDLED_TEXT,
    bundled_model,
    check_model,
    load_model_info,
)
from posbench.predictors.lstm.resample import (
    DT,
    GRID_OFFSETS,
    MIN_SPAN_S,
    N_STEPS,
    FixedGridFit,
    eval_poly,
    fit_poly,
    window_start,
)
from posbench.predictors.lstm.runtime import OnnxModel
from posbench.predictors.lstm.stages import (
    FUSED_STAGES,
    STAGES,
    LstmStep,
    StageRecorder,  # noqa: F401  (re-exported: a seam of this predictor, see above)
    StageTimer,
    lap,
)

STILL_SPEED_MPS = 0.15 / 3.6
STILL_FIXES = 5  # fixes averaged for the standstill hold
MAX_BRIDGE_STEPS = 1500
#: a real fix this long [s] after the previous real one restarts the fix history: the
#: bridging pseudo-fixes of a long outage (metres off by then) must not shape the new fit
RESTART_GAP_S = 5.0
Fit = Literal["closed", "lbfgs"]
FITS: tuple[str, ...] = get_args(Fit)
#: ``fused`` (default): the fix step in few numpy calls (:mod:`posbench.predictors.lstm.fused`);
#: ``staged``: the readable reference, stage by stage (same answers to float rounding)
Step = Literal["fused", "staged"]
STEPS: tuple[str, ...] = get_args(Step)


class LstmPredictor(ModelFileSeams, Predictor):
    """The paper's cubic resampling + MLP-LSTM-MLP (ONNX) + cubic current position.

    Args:
        model: path of a ``model.onnx`` with its ``model.json`` alongside (default: the
            bundled model).
        fit: ``"closed"`` (closed-form least squares) or ``"lbfgs"`` (the paper's iterative
            fit, :func:`posbench.predictors.cubic.fit_cubic_lbfgs`; slow, for latency comparison).
        step: ``"fused"`` (default; :mod:`posbench.predictors.lstm.fused`, closed-form fit only) or
            ``"staged"`` (the readable reference, timed stage by stage by ``bench latency``).
    """

    name = "lstm"
    bundled_text = BUNDLED_TEXT
    #: None, or a hook receiving (stage, duration [ns]) for each of :data:`STAGES` of every
    #: network step a fix triggers (see the module doc); set it on an instance
    stage_timer: StageTimer | None = None

    def __init__(self, model: str | None = None, fit: Fit = "closed", step: Step = "fused") -> None:
        if fit not in FITS:
            raise ValueError(f"fit must be one of {FITS}, not {fit!r}")
        if step not in STEPS:
            raise ValueError(f"step must be one of {STEPS}, not {step!r}")
        self.step = step
        self.bundled = not model
        self.model_path = Path(model) if model else bundled_model()
        if self.model_path.is_dir():  # a folder written by `bench train`
            self.model_path = self.model_path / "model.onnx"
        self.info = load_model_info(self.model_path)
        self.frame = self.info.get("frame", "heading")
        #: row 0 of the input holds the newest fix minus the newest grid point (model.json)
        self.fix_offset = bool(self.info.get("fix_offset", False))
        self.fit = fit
        declared = self.info.get("input_shape") or [None]
        batch_dim = declared[0] if isinstance(declared[0], str) else None
        self.net = OnnxModel(self.model_path, output=self.info.get("output"), batch_dim=batch_dim)
        check_model(self.model_path, self.info, self.net)
        self._init_buffers()

    def _init_buffers(self) -> None:
        self._final = FixedGridFit(np.append(GRID_OFFSETS, DT))
        self._grid_fit = FixedGridFit(GRID_OFFSETS)
        self._x = np.empty((N_STEPS, 6), dtype=np.float64)
        self._pts = np.empty((N_STEPS + 1, 2))
        fused = getattr(self, "step", "staged") == "fused" and self.fit == "closed"
        #: the model's core graph (model.json "core"; :mod:`posbench.predictors.lstm.core_net`), run
        #: by the fused step; a model copied without its core file runs the full graph
        self.core = (
            CoreNet(self.model_path, self.info["core"], self.net)
            if fused and has_core(self.model_path, self.info)
            else None
        )
        self._fused = (
            FusedStep(self.net, self.frame, self._final.pinv, self.fix_offset, self.core)
            if fused
            else None
        )
        self.stage_timer = None
        self.reset()

    def warm_up(self) -> None:
        """Load the fused step's compiled calls (numba) before a run's clock starts."""
        if self._fused is not None:
            self._fused.warm_up()

    def config(self) -> dict:
        return {
            "model": str(self.model_path),
            "fit": self.fit,
            "frame": self.frame,
            "fix_offset": self.fix_offset,
            "step": self.step,
            "core_graph": self.core is not None,
            "architecture": self.info.get("architecture"),
            "command": self.info.get("command"),
        }

    @property
    def stages(self) -> tuple[str, ...]:
        """The stage names :attr:`stage_timer` receives for a fix step, in order:
        :data:`FUSED_STAGES` for the fused step, :data:`STAGES` for the staged one."""
        return FUSED_STAGES if self._fused is not None else STAGES

    # ------------------------------------------------------------------ seams
    def last_step(self) -> LstmStep | None:
        """The network step behind the current answers (copies), or None while there is
        none: before the fixes span 2 s, or while a restart after a long outage is still
        answered by the start-up line. A query past the prediction may run bridging steps
        first; :meth:`position_at` may answer otherwise at standstill (the hold)."""
        if self._mode != "net":
            return None
        grid = self._grid.copy()
        pred = self._pred.copy()
        grid.flags.writeable = False
        pred.flags.writeable = False
        return LstmStep(grid, pred, self._t_end, DT, self._t_end > self._t_real)

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        self._fix = RowBuffer(FIX_CAP, 3)  # t, x, y (real fixes and bridging pseudo-fixes)
        self._t_real = math.nan  # time of the newest real fix
        self._imu = ImuHistory()
        self._can_v: float | None = None
        self._gps_v = math.nan
        self._hold: tuple[float, float] | None = None
        self._still: list[tuple[float, float]] = []  # newest fixes received at standstill
        self._mode = "empty"  # empty | line | net
        self._t_end = math.nan
        self._grid = np.zeros((N_STEPS, 2))
        self._pred = np.zeros(2)
        self._c: tuple[float, ...] = (0.0,) * 8  # final cubic (x0..x3, y0..y3) in s = t - t_end
        self._line = (0.0, 0.0, 0.0, 0.0, 0.0)  # t0, x0, vx, y0, vy
        self.steps = 0
        self.bridge_steps = 0
        self.fused_steps = 0  # of self.steps, those that ran through the fused step

    def observe_imu(self, t: float, ax: float, ay: float, yaw: float, yaw_rate: float) -> None:
        self._imu.add(t, ax, ay, yaw)

    def observe_speed(self, t: float, v: float) -> None:
        if math.isfinite(v):
            self._can_v = v

    def observe_gps(self, t: float, x: float, y: float) -> None:  # type: ignore[override]  # three-argument form on purpose: no sigma passed (accepts_sigma)
        timer = self.stage_timer
        c0 = perf_counter_ns() if timer is not None else 0
        if not (math.isfinite(x) and math.isfinite(y)):
            return
        if self._can_v is not None and abs(self._can_v) < STILL_SPEED_MPS:
            # standstill (wheel speed): hold the mean of the newest fixes received while
            # standing (noise / sqrt(n)), so the hold follows slow creep and the receiver
            # rather than a stale extrapolation
            st = self._still
            st.append((x, y))
            if len(st) > STILL_FIXES:
                del st[0]
            self._hold = (sum(p[0] for p in st) / len(st), sum(p[1] for p in st) / len(st))
        else:
            self._still.clear()
        fb = self._fix
        if t - self._t_real > RESTART_GAP_S:
            fb.clear()  # a long outage ends: start afresh from this fix (line, then cubic)
        self._t_real = t
        # a pseudo-fix at or after this time (bridging) gives way to the real fix
        tl = fb.t
        while tl and tl[-1] >= t:
            fb.pop()
        fb.append((t, x, y))
        fused = self._fused
        if fused is not None and self._fused_step(fused, timer, c0):
            return
        self._step_on_fixes(timer, c0)

    # ------------------------------------------------------------------ steps
    def _fused_step(self, f: FusedStep, timer: StageTimer | None, c0: int) -> bool:
        """The fix step through ``f`` (:attr:`_fused`); False (nothing changed) where the
        staged step must run instead: fixes spanning < 2 s (start-up line), fewer than 4
        fixes in the window (a lower-degree fit), a non-finite prediction."""
        fb = self._fix
        t_end = fb.t[fb.n - 1]
        if not fit_fused_window(f, fb, self._imu, t_end):
            return False
        if timer is not None:
            c0 = lap(timer, "resample", c0)
        f.features()
        if timer is not None:
            c0 = lap(timer, "features", c0)
        d0, d1 = f.infer()
        if timer is not None:
            c0 = lap(timer, "inference", c0)
        if not f.finish(d0, d1):
            return False
        pts = f.pts
        self._gps_v = f.speed
        self._grid = pts[:N_STEPS]
        self._pred = pts[N_STEPS]
        self._c = f.coef
        self._t_end = t_end
        self._mode = "net"
        self.steps += 1
        self.fused_steps += 1
        if timer is not None:
            lap(timer, "current_position_fit", c0)
        return True

    def _step_on_fixes(self, timer: StageTimer | None, c0: int) -> None:
        """A step on the fixes (the newest real): the position cubic and grid, then the
        network (``timer``: the stage hook, ``c0``: the step's start [ns])."""
        a = self._fix.view()
        end = a.shape[0] - 1
        t = a[:, 0]
        start = window_start(t, end)
        t_end = float(t[end])
        if t_end - t[start] < MIN_SPAN_S:
            self._fallback_line(a)
            return
        tt = t[start : end + 1]
        xy = a[start : end + 1, 1:]
        scale = t_end - float(tt[0])
        coef = fit_window(tt, xy, t_end, scale, self.fit)
        grid = eval_poly(coef, GRID_OFFSETS / scale)
        self._gps_v = math.hypot(coef[1, 0], coef[1, 1]) / scale
        psi = math.atan2(coef[1, 1], coef[1, 0])
        if timer is not None:
            c0 = lap(timer, "resample_positions", c0)
        self._run_net(grid, t_end, float(tt[0]), psi, coef, scale, timer, c0)

    def _run_net(
        self,
        grid: np.ndarray,
        t_end: float,
        t0: float,
        psi: float,
        coef: np.ndarray,
        scale: float,
        timer: StageTimer | None,
        c0: int,
    ) -> None:
        ax, ay, yaw = imu_on_grid(self._imu, t0, t_end, coef, scale, self.fit)
        if timer is not None:
            c0 = lap(timer, "resample_imu", c0)
        x = self._net_input(grid, ax, ay, yaw, psi, coef, scale)
        if timer is not None:
            c0 = lap(timer, "features", c0)
        out = self.net.run(x)
        if timer is not None:
            c0 = lap(timer, "inference", c0)
        d0, d1 = self._net_output(out, grid, psi)
        pts = self._pts
        pts[:N_STEPS] = grid
        pts[N_STEPS, 0] = grid[-1, 0] + d0
        pts[N_STEPS, 1] = grid[-1, 1] + d1
        self._grid = grid
        self._pred = pts[N_STEPS].copy()
        cf = self._final.fit(pts)
        self._c = tuple(cf[:, 0].tolist() + cf[:, 1].tolist())
        self._t_end = t_end
        self._mode = "net"
        self.steps += 1
        if timer is not None:
            lap(timer, "current_position_fit", c0)

    def _net_input(
        self,
        grid: np.ndarray,
        ax: np.ndarray,
        ay: np.ndarray,
        yaw: np.ndarray,
        psi: float,
        coef: np.ndarray,
        scale: float,
    ) -> np.ndarray:
        """The network's input window from the grid [m], IMU on the grid and heading [rad]
        (and, for a ``fix_offset`` model, the newest fix: the fix buffer's last row)."""
        fix = None
        if self.fix_offset:
            row = self._fix.a[self._fix.n - 1]
            fix = (float(row[1]), float(row[2]))
        return features_one(grid, ax, ay, yaw, psi, self.frame, self._x, fix)

    def _net_output(self, out: np.ndarray, grid: np.ndarray, psi: float) -> tuple[float, float]:
        """World displacement [m] from the newest grid point to 200 ms later, from the
        network's output (in the model's frame)."""
        d0, d1 = float(out[0]), float(out[1])
        if self.frame == "heading":
            c, s = math.cos(psi), math.sin(psi)
            d0, d1 = c * d0 - s * d1, s * d0 + c * d1
        return d0, d1

    def _bridge_step(self) -> None:
        """No fix for 0.2 s after the grid: the prediction becomes the newest sample."""
        t_new = self._t_end + DT
        self._fix.append((t_new, float(self._pred[0]), float(self._pred[1])))
        grid = np.vstack([self._grid[1:], self._pred])
        coef = self._grid_fit.fit(grid)  # in s = t - t_new [s], scale 1
        psi = math.atan2(coef[1, 1], coef[1, 0])
        t = self._fix.view()[:, 0]
        start = window_start(t, self._fix.n - 1)
        t0 = min(float(t[start]), t_new - MIN_SPAN_S)
        self._run_net(grid, t_new, t0, psi, coef, 1.0, None, 0)
        self.bridge_steps += 1

    def _fallback_line(self, a: np.ndarray) -> None:
        t = a[:, 0]
        if t.size == 1:
            self._line = (float(t[0]), float(a[0, 1]), 0.0, float(a[0, 2]), 0.0)
        else:
            c = fit_poly(t, a[:, 1:], float(t[-1]), 1.0, degree=1)
            self._line = (
                float(t[-1]),
                float(c[0, 0]),
                float(c[1, 0]),
                float(c[0, 1]),
                float(c[1, 1]),
            )
        self._gps_v = math.hypot(self._line[2], self._line[4]) if t.size > 1 else math.nan
        self._mode = "line"

    # ------------------------------------------------------------------ queries
    def _stationary(self) -> bool:
        v = self._can_v if self._can_v is not None else self._gps_v
        return v == v and abs(v) < STILL_SPEED_MPS

    def _estimate(self, t: float) -> tuple[float, float]:
        if self._mode == "net":
            n = 0
            while t > self._t_end + DT + 1e-9 and n < MAX_BRIDGE_STEPS:
                self._bridge_step()
                n += 1
            s = t - self._t_end
            c = self._c
            return (
                ((c[3] * s + c[2]) * s + c[1]) * s + c[0],
                ((c[7] * s + c[6]) * s + c[5]) * s + c[4],
            )
        if self._mode == "line":
            t0, x0, vx, y0, vy = self._line
            return x0 + vx * (t - t0), y0 + vy * (t - t0)
        return math.nan, math.nan

    def position_at(self, t: float) -> tuple[float, float]:
        if self._stationary():
            if self._hold is None or self._hold[0] != self._hold[0]:  # never hold "unknown"
                self._hold = self._estimate(t)
            return self._hold
        self._hold = None
        return self._estimate(t)
