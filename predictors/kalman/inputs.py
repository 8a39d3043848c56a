"""The sensor inputs of the Kalman filters, as small frozen option types, and the flat
names that address them.

A filter is composed, not configured: one motion model (constant acceleration,
:mod:`posbench.metrics.ca_model`; CTRA, :mod:`~posbench.predictors.kalman.ctra_model`)
plus the sensor inputs it takes, each an option type below or
``None`` (a fixes-only filter takes the GNSS alone). Each type holds its own defaults and
checks its own ranges (``check(owner)``); a bank builds its members from the same input
objects, so no option is declared twice. Stone Soup's split (a transition model, one
updater per sensor) is the model.

Flat names. ``--set kf.gps_sigma=0.5``, the keys of a tuning file, ``config()`` and the
hybrid's saved prior all use flat names (``gps_sigma``, ``accel_sigma``, ``use_imu``, ...).
:class:`FlatNames` maps each to an input's field (``use_<input>=False`` drops the input),
so those names keep working while the code reads ``filter.imu.sigma``.

Units: seconds, metres, radians; sigma are per-axis 1-sigma.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from posbench.predictors._geometry import check_config
from posbench.predictors.kalman.gnss_noise import GnssNoise
from posbench.scenarios.errors import DataError

KMH = 1.0 / 3.6


@dataclass(frozen=True)
class GnssInput:
    """GNSS fixes (:class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`).

    Attributes:
        sigma: fix noise [m] per axis for fixes that state no accuracy.
        sigma_scale: a fix stating ``s`` [m] states a total of ``(sigma_scale * s)^2``.
        noise_memory: > 0: estimate the white noise from the fixes (this many fixes of
            memory); it replaces ``sigma`` for fixes that state none and splits a statement.
        split: take a statement as the total of a white part (weighs the fix) and a slow
            part (added to the reported covariance); needs ``noise_memory`` > 0.
    """

    sigma: float = 0.3
    sigma_scale: float = 1.0
    noise_memory: float = 0.0
    split: bool = True

    def check(self, owner: str) -> None:
        check_config(
            owner,
            gps_sigma=(self.sigma, 1e-4, 1e3),
            gps_sigma_scale=(self.sigma_scale, 1e-3, 1e3),
            fix_noise_memory=(self.noise_memory, 0.0, 1e6),
        )

    def noise(self) -> GnssNoise:
        """A new noise model of this input's fixes."""
        return GnssNoise(self.sigma, self.sigma_scale, self.noise_memory, self.split)


@dataclass(frozen=True)
class AccelInput:
    """IMU acceleration, vehicle frame, as an observation of the filter's acceleration.

    Attributes:
        sigma: noise [m/s^2] per axis (the floor of the adapted noise).
        bias_tau_s: > 0: estimate the vehicle-frame bias from the IMU's velocity changes
            against a fixes-only filter, with this forgetting time [s].
        gate: > 0: skip an update whose 2-D innovation NIS exceeds this.
        noise_tau_s: > 0: adapt the noise to the innovations over this many seconds.
    """

    sigma: float = 0.3
    bias_tau_s: float = 0.0
    gate: float = 0.0
    noise_tau_s: float = 0.0

    def check(self, owner: str) -> None:
        check_config(
            owner,
            accel_sigma=(self.sigma, 1e-4, 1e3),
            accel_bias_tau_s=(self.bias_tau_s, 0.0, 1e6),
            imu_gate=(self.gate, 0.0, 1e9),
            imu_noise_tau_s=(self.noise_tau_s, 0.0, 1e6),
        )

    @property
    def robust(self) -> bool:
        """Whether the update removes a bias, adapts its noise or is gated."""
        return self.bias_tau_s > 0.0 or self.gate > 0.0 or self.noise_tau_s > 0.0


@dataclass(frozen=True)
class HeadingInput:
    """Where the IMU states no yaw, how the IMU and the wheel speed get a heading.

    Attributes:
        from_fixes: from fix chords longer than their noise, carried by the gyro
            (:class:`~posbench.predictors.kalman.course_heading.CourseHeading`), used while its
            standard deviation is below ``sigma_max`` [rad]; False: from the velocity state above
            ``min_speed`` [m/s].
    """

    from_fixes: bool = False
    sigma_max: float = 0.15
    min_speed: float = 1.0

    def check(self, owner: str) -> None:
        check_config(
            owner,
            heading_sigma_max=(self.sigma_max, 1e-4, 3.2),
            heading_min_speed=(self.min_speed, 0.0, 100.0),
        )


@dataclass(frozen=True)
class SpeedInput:
    """Wheel or CAN speed along the heading.

    Attributes:
        sigma: noise [m/s]. rel_sigma: scale error (tyre radius), a fraction of v.
        stop_speed: below this [m/s] a zero-velocity update of both components.
    """

    sigma: float = 0.2
    rel_sigma: float = 0.03
    stop_speed: float = 0.15 * KMH

    def check(self, owner: str) -> None:
        check_config(
            owner,
            speed_sigma=(self.sigma, 1e-4, 1e3),
            speed_rel_sigma=(self.rel_sigma, 0.0, 1.0),
            stop_speed=(self.stop_speed, 0.0, 10.0),
        )


class FlatNames:
    """Flat option names <-> fields of a filter's inputs (module docstring).

    Args:
        fields: flat name -> (input name, field name); a field name of None marks the
            switch ``use_<input>``: False drops the input (None), True keeps or restores it.
    """

    def __init__(self, fields: Mapping[str, tuple[str, str | None]]) -> None:
        self.fields = dict(fields)

    def compose(
        self,
        owner: str,
        inputs: Mapping[str, Any],
        defaults: Mapping[str, Any],
        flat: Mapping[str, Any],
    ) -> dict[str, Any]:
        """``inputs`` (input name -> option object or None) with the ``flat`` options
        applied; ``defaults`` (input name -> option object) restores an input switched on.
        An unknown flat name raises TypeError, as an unknown keyword would."""
        out = {key: self._input(owner, key, value, defaults) for key, value in inputs.items()}
        changes: dict[str, dict[str, Any]] = {}
        switches: dict[str, bool] = {}
        for name, value in flat.items():
            if name not in self.fields:
                raise TypeError(f"{owner}: unexpected option {name!r}")
            key, field = self.fields[name]
            if field is None:
                switches[key] = bool(value)
            else:
                changes.setdefault(key, {})[field] = value
        for key, on in switches.items():
            if not on:
                out[key] = None
            elif out[key] is None:
                out[key] = defaults[key]
        for key, fields in changes.items():
            base = out[key] if out[key] is not None else defaults[key]
            changed = dataclasses.replace(base, **fields)
            changed.check(owner)
            if out[key] is not None:
                out[key] = changed
        for value in out.values():
            if value is not None and hasattr(value, "check"):
                value.check(owner)
        return out

    @staticmethod
    def _input(owner: str, key: str, value: Any, defaults: Mapping[str, Any]) -> Any:
        """An input as given: an option object, None, or a mapping of its fields (``--set
        kf.imu='{"gate": 0}'``) applied to its default."""
        if not isinstance(value, Mapping):
            return value
        base = defaults[key]
        fields = {f.name for f in dataclasses.fields(base)}
        unknown = sorted(set(value) - fields)
        if unknown:
            known = ", ".join(sorted(fields))
            msg = f"{owner}: {key} has no field {unknown[0]!r}; its fields: {known}"
            raise DataError(None, msg)
        return dataclasses.replace(base, **value)

    def types(self, defaults: Mapping[str, Any]) -> dict[str, Any]:
        """Each flat name's declared type: its input field's (``bool`` for a ``use_``
        switch), as :func:`posbench.predictors.option_types.parse_options` reads them."""
        from posbench.predictors.option_types import field_types

        return {
            name: bool if field is None else field_types(defaults[key].__class__)[field]
            for name, (key, field) in self.fields.items()
        }

    def flatten(self, inputs: Mapping[str, Any], defaults: Mapping[str, Any]) -> dict[str, Any]:
        """The flat options of ``inputs`` (a dropped input: its ``use_`` switch False and
        its fields at ``defaults``), in the order of :attr:`fields`."""
        out: dict[str, Any] = {}
        for name, (key, field) in self.fields.items():
            value = inputs[key]
            if field is None:
                out[name] = value is not None
            else:
                out[name] = getattr(value if value is not None else defaults[key], field)
        return out


@dataclass(frozen=True)
class CtraImuInput:
    """The IMU of the CTRA EKF: yaw rate, longitudinal acceleration and yaw, each the
    signal plus a sensor bias the filter estimates.

    Attributes:
        yaw_rate_sigma: gyro noise [rad/s]. accel_sigma: longitudinal accel noise [m/s^2].
        yaw_sigma: IMU yaw noise [rad]; use_yaw: False ignores the IMU's yaw.
        accel_bias_psd, gyro_bias_psd: random-walk densities of the biases
            [m^2/s^5, rad^2/s^3]; accel_bias_sigma0, gyro_bias_sigma0, yaw_offset_sigma0:
            their prior 1-sigma [m/s^2, rad/s, rad].
    """

    yaw_rate_sigma: float = 0.02
    accel_sigma: float = 0.3
    yaw_sigma: float = 0.05
    use_yaw: bool = True
    accel_bias_psd: float = 1e-3
    gyro_bias_psd: float = 1e-6
    accel_bias_sigma0: float = 0.5
    gyro_bias_sigma0: float = 0.01
    yaw_offset_sigma0: float = 0.1

    def check(self, owner: str) -> None:
        check_config(
            owner,
            yaw_rate_sigma=(self.yaw_rate_sigma, 1e-6, 1e3),
            accel_sigma=(self.accel_sigma, 1e-4, 1e3),
            yaw_sigma=(self.yaw_sigma, 1e-6, 10.0),
            accel_bias_psd=(self.accel_bias_psd, 0.0, 1e6),
            gyro_bias_psd=(self.gyro_bias_psd, 0.0, 1e6),
            accel_bias_sigma0=(self.accel_bias_sigma0, 1e-9, 1e3),
            gyro_bias_sigma0=(self.gyro_bias_sigma0, 1e-9, 1e3),
            yaw_offset_sigma0=(self.yaw_offset_sigma0, 1e-9, 10.0),
        )


@dataclass(frozen=True)
class CtraSpeedInput:
    """Wheel speed of the CTRA EKF, ``(1 + k_v) v`` with a scale error k_v it estimates.

    Attributes:
        sigma: noise [m/s]. rel_sigma: scale error as noise, a fraction of v.
        scale_sigma0: prior 1-sigma of k_v.
    """

    sigma: float = 0.2
    rel_sigma: float = 0.03
    scale_sigma0: float = 0.05

    def check(self, owner: str) -> None:
        check_config(
            owner,
            speed_sigma=(self.sigma, 1e-4, 1e3),
            speed_rel_sigma=(self.rel_sigma, 0.0, 1.0),
            speed_scale_sigma0=(self.scale_sigma0, 1e-9, 10.0),
        )


#: one linear CA filter's inputs by default (the kf bank's aided members take
#: :data:`~posbench.predictors.kalman.kf.BANK_INPUTS`)
KF_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(),
    "imu": AccelInput(),
    "heading": HeadingInput(),
    "speed": SpeedInput(),
}
#: flat option names (``--set kf.X``, tuning files, ``config()``) -> the inputs' fields
KF_FLAT = FlatNames(
    {
        "gps_sigma": ("gnss", "sigma"),
        "gps_sigma_scale": ("gnss", "sigma_scale"),
        "fix_noise_memory": ("gnss", "noise_memory"),
        "gps_split": ("gnss", "split"),
        "use_imu": ("imu", None),
        "accel_sigma": ("imu", "sigma"),
        "accel_bias_tau_s": ("imu", "bias_tau_s"),
        "imu_gate": ("imu", "gate"),
        "imu_noise_tau_s": ("imu", "noise_tau_s"),
        "heading_from_fixes": ("heading", "from_fixes"),
        "heading_sigma_max": ("heading", "sigma_max"),
        "heading_min_speed": ("heading", "min_speed"),
        "use_speed": ("speed", None),
        "speed_sigma": ("speed", "sigma"),
        "speed_rel_sigma": ("speed", "rel_sigma"),
        "stop_speed": ("speed", "stop_speed"),
    }
)

#: one CTRA EKF's inputs by default (the ekf bank's members take these)
EKF_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(),
    "imu": CtraImuInput(),
    "speed": CtraSpeedInput(),
}
#: flat option names (``--set ekf.X``, tuning files, ``config()``) -> the inputs' fields
EKF_FLAT = FlatNames(
    {
        "gps_sigma": ("gnss", "sigma"),
        "gps_sigma_scale": ("gnss", "sigma_scale"),
        "fix_noise_memory": ("gnss", "noise_memory"),
        "gps_split": ("gnss", "split"),
        "use_imu": ("imu", None),
        "yaw_rate_sigma": ("imu", "yaw_rate_sigma"),
        "accel_sigma": ("imu", "accel_sigma"),
        "yaw_sigma": ("imu", "yaw_sigma"),
        "use_imu_yaw": ("imu", "use_yaw"),
        "accel_bias_psd": ("imu", "accel_bias_psd"),
        "gyro_bias_psd": ("imu", "gyro_bias_psd"),
        "accel_bias_sigma0": ("imu", "accel_bias_sigma0"),
        "gyro_bias_sigma0": ("imu", "gyro_bias_sigma0"),
        "yaw_offset_sigma0": ("imu", "yaw_offset_sigma0"),
        "use_speed": ("speed", None),
        "speed_sigma": ("speed", "sigma"),
        "speed_rel_sigma": ("speed", "rel_sigma"),
        "speed_scale_sigma0": ("speed", "scale_sigma0"),
    }
)
