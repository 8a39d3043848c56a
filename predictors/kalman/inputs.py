"""The sensor inputs of the Kalman filters, as small frozen option types, and the flat
names that address them.

A filter is composed, not configured: one motion model (constant acceleration,
:mod:`posbench.metrics.ca_model`; CTRA, :mod:`~posbench.predictors.kalman.ctra_model`)
plus the sensor inputs it takes, each an option type below or
``None`` (a fixes-only filter takes the GNSS alone). Each field of a type is declared
once (:func:`option`): default, flat name, meaning, unit and range; from that declaration
come the type's range check (``check(owner)``), the flat names (:meth:`FlatNames.of`), the
types ``--set`` parses by and the meanings ``bench predictors`` and the Predictor options
page show. A bank builds its members from the same input objects. Stone Soup's split (a
transition model, one updater per sensor) is the model.

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


def option(
    default: Any,
    flat: str,
    doc: str,
    unit: str = "",
    low: float | None = None,
    high: float | None = None,
) -> Any:
    """A field of an input type, declared once: its ``default``, its ``flat`` name (``--set``,
    tuning files, ``config()``), what it means (``doc``), its ``unit`` and, for a number, the
    range ``[low, high]`` :meth:`InputType.check` holds it to."""
    meta: dict[str, Any] = {"flat": flat, "doc": doc, "unit": unit, "range": None}
    if low is not None and high is not None:
        meta["range"] = (low, high)
    return dataclasses.field(default=default, metadata=meta)


@dataclass(frozen=True)
class OptionDoc:
    """What one flat option is: its meaning, unit and range (None: a yes/no or no range)."""

    doc: str
    unit: str
    range: tuple[float, float] | None

    def text(self) -> str:
        """One line: meaning, then unit and range where they are declared."""
        parts = [self.doc]
        if self.range is not None:
            low, high = self.range
            parts.append(f"in [{low:g}, {high:g}]" + (f" {self.unit}" if self.unit else ""))
        elif self.unit:
            parts.append(self.unit)
        return "; ".join(parts)


class InputType:
    """Base of the input types: :meth:`check` and :meth:`option_docs` read the fields'
    declarations (:func:`option`)."""

    def check(self, owner: str) -> None:
        """Raise :class:`~posbench.scenarios.errors.DataError` naming ``owner`` and the flat
        name of a field outside its declared range."""
        checks = {
            f.metadata["flat"]: (getattr(self, f.name), *f.metadata["range"])
            for f in dataclasses.fields(self)  # type: ignore[arg-type]
            if f.metadata.get("range") is not None
        }
        check_config(owner, **checks)

    @classmethod
    def option_docs(cls) -> dict[str, OptionDoc]:
        """Each field's declaration by the field's name."""
        return {
            f.name: OptionDoc(f.metadata["doc"], f.metadata["unit"], f.metadata["range"])
            for f in dataclasses.fields(cls)  # type: ignore[arg-type]
        }


@dataclass(frozen=True)
class GnssInput(InputType):
    """GNSS fixes (:class:`~posbench.predictors.kalman.gnss_noise.GnssNoise`)."""

    sigma: float = option(
        0.3, "gps_sigma", "fix noise per axis for fixes that state no accuracy", "m", 1e-4, 1e3
    )
    sigma_scale: float = option(
        1.0,
        "gps_sigma_scale",
        "a fix stating s states a total of (gps_sigma_scale s)^2",
        "",
        1e-3,
        1e3,
    )
    noise_memory: float = option(
        0.0,
        "fix_noise_memory",
        "> 0: estimate the white noise from the fixes, with this memory; it replaces "
        "gps_sigma for fixes that state none and splits a statement",
        "fixes",
        0.0,
        1e6,
    )
    split: bool = option(
        True,
        "gps_split",
        "take a statement as a white part (weighs the fix) plus a slow part (added to the "
        "reported covariance); needs fix_noise_memory > 0",
    )

    def noise(self) -> GnssNoise:
        """A new noise model of this input's fixes."""
        return GnssNoise(self.sigma, self.sigma_scale, self.noise_memory, self.split)


@dataclass(frozen=True)
class AccelInput(InputType):
    """IMU acceleration, vehicle frame, as an observation of the filter's acceleration."""

    sigma: float = option(
        0.3, "accel_sigma", "noise per axis (the floor of the adapted noise)", "m/s^2", 1e-4, 1e3
    )
    bias_tau_s: float = option(
        0.0,
        "accel_bias_tau_s",
        "> 0: estimate the vehicle-frame bias from the IMU's velocity changes against a "
        "fixes-only filter, with this forgetting time",
        "s",
        0.0,
        1e6,
    )
    gate: float = option(
        0.0, "imu_gate", "> 0: skip an update whose 2-D innovation NIS exceeds this", "", 0.0, 1e9
    )
    noise_tau_s: float = option(
        0.0,
        "imu_noise_tau_s",
        "> 0: adapt the noise to the innovations over this time",
        "s",
        0.0,
        1e6,
    )

    @property
    def robust(self) -> bool:
        """Whether the update removes a bias, adapts its noise or is gated."""
        return self.bias_tau_s > 0.0 or self.gate > 0.0 or self.noise_tau_s > 0.0


@dataclass(frozen=True)
class HeadingInput(InputType):
    """Where the IMU states no yaw, how the IMU and the wheel speed get a heading."""

    from_fixes: bool = option(
        False,
        "heading_from_fixes",
        "from fix chords longer than their noise, carried by the gyro, while its standard "
        "deviation is below heading_sigma_max; no: from the velocity above heading_min_speed",
    )
    sigma_max: float = option(
        0.15, "heading_sigma_max", "the most a course heading may be unsure", "rad", 1e-4, 3.2
    )
    min_speed: float = option(
        1.0,
        "heading_min_speed",
        "the speed above which the velocity gives a heading",
        "m/s",
        0.0,
        100.0,
    )


@dataclass(frozen=True)
class SpeedInput(InputType):
    """Wheel or CAN speed along the heading."""

    sigma: float = option(0.2, "speed_sigma", "noise", "m/s", 1e-4, 1e3)
    rel_sigma: float = option(
        0.03, "speed_rel_sigma", "scale error (tyre radius), a fraction of v", "", 0.0, 1.0
    )
    stop_speed: float = option(
        0.15 * KMH,
        "stop_speed",
        "below this speed, a zero-velocity update of both components",
        "m/s",
        0.0,
        10.0,
    )


def stopped(v: Any, stop_speed: Any) -> Any:
    """Whether a wheel speed ``v`` [m/s] (a float, or arrays elementwise) is a standstill:
    below ``stop_speed`` [m/s], it is a zero-velocity update of both components; at or
    above, a speed along the heading. The one statement of the rule (the kf's rows compile
    it, the kf bank, the gradient tuning and the reference call it)."""
    return abs(v) < stop_speed


@dataclass(frozen=True)
class CtraImuInput(InputType):
    """The IMU of the CTRA EKF: yaw rate, longitudinal acceleration and yaw, each the
    signal plus a sensor bias the filter estimates."""

    yaw_rate_sigma: float = option(0.02, "yaw_rate_sigma", "gyro noise", "rad/s", 1e-6, 1e3)
    accel_sigma: float = option(
        0.3, "accel_sigma", "longitudinal acceleration noise", "m/s^2", 1e-4, 1e3
    )
    yaw_sigma: float = option(0.05, "yaw_sigma", "IMU yaw noise", "rad", 1e-6, 10.0)
    use_yaw: bool = option(True, "use_imu_yaw", "no: ignore the IMU's yaw")
    accel_bias_psd: float = option(
        1e-3, "accel_bias_psd", "random-walk density of the accelerometer bias", "m^2/s^5", 0.0, 1e6
    )
    gyro_bias_psd: float = option(
        1e-6, "gyro_bias_psd", "random-walk density of the gyro bias", "rad^2/s^3", 0.0, 1e6
    )
    accel_bias_sigma0: float = option(
        0.5, "accel_bias_sigma0", "prior 1-sigma of the accelerometer bias", "m/s^2", 1e-9, 1e3
    )
    gyro_bias_sigma0: float = option(
        0.01, "gyro_bias_sigma0", "prior 1-sigma of the gyro bias", "rad/s", 1e-9, 1e3
    )
    yaw_offset_sigma0: float = option(
        0.1, "yaw_offset_sigma0", "prior 1-sigma of the IMU yaw offset", "rad", 1e-9, 10.0
    )


@dataclass(frozen=True)
class CtraSpeedInput(InputType):
    """Wheel speed of the CTRA EKF, ``(1 + k_v) v`` with a scale error k_v it estimates."""

    sigma: float = option(0.2, "speed_sigma", "noise", "m/s", 1e-4, 1e3)
    rel_sigma: float = option(
        0.03, "speed_rel_sigma", "scale error as noise, a fraction of v", "", 0.0, 1.0
    )
    scale_sigma0: float = option(
        0.05, "speed_scale_sigma0", "prior 1-sigma of the scale error k_v", "", 1e-9, 10.0
    )


class FlatNames:
    """Flat option names <-> fields of a filter's inputs (module docstring).

    Args:
        fields: flat name -> (input name, field name); a field name of None marks the
            switch ``use_<input>``: False drops the input (None), True keeps or restores it.
    """

    def __init__(
        self,
        fields: Mapping[str, tuple[str, str | None]],
        docs: Mapping[str, OptionDoc] | None = None,
    ) -> None:
        self.fields = dict(fields)
        self._docs = dict(docs or {})

    @classmethod
    def of(cls, inputs: Mapping[str, type[InputType]], optional: tuple[str, ...]) -> FlatNames:
        """The flat names the input types declare (:func:`option`), input by input in
        ``inputs``' order; an input in ``optional`` has a ``use_<input>`` switch first."""
        fields: dict[str, tuple[str, str | None]] = {}
        docs: dict[str, OptionDoc] = {}
        for key, tp in inputs.items():
            if key in optional:
                fields[f"use_{key}"] = (key, None)
                docs[f"use_{key}"] = OptionDoc(
                    f"no: the aided members go without the {key}", "", None
                )
            for f in dataclasses.fields(tp):  # type: ignore[arg-type]
                fields[f.metadata["flat"]] = (key, f.name)
                docs[f.metadata["flat"]] = tp.option_docs()[f.name]
        return cls(fields, docs)

    def docs(self) -> dict[str, OptionDoc]:
        """Each flat name's declaration (meaning, unit, range), where the types declare one."""
        return dict(self._docs)

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


#: one linear CA filter's inputs by default (the kf bank's aided members take
#: :data:`~posbench.predictors.kalman.kf.BANK_INPUTS`)
KF_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(),
    "imu": AccelInput(),
    "heading": HeadingInput(),
    "speed": SpeedInput(),
}
#: flat option names (``--set kf.X``, tuning files, ``config()``) -> the inputs' fields
KF_FLAT = FlatNames.of(
    {"gnss": GnssInput, "imu": AccelInput, "heading": HeadingInput, "speed": SpeedInput},
    optional=("imu", "speed"),
)

#: one CTRA EKF's inputs by default (the ekf bank's members take these)
EKF_INPUTS: dict[str, Any] = {
    "gnss": GnssInput(),
    "imu": CtraImuInput(),
    "speed": CtraSpeedInput(),
}
#: flat option names (``--set ekf.X``, tuning files, ``config()``) -> the inputs' fields
EKF_FLAT = FlatNames.of(
    {"gnss": GnssInput, "imu": CtraImuInput, "speed": CtraSpeedInput}, optional=("imu", "speed")
)
