"""The restricted unpickler: NumPy arrays and plain containers load, code does not run."""

from __future__ import annotations

import collections
import os
import pickle
import subprocess
from pathlib import Path

import numpy as np
import pytest

from posbench.scenarios.errors import DataError
from posbench.scenarios.safe_pickle import safe_load, safe_loads


class _Evil:
    """Pickles to a call of ``func(*args)``."""

    def __init__(self, func: object, *args: object) -> None:
        self.func, self.args = func, args

    def __reduce__(self) -> tuple:
        return (self.func, self.args)


def _marker_cmd(marker: Path) -> str:
    return f"echo pwned > {marker}"


@pytest.mark.parametrize("protocol", [0, 2, 5])
def test_numpy_and_containers_round_trip(protocol: int) -> None:
    obj = {
        0: {
            "a": np.arange(12, dtype=np.float64).reshape(4, 3),
            "b": [1, 2, 3],
            "c": ("1649851224769416716", 0.13, -0.15),
            "theta": -1.35,
        },
        "ints": np.array([1649851224583364005, 1649851224680112130], dtype=np.int64),
        "f32": np.linspace(0, 1, 5, dtype=np.float32),
        "fortran": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
        "scalar": np.float64(2.5),
        "i32": np.int32(7),
        "od": collections.OrderedDict([("x", 1), ("y", 2)]),
        "set": {1, 2},
        "fs": frozenset({3}),
        "cx": 1 + 2j,
        "none": None,
        "bytes": b"\x00\x01",
    }
    got = safe_loads(pickle.dumps(obj, protocol=protocol), "mem")
    np.testing.assert_array_equal(got[0]["a"], obj[0]["a"])
    assert got[0]["a"].dtype == np.float64 and got[0]["c"] == obj[0]["c"]
    np.testing.assert_array_equal(got["ints"], obj["ints"])
    assert got["ints"].dtype == np.int64 and got["f32"].dtype == np.float32
    np.testing.assert_array_equal(got["fortran"], obj["fortran"])
    assert got["scalar"] == 2.5 and isinstance(got["scalar"], np.float64)
    assert got["i32"] == 7 and isinstance(got["i32"], np.int32)
    assert got["od"] == obj["od"] and isinstance(got["od"], collections.OrderedDict)
    assert got["set"] == {1, 2} and got["fs"] == frozenset({3}) and got["cx"] == 1 + 2j
    assert got["bytes"] == b"\x00\x01"


@pytest.mark.parametrize("protocol", [0, 2])
def test_numpy1_core_names_are_mapped(protocol: int) -> None:
    """Pickles from NumPy 1.x name ``numpy.core.*``; they load under NumPy 2 too."""
    arr = np.arange(6.0).reshape(3, 2)
    data = pickle.dumps({"gt": arr, "s": np.float64(1.5)}, protocol=protocol)
    if b"numpy._core" in data:  # running under NumPy 2: write the NumPy 1 spelling
        data = data.replace(b"numpy._core", b"numpy.core")
    assert b"numpy.core" in data and b"numpy._core" not in data
    got = safe_loads(data, "mem")
    np.testing.assert_array_equal(got["gt"], arr)
    assert got["s"] == 1.5


def test_frombuffer_name_admitted() -> None:
    """The route pickles use ``numpy.core.numeric._frombuffer`` (protocol 5 buffers)."""
    arr = np.arange(16.0).reshape(8, 2)
    data = pickle.dumps(arr, protocol=5)
    assert b"_frombuffer" in data
    np.testing.assert_array_equal(safe_loads(data, "mem"), arr)


@pytest.mark.parametrize("protocol", [0, 2, 5])
def test_os_system_refused_and_not_run(tmp_path: Path, protocol: int) -> None:
    marker = tmp_path / "pwned.txt"
    evil = tmp_path / "evil.pickle"
    evil.write_bytes(
        pickle.dumps(
            {"ok": np.zeros(3), "x": _Evil(os.system, _marker_cmd(marker))}, protocol=protocol
        )
    )
    with pytest.raises(DataError) as ei:
        safe_load(evil)
    msg = str(ei.value)
    assert msg.startswith(str(evil)) and "refused to unpickle" in msg
    assert f"'{os.system.__module__}.system'" in msg
    assert not marker.exists()


@pytest.mark.parametrize(
    "func", [eval, exec, getattr, __import__, subprocess.Popen, np.load, collections.namedtuple]
)
def test_other_callables_refused(tmp_path: Path, func: object) -> None:
    marker = tmp_path / "m"
    data = pickle.dumps(_Evil(func, f"open({str(marker)!r}, 'w')"), protocol=2)
    with pytest.raises(DataError, match="refused to unpickle"):
        safe_loads(data, tmp_path / "x.pickle")
    assert not marker.exists()


def test_truncated_and_garbage(tmp_path: Path) -> None:
    data = pickle.dumps({"a": np.arange(100.0)}, protocol=5)
    with pytest.raises(DataError, match="truncated or corrupt"):
        safe_loads(data[: len(data) // 2], "half.pickle")
    with pytest.raises(DataError, match="truncated or corrupt"):
        safe_loads(b"not a pickle at all", "junk.pickle")
    with pytest.raises(DataError, match="cannot read"):
        safe_load(tmp_path / "missing.pickle")
