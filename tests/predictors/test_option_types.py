"""Options mean what they say: every predictor option is parsed by its declared type, in one
place (:mod:`posbench.predictors.option_types`), for ``--set``, the Python API and tuning
files alike. A yes/no option takes true/false (and yes/no, on/off, 1/0), never any text for
yes; choices are checked against their list; JSON that does not parse and fields of the
wrong kind are named, in one line."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from helpers import assert_one_error_line, bench

from posbench.errors import UsageError
from posbench.predictors.catalogue import BUILT_IN
from posbench.predictors.kalman.inputs import AccelInput
from posbench.predictors.option_types import (
    BOOL_TEXT,
    OptionValueError,
    declared_types,
    parse_options,
    parse_value,
    takes_text,
)
from posbench.predictors.registry import available, create, predictor_class

#: built-in predictors that can be built without a model file of the user's
BUILDABLE = [n for n, e in available().items() if e.source == BUILT_IN and n != "lstm-authors"]
OFF = ("no", "false", "0", "off")


def _yes_no_options() -> list[tuple[str, str]]:
    """(predictor, option) for every yes/no option of every built-in predictor."""
    out = []
    for name in sorted(n for n, e in available().items() if e.source == BUILT_IN):
        for option, tp in declared_types(predictor_class(name)).items():
            if tp is bool:
                out.append((name, option))
    return out


YES_NO = _yes_no_options()


def test_every_built_in_yes_no_option_is_found():
    # the banks' flat switches and the hybrid's gate among them: the sweep below is not empty
    found = set(YES_NO)
    assert {("kf", "use_imu"), ("kf", "use_speed"), ("ekf", "use_imu_yaw")} <= found
    assert {("hybrid", "gate"), ("kf-paper", "resample")} <= found
    assert len(found) >= 10


@pytest.mark.parametrize(("name", "option"), YES_NO)
def test_bench_run_set_no_false_0_off_mean_off_and_maybe_is_refused(name, option):
    """`bench run --set NAME.OPTION=VALUE` as the command line gives it (a bare word is
    text): the plan resolves no/false/0/off to False, 'maybe' to one error line."""
    from posbench.pipeline.plan import RunOptions, plan_run
    from posbench.replay.predictor_options import parse_set

    for word in OFF:
        sets, given = parse_set([f"{name}.{option}={word}"])
        plan = plan_run(RunOptions(predictors=(name,), options=sets), given)
        assert plan.config.predictor_options[name][option] is False, word
    sets, given = parse_set([f"{name}.{option}=maybe"])
    with pytest.raises(UsageError) as e:
        plan_run(RunOptions(predictors=(name,), options=sets), given)
    assert str(e.value).startswith(f"--set {name}.{option}=maybe: {name}.{option} takes true or")


@pytest.mark.parametrize("word", [*OFF, "False", "NO", "Off"])
def test_off_words_parse_to_false(word):
    assert parse_value("x", word, bool) is False


@pytest.mark.parametrize("word", ["true", "yes", "on", "1", "True", "YES", 1, True])
def test_on_words_parse_to_true(word):
    assert parse_value("x", word, bool) is True


@pytest.mark.parametrize("value", ["maybe", "", "2", [1], {"x": 1}, 2, 0.5, None, "nein"])
def test_anything_else_is_not_a_yes_no(value):
    with pytest.raises(OptionValueError) as e:
        parse_value("use_imu", value, bool)
    assert str(e.value).startswith(f"use_imu takes {BOOL_TEXT}, not ")


def test_use_imu_no_runs_as_use_imu_false_and_not_as_the_default():
    """The case of the issue: `--set kf.use_imu=no` ran with the IMU on, to the bit the
    default's answers. Now its answers are use_imu=false's, and differ from the default's."""
    import posbench

    def future_mean(**kf: Any) -> float:
        run = posbench.run(
            predictors="kf", options={"kf": kf} if kf else {}, synthetic_duration_s=60, out=None
        )
        return run.results["predictors"]["kf"]["future"]["mean_m"]

    no, false, default = future_mean(use_imu="no"), future_mean(use_imu=False), future_mean()
    assert no == false
    assert no != default


def test_the_gps_conditions_a_predictor_takes_are_the_runs():
    from posbench.config import GPS_CONDITIONS
    from posbench.predictors.base import GPS_CONDITIONS as DECLARED

    assert DECLARED == GPS_CONDITIONS


def test_hybrid_gate_no_is_off_and_bogus_condition_refused():
    off = create("hybrid", None, gate="no")
    assert off.gate is False
    with pytest.raises(OptionValueError, match="gps_condition takes one of 'native', 'none'"):
        create("hybrid", None, gps_condition="bogus")
    assert create("hybrid", None, gps_condition="rtk").gps_condition == "rtk"


def test_nested_fields_parsed_by_their_types():
    kf = create("kf", None, imu={"gate": 0, "bias_tau_s": 0})
    assert kf.inputs["imu"].gate == 0.0
    with pytest.raises(OptionValueError, match=r"^imu\.gate takes a number, not true$"):
        create("kf", None, imu={"gate": True})
    with pytest.raises(OptionValueError, match=r"^imu has no field 'gat'; AccelInput's fields"):
        create("kf", None, imu={"gat": 1})
    with pytest.raises(OptionValueError, match=r"^gnss takes an object of GnssInput fields"):
        create("kf", None, gnss=None)
    # an input switched off by null where it may be (imu), an instance as it is
    assert create("kf", None, imu=None).inputs["imu"] is None
    mine = dataclasses.replace(AccelInput(), sigma=0.5)
    assert create("kf", None, imu=mine).inputs["imu"].sigma == 0.5


def test_numbers_lists_and_choices():
    assert parse_value("j", 4, float) == 4.0 and isinstance(parse_value("j", 4, float), float)
    assert parse_value("j", np.float64(2.5), float) == 2.5
    assert parse_value("n", np.int64(3), int) == 3
    assert parse_value("n", 3.0, int) == 3
    for bad, what in [("4", "a number"), (True, "a number"), (float("nan"), "a finite number")]:
        with pytest.raises(OptionValueError, match=f"takes {what}"):
            parse_value("j", bad, float)
    from collections.abc import Sequence
    from typing import Literal

    assert parse_value("h", [1, 3], Sequence[float]) == (1.0, 3.0)
    assert parse_value("h", [], Sequence[float]) == ()
    with pytest.raises(OptionValueError, match=r"^h\[1\] takes a number, not 'x'$"):
        parse_value("h", [1, "x"], Sequence[float])
    with pytest.raises(OptionValueError, match="takes a list of numbers, not 4"):
        parse_value("h", 4, Sequence[float])
    fit = Literal["closed", "lbfgs"]
    assert parse_value("fit", "lbfgs", fit) == "lbfgs"
    assert takes_text(fit | None) == "one of 'closed', 'lbfgs' or null"
    with pytest.raises(OptionValueError, match="fit takes one of 'closed', 'lbfgs', not 'x'"):
        parse_value("fit", "x", fit)


def test_undeclared_options_pass_as_given():
    class Plain:
        def __init__(self, a=1, **kw):  # no annotations: nothing to parse by
            pass

    assert parse_options(Plain, {"a": "no", "b": [1]}) == {"a": "no", "b": [1]}


@pytest.mark.parametrize("name", BUILDABLE)
def test_every_built_in_is_built_with_its_defaults_parsed(name):
    """Each built-in's declared defaults are values of their own declared types."""
    from posbench.predictors.registry import constructor_options

    cls = predictor_class(name)
    defaults, _ = constructor_options(cls)
    types = declared_types(cls)
    import inspect

    given = {k: v for k, v in defaults.items() if v is not inspect.Parameter.empty}
    parse_options(cls, {k: v for k, v in given.items() if k in types})
    assert create(name, None) is not None


# -------------------------------------------------------------- the command line
CASES = [
    ("kf.use_imu=maybe", "--set kf.use_imu=maybe: kf.use_imu takes true or false"),
    ("hybrid.gate=[1]", "hybrid.gate takes true or false (also yes/no, on/off, 1/0), not [1]"),
    ('hybrid.gate={"x":1}', "hybrid.gate takes true or false"),
    ('kf.imu={"gate": true}', "kf.imu.gate takes a number, not true"),
    ("hybrid.gps_condition=bogus", "takes one of 'native', 'none', 'rtk', 'consumer' or null"),
    ('kf.imu={"gate": 0', "is not valid JSON (Expecting ',' delimiter at column 11)"),
    ("kf.gnss=null", "kf.gnss takes an object of GnssInput fields"),
    ("lstm.fit=nope", "lstm.fit takes one of 'closed', 'lbfgs', not 'nope'"),
    ("kf.jerk_psds=4", "kf.jerk_psds takes a list of numbers, not 4"),
]


@pytest.mark.parametrize(("setting", "needle"), CASES, ids=[c[0] for c in CASES])
def test_bad_values_are_one_error_line(tmp_path, setting, needle):
    name = setting.split(".")[0]
    r = bench("run", "-p", name, "--set", setting, "--out", tmp_path / "o", cwd=tmp_path)
    line = assert_one_error_line(r, needle)
    assert "AttributeError" not in line and "Traceback" not in r.stderr
    assert not (tmp_path / "o").exists()


def test_bench_predictors_says_what_each_option_takes():
    r = bench("predictors", "hybrid", "--json")
    assert r.returncode == 0, r.stderr
    import json

    opts = {o["name"]: o for o in json.loads(r.stdout)["predictors"][0]["options"]}
    assert opts["gate"]["takes"] == BOOL_TEXT
    assert opts["gps_condition"]["takes"].startswith("one of 'native'")
    r = bench("predictors", "lstm", columns=120)
    assert "one of 'closed', 'lbfgs'" in r.stdout


def test_an_empty_horizon_list_means_what_it_says():
    """`kf.horizons_s=[]` is no horizon scoring (one fix ahead only), as the option's doc
    says: the bank keeps no horizon, and under outages it answers otherwise than with the
    default (1, 3) s (without outages no query lies a second past its fix: the same)."""
    import posbench

    assert create("kf", None, horizons_s=[]).horizons_s == ()
    assert create("ekf", None, horizons_s=[]).horizons_s == ()

    def now_mean(**kf: Any) -> float:
        run = posbench.run(
            predictors="kf",
            options={"kf": kf} if kf else {},
            synthetic_duration_s=120,
            dropouts="outages",
            out=None,
        )
        return run.results["predictors"]["kf"]["now"]["mean_m"]

    assert now_mean(horizons_s=[]) != now_mean()
