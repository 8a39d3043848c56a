"""Property-based fuzzing (hypothesis, bounded): loaders, the cubic fits, the predictors and
the model files never fail with anything but the documented clear errors, and give no NaN
from finite input."""

from __future__ import annotations

import math
import pickle
import shutil

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from posbench.predictors import registry
from posbench.predictors.cubic import fit_cubic
from posbench.predictors.lstm.resample import fit_poly
from posbench.replay.gps_outliers import GatedPredictor
from posbench.scenarios.errors import DataError
from posbench.scenarios.safe_pickle import safe_loads

FUZZ = settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

# ---------------------------------------------------------------------------- loaders
CELL = st.one_of(
    st.sampled_from(
        [
            "",
            "nan",
            "inf",
            "-1",
            "0",
            "1e300",
            "abc",
            "1.5",
            '"',
            "1e9",
            "gps",
            "imu",
            "speed",
            "truth",
            " ",
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet=',.-e0123456789 "x', max_size=6),
)
HEADERS = st.lists(
    st.sampled_from(
        ["stream", "t", "t_ns", "x", "y", "lat", "lon", "ax", "ay", "v", "yaw", "accuracy", "junk"]
    ),
    min_size=1,
    max_size=7,
)


@FUZZ
@given(header=HEADERS, rows=st.lists(st.lists(CELL, min_size=0, max_size=8), max_size=15))
def test_table_loader_random_csv(tmp_path_factory, header, rows):
    from posbench.scenarios.loaders.table import load_table

    p = tmp_path_factory.mktemp("csv") / "f.csv"
    p.write_text(",".join(header) + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    try:
        d = load_table(p)
    except DataError as e:
        assert str(p) in str(e) and "\n" not in str(e).strip()
        return
    assert len(d.gps) > 0 or d.truth is not None
    assert np.all(np.isfinite(d.gps.t)) and np.all(np.isfinite(d.gps.x))


LEAF = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5), st.binary(max_size=5)
)
OBJ = st.recursive(
    LEAF,
    lambda c: st.one_of(
        st.lists(c, max_size=4),
        st.tuples(c, c),
        st.dictionaries(st.text(max_size=3), c, max_size=3),
    ),
    max_leaves=12,
)


@FUZZ
@given(
    obj=OBJ,
    cuts=st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)), max_size=4),
    truncate=st.integers(0, 10_000),
    protocol=st.sampled_from([0, 2, 4]),
)
def test_safe_unpickler_random_and_mutated_pickles(obj, cuts, truncate, protocol):
    data = bytearray(pickle.dumps({"a": np.arange(4.0), "o": obj}, protocol=protocol))
    for pos, val in cuts:
        data[pos % len(data)] = val
    data = bytes(data[: max(1, len(data) - truncate % len(data))])
    try:
        safe_loads(data, "fuzz.pickle")
    except DataError as e:
        assert "fuzz.pickle" in str(e)


@FUZZ
@given(data=st.binary(max_size=200))
def test_safe_unpickler_random_bytes(data):
    try:
        safe_loads(data, "junk.pickle")
    except DataError as e:
        assert "junk.pickle" in str(e)


@FUZZ
@given(
    windows=st.dictionaries(
        st.integers(0, 5),
        st.dictionaries(
            st.sampled_from(["tstamps", "ground_truth", "ACCEL", "theta", "X", "Y"]),
            st.one_of(
                st.lists(st.integers(0, 2**62), max_size=8),
                st.lists(st.lists(st.floats(-1e3, 1e3), min_size=2, max_size=2), max_size=8),
                st.lists(st.tuples(st.text(max_size=4), st.floats(), st.floats()), max_size=4),
                st.floats(),
            ),
            max_size=6,
        ),
        max_size=4,
    )
)
def test_route_pickle_loader_random_contents(tmp_path_factory, windows):
    from posbench.scenarios.loaders.aslan import load_aslan_pickle

    p = tmp_path_factory.mktemp("pk") / "r.pickle"
    p.write_bytes(pickle.dumps(windows, protocol=2))
    try:
        d = load_aslan_pickle(p)
    except DataError as e:
        assert str(p) in str(e)
        return
    assert np.all(np.isfinite(d.gps.t))


# ---------------------------------------------------------------------------- cubic fits
@FUZZ
@given(
    n=st.integers(1, 12),
    offset=st.sampled_from([0.0, 1e3, 1.7e9]),
    gap=st.sampled_from([1e-9, 1e-6, 1e-3, 0.2]),
    slope=st.floats(-50, 50),
    noise=st.floats(0, 1),
    seed=st.integers(0, 100),
)
def test_cubic_fits_are_finite(n, offset, gap, slope, noise, seed):
    rng = np.random.default_rng(seed)
    t = offset + np.cumsum(np.full(n, gap) * rng.uniform(1.0, 1.01, n))
    y = np.stack([slope * (t - t[0]), 3.0 * (t - t[0])], axis=1)  # collinear
    y += rng.normal(0, noise, y.shape)
    f = fit_cubic(t, y)
    assert np.all(np.isfinite(f.coef))
    assert np.all(np.isfinite(f(t[-1] + 0.2)))
    scale = max(float(t[-1] - t[0]), 1e-3)
    c = fit_poly(t, y, float(t[-1]), scale)
    assert np.all(np.isfinite(c))


# ---------------------------------------------------------------------------- predictors
EVENTS = st.lists(
    st.tuples(
        st.sampled_from(["gps", "imu", "speed"]),
        st.floats(0.001, 2.0),  # time step [s]
        st.floats(-1e4, 1e4),
        st.floats(-1e4, 1e4),
        st.floats(-50, 50),
        st.floats(-4, 4),
    ),
    min_size=1,
    max_size=60,
)


@pytest.mark.parametrize("name", ["cv", "poly", "kf", "kf-paper", "ekf", "lstm"])
@pytest.mark.parametrize("gated", [False, True])
def test_predictors_on_random_event_streams(name, gated):
    pred = registry.create(name)
    pred = GatedPredictor(pred) if gated else pred

    @settings(max_examples=25, deadline=None)
    @given(events=EVENTS)
    def run(events):
        pred.reset()
        t, seen_fix = 0.0, False
        for kind, dt, a, b, c, d in events:
            t += dt
            if kind == "gps":
                pred.observe_gps(t, a, b)
                seen_fix = True
            elif kind == "imu":
                pred.observe_imu(t, c, d, d, d / 4)
            else:
                pred.observe_speed(t, abs(c))
            for h in (0.0, 0.2):
                x, y = pred.position_at(t + h)
                if seen_fix:
                    assert math.isfinite(x) and math.isfinite(y), (kind, t, x, y)
                else:
                    assert (math.isnan(x) and math.isnan(y)) or name == "ekf"

    run()


# ---------------------------------------------------------------------------- model files
@pytest.fixture()
def model_copy(tmp_path):
    from posbench.predictors.lstm.predictor import bundled_model

    src = bundled_model()
    shutil.copy(src, tmp_path / "model.onnx")
    shutil.copy(src.with_suffix(".json"), tmp_path / "model.json")
    return tmp_path / "model.onnx"


@FUZZ
@given(cut=st.integers(1, 4000), flips=st.lists(st.integers(0, 10**6), max_size=5))
def test_corrupted_onnx_is_a_one_line_error_naming_the_file(model_copy, cut, flips):
    from posbench.predictors.lstm.predictor import LstmPredictor

    data = bytearray(model_copy.read_bytes())
    bad = model_copy.with_name("bad.onnx")
    for f in flips:
        data[f % len(data)] ^= 0xFF
    bad.write_bytes(bytes(data[: max(1, len(data) - cut)]))
    shutil.copy(model_copy.with_suffix(".json"), bad.with_suffix(".json"))
    try:
        p = LstmPredictor(model=str(bad))
        for i in range(20):  # it loaded: it must also run
            p.observe_gps(0.2 * i, 2.0 * i, 0.0)
            p.position_at(0.2 * i + 0.2)
    except DataError as e:
        assert str(bad) in str(e) and "\n" not in str(e)


@pytest.mark.parametrize("edit", ["frame", "output", "input_shape", "format", "not_json"])
def test_mismatched_model_json_is_a_one_line_error_naming_the_file(model_copy, edit):
    import json

    from posbench.predictors.lstm.predictor import LstmPredictor

    js = model_copy.with_suffix(".json")
    info = json.loads(js.read_text())
    if edit == "frame":
        info["frame"] = "sideways"
    elif edit == "output":
        info["output"] = "no_such_output"
    elif edit == "input_shape":
        info["input_shape"] = [1, 9, 4]
    elif edit == "format":
        info["format"] = "other"
    text = "{not json" if edit == "not_json" else json.dumps(info)
    js.write_text(text)
    with pytest.raises(DataError) as e:
        p = LstmPredictor(model=str(model_copy))
        for i in range(20):
            p.observe_gps(0.2 * i, 2.0 * i, 0.0)
            p.position_at(0.2 * i + 0.2)
    msg = str(e.value)
    assert ("model.json" in msg or "model.onnx" in msg) and "\n" not in msg
