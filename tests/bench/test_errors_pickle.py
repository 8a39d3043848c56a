"""Every project exception survives pickling - the way it crosses from a worker process
back to the driver - with its message and attributes (a DataError that could not be
unpickled broke the whole process pool: a 67-line BrokenProcessPool traceback)."""

from __future__ import annotations

import ast
import importlib
import multiprocessing
import pickle
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from helpers import module_name, source_files


def samples() -> dict[str, list[BaseException]]:
    """Instances of each project exception class, by ``module.Class``."""
    from posbench.errors import UsageError
    from posbench.figures.style import NothingToPlot
    from posbench.predictors.lstm.core_graph import NoCoreGraph
    from posbench.predictors.option_types import OptionValueError
    from posbench.predictors.registry import PredictorError
    from posbench.recording.web import ServeError
    from posbench.replay.executors import ExecutorError
    from posbench.scenarios.errors import DataError

    return {
        "posbench.scenarios.errors.DataError": [
            DataError("/data/drive.bag", "topic /fix: no messages"),
            DataError(Path("/data/x.csv"), "line 3: 'a' is not a number"),
            DataError(None, "truth: need at least 2 samples"),
        ],
        "posbench.errors.UsageError": [UsageError("--horizon must be more than 0 s; got -1")],
        "posbench.replay.executors.ExecutorError": [
            ExecutorError("cannot start Ray at auto: no cluster")
        ],
        "posbench.figures.style.NothingToPlot": [NothingToPlot("no query with a known speed")],
        "posbench.recording.web.ServeError": [
            ServeError("the rerun web viewer stopped on its own (exit 1): port 9090 in use")
        ],
        "posbench.predictors.registry.PredictorError": [
            PredictorError("nosuchmodule:X: no module named 'nosuchmodule'")
        ],
        "posbench.predictors.option_types.OptionValueError": [
            OptionValueError("use_imu", "maybe", "true or false"),
            OptionValueError("imu.gat", 1, "an object", "imu has no field 'gat'"),
        ],
        "posbench.predictors.lstm.core_graph.NoCoreGraph": [
            NoCoreGraph("not a speed-form posbench model (no net.res_std)")
        ],
    }


def _is_exception_base(base: ast.expr, known: set[str]) -> bool:
    name = base.attr if isinstance(base, ast.Attribute) else getattr(base, "id", "")
    return name.endswith(("Error", "Exception")) or name in known


def project_exception_classes() -> set[str]:
    """``module.Class`` of every class in the project's packages deriving from an
    exception (by its base's name: ``...Error`` / ``...Exception`` / another found one)."""
    found: dict[str, str] = {}
    for f in source_files():
        module = module_name(f)
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ClassDef) and any(
                _is_exception_base(b, set(found)) for b in node.bases
            ):
                found[node.name] = f"{module}.{node.name}"
    return set(found.values())


def _assert_same(a: BaseException, b: BaseException) -> None:
    assert type(a) is type(b)
    assert str(a) == str(b)
    assert a.args == b.args
    assert vars(a) == vars(b)


def test_every_project_exception_class_is_covered():
    """A new exception class must be added to :func:`samples` (and so be tested here)."""
    assert project_exception_classes() == set(samples())


@pytest.mark.parametrize("key", sorted(samples()))
def test_round_trip_through_pickle(key):
    module, name = key.rsplit(".", 1)
    cls = getattr(importlib.import_module(module), name)
    for exc in samples()[key]:
        assert type(exc) is cls
        for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
            _assert_same(exc, pickle.loads(pickle.dumps(exc, protocol=protocol)))


def test_data_error_keeps_path_and_detail():
    from posbench.scenarios.errors import DataError

    back = pickle.loads(pickle.dumps(DataError(Path("/d/x.bag"), "bad topic")))
    assert (back.path, back.detail, str(back)) == ("/d/x.bag", "bad topic", "/d/x.bag: bad topic")


def raise_sample(key: str, i: int) -> None:
    """Worker side: build the exception in the worker process and raise it."""
    raise samples()[key][i]


@pytest.mark.parametrize("method", ["fork", "spawn"])
def test_raised_in_a_worker_process_arrives_intact(method):
    if method not in multiprocessing.get_all_start_methods():
        pytest.skip(f"no {method} start method here")
    cases = [(k, i) for k, v in sorted(samples().items()) for i in range(len(v))]
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context(method)) as pool:
        for key, i in cases:
            with pytest.raises(BaseException) as info:
                pool.submit(raise_sample, key, i).result(timeout=60)
            _assert_same(info.value, samples()[key][i])


def test_runner_with_two_workers_raises_the_data_error(tmp_path):
    """A drive that loads but cannot be prepared: its DataError reaches the caller of the
    parallel runner as itself, not as a broken process pool."""
    from posbench.config import RunConfig
    from posbench.replay.runner import run
    from posbench.scenarios.errors import DataError
    from posbench.scenarios.loaders import load

    drives = []
    for k in (1, 2):
        f = tmp_path / f"drive{k}.csv"
        f.write_text(one_sample_truth_csv())
        drives += load(f)
    with pytest.raises(DataError, match="truth: need at least 2 samples"):
        run(drives, RunConfig(predictors=("cv",), gps_profile="rtk"), workers=2)


def one_sample_truth_csv() -> str:
    """A drive whose truth has one sample: it loads, but no GPS can be drawn from it
    (``--gps-profile rtk``; by default its own fixes are fed)."""
    rows = ["stream,t,x,y"] + [f"gps,{0.2 * i:.1f},{2 * i},0" for i in range(50)]
    return "\n".join([*rows, "truth,5.0,10,0"]) + "\n"
