"""What a network step of the ``lstm`` (and ``hybrid``) predictors reports: its stages in
order, the stage-timer hook and a recorder for it, and :class:`LstmStep`, the newest step
copied out of a predictor's state."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from time import perf_counter_ns

import numpy as np

#: the stages of a network step, in the order :attr:`LstmPredictor.stage_timer` receives them:
#: ``resample_positions`` (fix bookkeeping, window search, position cubic, 8-point grid,
#: heading), ``resample_imu`` (IMU cubic on the grid or its GPS stand-ins), ``features``
#: (the network input), ``inference`` (the ONNX run), ``current_position_fit`` (network
#: output to a world displacement, cubic through grid and prediction, state update)
STAGES = ("resample_positions", "resample_imu", "features", "inference", "current_position_fit")
#: the stages of a *fused* network step (``step="fused"``, the default): ``resample`` (fix
#: bookkeeping, window search, both cubics in one solve, their values on the grid),
#: ``features``, ``inference``, ``current_position_fit`` (as in :data:`STAGES`)
FUSED_STAGES = ("resample", "features", "inference", "current_position_fit")

#: a stage-timer hook: called with (stage name, duration [ns])
StageTimer = Callable[[str, int], None]


def lap(timer: StageTimer, stage: str, c0: int) -> int:
    """Report the stage that began at ``c0`` [ns]; the clock after the report (so the
    hook's own time is charged to no stage)."""
    timer(stage, perf_counter_ns() - c0)
    return perf_counter_ns()


class StageRecorder:
    """A :data:`StageTimer` that keeps every duration [ns] per stage name.

    ``ns[stage]`` lists the durations in the order received; :meth:`clear` empties them.
    """

    def __init__(self) -> None:
        self.ns: dict[str, list[int]] = {s: [] for s in STAGES}

    def __call__(self, stage: str, duration_ns: int) -> None:
        self.ns.setdefault(stage, []).append(duration_ns)

    def clear(self) -> None:
        for v in self.ns.values():
            v.clear()


@dataclass(frozen=True, eq=False)
class LstmStep:
    """One network step of :class:`LstmPredictor`, copied out of its state (read-only arrays).

    Attributes:
        grid: (8, 2) resampled input positions [m, ENU], oldest first, 200 ms apart,
            the last at ``t_fix``.
        pred: (2,) the predicted position [m, ENU] at ``t_fix + horizon_s``.
        t_fix: time [s] of the newest grid point: the fix the step ran on (for a bridging
            step, the pseudo-fix that stood in for a missing one).
        horizon_s: how far [s] past ``t_fix`` the network predicts (0.2 s).
        bridged: True if a missing fix was bridged (the step ran inside ``position_at``
            on the previous prediction, not on a real fix).
    """

    grid: np.ndarray
    pred: np.ndarray
    t_fix: float
    horizon_s: float
    bridged: bool
