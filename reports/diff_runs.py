"""Are two saved runs the same to the bit? ``python reports/diff_runs.py OLD NEW``

Compares ``results.json`` of two ``bench run`` folders exactly (floats with ``==``, no
tolerance), skipping what differs between any two runs of the same code: latencies (keys
ending ``_us``), the command line, git commit, package versions, and the list of files
written. ``traces.parquet`` is compared column by column, bit for bit (NaN equal to NaN),
when both runs have one (the committed reports in ``reports/`` keep none).
Prints every difference (up to 50) and exits 1 if there is one, else prints ``same`` and
exits 0. Used to check that a faster harness gives the same results (README, Performance).
"""

from __future__ import annotations

import json
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

#: keys whose values legitimately differ between two runs of the same code and data
SKIPPED = {"command", "git_commit", "versions", "outputs"}


def diff_results(a: Any, b: Any, path: str = "") -> Iterator[str]:
    """Every difference between two results trees, as ``path: a vs b`` lines."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            yield f"{path}: keys {sorted(set(a) ^ set(b))}"
        for k in sorted(set(a) & set(b)):
            if k in SKIPPED or k.endswith("_us"):
                continue
            yield from diff_results(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            yield f"{path}: length {len(a)} vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            yield from diff_results(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return
    elif type(a) is not type(b) or a != b:
        yield f"{path}: {a!r} vs {b!r}"


def diff_traces(old: Path, new: Path) -> Iterator[str]:
    """Every column of ``traces.parquet`` that differs (dtype, length or any value)."""
    import numpy as np
    import pandas as pd

    a, b = pd.read_parquet(old), pd.read_parquet(new)
    if list(a.columns) != list(b.columns):
        yield f"traces: columns {list(a.columns)} vs {list(b.columns)}"
    if len(a) != len(b):
        yield f"traces: {len(a)} vs {len(b)} rows"
        return
    for c in [c for c in a.columns if c in b.columns]:
        x, y = a[c], b[c]
        if x.dtype != y.dtype:
            yield f"traces/{c}: dtype {x.dtype} vs {y.dtype}"
            continue
        if x.dtype.kind == "f":
            xv, yv = x.to_numpy(), y.to_numpy()
            same = np.array_equal(xv.view(np.int64), yv.view(np.int64)) or bool(
                np.all((xv == yv) | (np.isnan(xv) & np.isnan(yv)))
            )
        else:
            same = x.astype(str).equals(y.astype(str)) if x.dtype == object else x.equals(y)
        if not same:
            yield f"traces/{c}: values differ"


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.strip().splitlines()[0], file=sys.stderr)
        return 2
    old, new = (Path(p) for p in argv)
    ra = json.loads((old / "results.json").read_text())
    rb = json.loads((new / "results.json").read_text())
    diffs = list(diff_results(ra, rb))
    traces = [run / "traces.parquet" for run in (old, new)]
    if all(p.is_file() for p in traces):
        diffs += list(diff_traces(*traces))
    else:  # the committed reports keep no traces (.gitignore): results.json alone then
        missing = ", ".join(str(p) for p in traces if not p.is_file())
        print(f"traces not compared: no {missing}")
    for line in diffs[:50]:
        print(line)
    if len(diffs) > 50:
        print(f"... {len(diffs) - 50} more")
    if not diffs:
        print("same")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
