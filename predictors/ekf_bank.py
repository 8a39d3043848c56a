"""``ekf``: the CTRA extended Kalman filter as a bank that adapts to its data.

Members: :class:`~posbench.predictors.ekf.CtraEkf` at each pair of white-jerk and
white-yaw-acceleration densities of ``noise_levels`` (steady motorway to city
manoeuvres), each once *aided* (IMU yaw rate, acceleration and yaw, wheel speed; the
filter estimates their biases, offset and scale) and once on fixes alone.
:class:`~posbench.predictors.bank.ModelBank` answers with the member whose predictions
of the fixes have the highest recent likelihood, so an input that does not help on a
drive, or a process noise that does not fit it, is weighed down by the drive's own
innovations (see :mod:`posbench.predictors.kf_bank`, the same idea for ``kf``). Fixes
that state no accuracy have their noise estimated from the fixes themselves
(``fix_noise_memory``, 30 fixes).

Units: seconds, metres, radians, local ENU.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from posbench.predictors._geometry import check_config
from posbench.predictors.bank import ModelBank
from posbench.predictors.ekf import CtraEkf
from posbench.predictors.kf_bank import HORIZONS_S

#: (jerk_psd [m^2/s^5], yaw_acc_psd [rad^2/s^3]) of the members, gentle to agile
NOISE_LEVELS = ((0.5, 0.03), (4.0, 0.3), (32.0, 3.0), (256.0, 10.0))


class EkfBank(ModelBank):
    """CTRA EKFs, aided and fixes-only at several process noises, selected by the
    likelihood of their fix predictions (module docstring).

    Args:
        noise_levels: ``(jerk_psd, yaw_acc_psd)`` pairs, one pair of members each.
        jerk_psd, yaw_acc_psd: one level instead of ``noise_levels`` (a bank of one aided
            and one fixes-only member; the one not given takes
            :class:`~posbench.predictors.ekf.CtraEkf`'s default), e.g. ``--set ekf.jerk_psd=4``.
        memory_fixes: exponential memory of the member scores, in fixes.
        horizons_s, horizon_memory: the horizons [s] members are also scored at and the
            memory of those scores (:class:`~posbench.predictors.bank.ModelBank`); ``[]``:
            one fix ahead only.
        cov_scale: ``covariance_at`` reports ``cov_scale`` x the selected member's covariance.
        **options: any other :class:`~posbench.predictors.ekf.CtraEkf` option, passed to
            every member (``gps_sigma``, ``gps_sigma_scale``, ``yaw_rate_sigma``, ...).
    """

    name = "ekf"

    def __init__(
        self,
        noise_levels: Sequence[Sequence[float]] = NOISE_LEVELS,
        jerk_psd: float | None = None,
        yaw_acc_psd: float | None = None,
        memory_fixes: float = 20.0,
        cov_scale: float = 1.0,
        horizons_s: Sequence[float] = HORIZONS_S,
        horizon_memory: float = 10.0,
        **options: float | bool,
    ) -> None:
        if jerk_psd is not None or yaw_acc_psd is not None:
            noise_levels = (
                (
                    2.0 if jerk_psd is None else jerk_psd,
                    0.1 if yaw_acc_psd is None else yaw_acc_psd,
                ),
            )
        levels = tuple((float(j), float(w)) for j, w in noise_levels)
        check_config(
            "ekf", **{f"noise_levels[{i}]": (j, 1e-9, 1e6) for i, (j, _) in enumerate(levels)}
        )
        options.setdefault("fix_noise_memory", 30.0)  # members check the options
        self._options = dict(options)
        self.noise_levels = levels
        members, labels = [], []
        for j, w in levels:
            for aided in (True, False):
                # a fixes-only member takes no sensor input at all
                extra = {} if aided else {"use_imu": False, "use_speed": False}
                # any CtraEkf option (from --set): CtraEkf checks the names and values
                member_options: dict[str, Any] = {**options, **extra}
                members.append(CtraEkf(jerk_psd=j, yaw_acc_psd=w, **member_options))
                labels.append(f"{'aided' if aided else 'fixes'} j{j:g} w{w:g}")
        super().__init__(
            members,
            labels,
            memory_fixes=memory_fixes,
            cov_scale=cov_scale,
            horizons_s=horizons_s,
            horizon_memory=horizon_memory,
        )

    def config(self) -> dict:
        member = {
            k: v
            for k, v in self.members[0].config().items()
            if k not in ("jerk_psd", "yaw_acc_psd", "cov_scale")
        }
        return {
            **member,
            **self._options,
            "noise_levels": [list(p) for p in self.noise_levels],
            "memory_fixes": self.memory_fixes,
            "cov_scale": self.cov_scale,
            "horizons_s": list(self.horizons_s),
            "horizon_memory": self.horizon_memory,
        }
