"""The Kalman filters composed of sensor inputs (issue 35): every flat option name that
``--set``, tuning files and saved priors use still works and lands in its input; a
fixes-only member takes no sensor input; ``config()`` round-trips."""

from __future__ import annotations

import pytest
from reference_filters.banks import member_bank
from reference_filters.ctra_ekf import CtraEkf
from reference_filters.linear_kalman import LinearKalman

from posbench.predictors.kalman.ekf import EkfBank
from posbench.predictors.kalman.inputs import EKF_FLAT, KF_FLAT, AccelInput, GnssInput, SpeedInput
from posbench.predictors.kalman.kf import KalmanBank
from posbench.predictors.registry import constructor_options
from posbench.scenarios.errors import DataError

#: the flat options the filters took before they were composed (their old signatures)
OLD_KF = (
    "gps_sigma accel_sigma speed_sigma speed_rel_sigma use_speed stop_speed "
    "heading_min_speed gps_sigma_scale use_imu heading_from_fixes heading_sigma_max "
    "accel_bias_tau_s imu_gate imu_noise_tau_s fix_noise_memory gps_split"
).split()
OLD_EKF = (
    "gps_sigma yaw_rate_sigma accel_sigma yaw_sigma speed_sigma speed_rel_sigma use_imu_yaw "
    "use_imu use_speed accel_bias_psd gyro_bias_psd accel_bias_sigma0 gyro_bias_sigma0 "
    "yaw_offset_sigma0 speed_scale_sigma0 gps_sigma_scale fix_noise_memory gps_split"
).split()


def test_every_old_flat_name_is_still_an_option():
    assert set(OLD_KF) <= set(KF_FLAT.fields)
    assert set(OLD_EKF) <= set(EKF_FLAT.fields)
    for cls, names in ((LinearKalman, OLD_KF), (KalmanBank, OLD_KF), (EkfBank, OLD_EKF)):
        options, any_keyword = constructor_options(cls)
        assert not any_keyword  # unknown names are refused, not swallowed
        assert set(names) <= set(options), cls


def test_flat_names_land_in_their_inputs():
    f = LinearKalman(gps_sigma=0.7, accel_sigma=0.4, imu_gate=9.0, stop_speed=0.1)
    assert f.gnss == GnssInput(sigma=0.7)
    assert f.imu == AccelInput(sigma=0.4, gate=9.0)
    assert f.speed == SpeedInput(stop_speed=0.1)
    g = LinearKalman(use_imu=False, use_speed=False)
    assert g.imu is None and g.speed is None
    e = CtraEkf(yaw_rate_sigma=0.05, use_imu_yaw=False, speed_scale_sigma0=0.1)
    assert e.imu is not None and e.imu.yaw_rate_sigma == 0.05 and not e.imu.use_yaw
    assert e.speed is not None and e.speed.scale_sigma0 == 0.1


@pytest.mark.parametrize(
    "make",
    [
        lambda: LinearKalman(2.0, gps_sigma=0.4, use_speed=False, heading_from_fixes=True),
        lambda: CtraEkf(4.0, 0.3, accel_sigma=0.5, use_imu=False),
    ],
)
def test_config_round_trips(make):
    f = make()
    assert type(f)(**f.config()).config() == f.config()


def test_bank_options_reach_the_aided_members_and_fixes_only_members_take_no_sensor():
    kb = KalmanBank(accel_sigma=0.6, use_speed=False, gps_sigma=0.5)
    for m, label in zip(member_bank(kb).members, kb.labels, strict=True):
        assert m.gnss.sigma == 0.5  # type: ignore[attr-defined]
        if label.startswith("aided"):
            assert m.imu.sigma == 0.6 and m.speed is None  # type: ignore[attr-defined]
        else:
            assert m.imu is None and m.speed is None  # type: ignore[attr-defined]
    eb = EkfBank(yaw_rate_sigma=0.03)
    for m, label in zip(member_bank(eb).members, eb.labels, strict=True):
        if label.startswith("aided"):
            assert m.imu.yaw_rate_sigma == 0.03  # type: ignore[attr-defined]
        else:
            assert m.imu is None and m.speed is None  # type: ignore[attr-defined]
    assert kb.config()["accel_sigma"] == 0.6 and kb.config()["use_speed"] is False


def test_an_input_given_as_its_fields():
    kb = KalmanBank(imu={"gate": 0.0})
    assert kb.inputs["imu"] == AccelInput(sigma=0.3, bias_tau_s=30.0, gate=0.0, noise_tau_s=5.0)
    with pytest.raises(DataError, match="imu has no field 'gatex'"):
        KalmanBank(imu={"gatex": 0.0})
    with pytest.raises(DataError, match="accel_sigma=-1"):
        LinearKalman(accel_sigma=-1)
    with pytest.raises(TypeError, match="unexpected option 'bogus'"):
        LinearKalman(bogus=1)


@pytest.mark.parametrize("bank", [KalmanBank, EkfBank])
def test_every_flat_option_is_declared_once_with_its_meaning_and_range(bank):
    """Each flat option's meaning, unit and range come from its input field's declaration:
    the range is the one ``check`` enforces (a value just outside is refused, naming the
    flat option), and ``bench predictors`` shows the meaning."""
    docs = bank.flat_option_docs()
    assert list(docs) == list(bank.flat_names.fields)
    assert all(d.doc for d in docs.values())
    ranged = {name: d.range for name, d in docs.items() if d.range is not None}
    assert len(ranged) >= 12
    for name, (low, high) in ranged.items():
        bank(**{name: low})  # the ends are accepted
        bank(**{name: high})
        for outside in (low - 1.0, high * 2.0):
            with pytest.raises(DataError, match=rf"{bank.name}: {name}=.* must be in"):
                bank(**{name: outside})
    from posbench.cli.predictors import predictor_info

    info = predictor_info(bank.name, options=True)
    meanings = {o["name"]: o["meaning"] for o in info["options"]}
    assert meanings["gps_sigma"] == docs["gps_sigma"].text()
    assert "[0.0001, 1000] m" in meanings["gps_sigma"]
