"""The configuration of one ``bench run``: everything that determines its figures."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from posbench.scenarios.drive import Drive
    from posbench.scenarios.stored_drive import DriveInfo

#: the GPS conditions a drive can be replayed under (and a predictor tuned for): ``native``
#: (the recording's own fixes) or a profile of fixes simulated from the truth; the same as
#: :data:`posbench.predictors.base.GPS_CONDITIONS`, which a predictor's option declares (this
#: module may not import the predictors; tests/predictors/test_option_types.py holds them equal)
GPS_CONDITIONS = ("native", "none", "rtk", "consumer")
#: ``--gps-profile`` choices: a condition for every drive, or ``auto`` (one per drive)
AUTO_PROFILE = "auto"
GPS_PROFILES = (AUTO_PROFILE, *GPS_CONDITIONS)
#: the simulated profile ``auto`` gives a drive whose fixes are the truth's own positions
AUTO_SIMULATED = "rtk"
#: how results.json names the package's own tuning file (the same on every installation)
BUILT_IN_TUNING = "posbench/predictors/tuned.json"
#: the predictors of a run that names none (``bench run``, :func:`posbench.run`)
DEFAULT_PREDICTORS = ("cv", "poly", "kf", "kf-paper", "ekf", "lstm")


@dataclass(frozen=True)
class RunConfig:
    """What to replay and how.

    Attributes:
        predictors: registry names, in report order.
        horizon_s: look-ahead of the "future" query after each fix [s] (paper: 0.2).
        now_step_s: period of the "now" (current position) queries [s].
        gps_profile: which fixes a drive with truth is fed and scored on: ``auto`` (the
            default) its own receiver's (``native``) where the fixes and the truth come from
            different sources, and ``rtk`` fixes drawn from the truth where the fixes *are*
            the truth (KITTI's OXTS, the synthetic drives: ``Drive.fixes_from_truth``);
            ``native`` or a simulated profile (``none`` exact, ``rtk`` ~2 cm, ``consumer``
            ~1 m correlated) for every drive. Drives without truth always use their own
            fixes (:func:`gps_condition`).
        gps_latency_s: receiver latency of the drawn fixes [s].
        intervals: fix-interval distribution of the drawn fixes (``aslan`` = the paper's routes).
        dropouts: GPS dropout profile (``none``, ``random:p``, ``outages``, ``outage:L``,
            ``outage-lengths``).
        seed: master seed; each drive's seed derives from it and the drive's name only,
            so results do not depend on the number of workers.
        exclude_poor_truth: skip drives whose truth is flagged poor (median accuracy > 1 m).
        tuning: a tuning file of the user's (``bench tune --out``) whose entries replace the
            package's for the predictors and GPS conditions it holds; None: the package's.
        use_tuned: start from the tuned parameters of ``predictors/tuned.json`` for the drive's
            GPS condition (``bench tune`` writes them); False = the predictors' physical defaults.
        predictor_options: per-predictor constructor overrides, e.g.
            ``{"lstm-authors": {"model": p}}``.
        gate: put every predictor behind the GPS outlier gate
            (:class:`posbench.replay.gps_outliers.FixGate`, default limits): a fix implying
            impossible motion is dropped before the predictor sees it (bridged like a missing
            fix) and counted. False = the paper's ungated behaviour. Scoring is unaffected: the
            reference is never gated.
    """

    predictors: tuple[str, ...] = ("cv", "kf")
    horizon_s: float = 0.2
    now_step_s: float = 0.05
    gps_profile: str = AUTO_PROFILE
    gps_latency_s: float = 0.0
    intervals: str = "aslan"
    dropouts: str = "none"
    seed: int = 0
    exclude_poor_truth: bool = True
    use_tuned: bool = True
    predictor_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    gate: bool = True
    tuning: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["predictors"] = list(self.predictors)
        return d


#: the predictor the others are compared with when no baseline is named (if it is in the run)
DEFAULT_BASELINE = "kf"


def default_baseline(predictors: Iterable[str]) -> str | None:
    """:data:`DEFAULT_BASELINE` when it is among ``predictors``, else None (no paired
    comparison)."""
    return DEFAULT_BASELINE if DEFAULT_BASELINE in tuple(predictors) else None


def drive_seed(seed: int, drive_name: str) -> int:
    """A per-drive seed from the master seed and the drive's name (stable across runs/workers)."""
    h = hashlib.sha256(f"{seed}:{drive_name}".encode()).digest()
    return int.from_bytes(h[:4], "little")


def gps_condition(cfg: RunConfig, drive: Drive | DriveInfo) -> str:
    """The GPS condition (one of :data:`GPS_CONDITIONS`) ``drive`` (or its description) is
    replayed under:
    ``native`` (its own recorded fixes) for a drive without truth; for one with truth the
    run's profile, where ``auto`` is ``native`` when the fixes come from a receiver of their
    own and :data:`AUTO_SIMULATED` when they are the truth's positions or were simulated
    from it (``Drive.fixes_from_truth``)."""
    if not drive.has_truth:
        return "native"
    if cfg.gps_profile == AUTO_PROFILE:
        return AUTO_SIMULATED if drive.fixes_from_truth else "native"
    if cfg.gps_profile == "native" and drive.fix_count == 0:
        return AUTO_SIMULATED  # no fixes of its own to feed
    return cfg.gps_profile


def fixes_description(condition: str) -> str:
    """What a run fed and scored under GPS ``condition``, in words for the terminal and
    report.md."""
    if condition == "native":
        return "the recording's own receiver"
    return f"simulated `{condition}` fixes drawn from the truth"
