"""A plain install, used as a new user would: only ``posbench`` lands at the top of
site-packages, and the Python API works from a folder that holds packages of its own named
like posbench's old top-level ones (``metrics/``, ``predictors/``, ...)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from helpers import ROOT

GENERIC = ("bench", "metrics", "predictors", "scenarios")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """``pip install --no-deps --target DIR .`` of this checkout (not editable)."""
    target = tmp_path_factory.mktemp("site")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--no-deps",
            "--quiet",
            "--disable-pip-version-check",
            "--target",
            str(target),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    return target


@pytest.mark.slow
def test_a_plain_install_puts_nothing_generic_at_the_top(installed: Path):
    top = sorted(p.name for p in installed.iterdir() if p.name not in ("bin", "__pycache__"))
    assert "posbench" in top
    assert [t for t in top if t != "posbench" and not t.endswith(".dist-info")] == []
    dist = next(p for p in top if p.endswith(".dist-info"))
    assert dist.startswith("posbench_harness-")
    pkg = installed / "posbench"
    for data in (
        "py.typed",  # PEP 561: type checkers read posbench's own annotations
        "saved_run/schemas/results.schema.json",
        "predictors/tuned.json",
        "predictors/lstm/bundled/model.onnx",
        "predictors/hybrid/bundled/model.onnx",
    ):
        assert (pkg / data).is_file(), data


@pytest.mark.slow
def test_the_api_works_beside_a_users_own_metrics_package(installed: Path, tmp_path: Path):
    """The user's folder holds ``metrics/`` and ``predictors/`` packages of its own: posbench
    runs, saves, loads and compares, and the user's packages stay theirs."""
    work = tmp_path / "notebook"
    for name in ("metrics", "predictors"):
        (work / name).mkdir(parents=True)
        (work / name / "__init__.py").write_text(f"MINE = {name!r}\n")
    code = textwrap.dedent(f"""
        import metrics, predictors
        import posbench
        run = posbench.run(predictors="cv,kf", out="out", workers=1, plot_formats="none")
        loaded = posbench.load("out")
        table = loaded.summary()
        assert list(table.index.names) == ["predictor", "kind"] and len(table) == 4
        kf_future = ("kf", "future")
        assert table.loc[kf_future, "mean_m"] == run.summary().loc[kf_future, "mean_m"]
        cmp = posbench.compare(loaded, run)
        delta = cmp.frame.loc[cmp.frame["scope"] == "all", "delta {{}}".format(cmp.labels[1])]
        assert delta.abs().max() == 0
        assert metrics.MINE == "metrics" and predictors.MINE == "predictors"
        assert posbench.__file__.startswith({str(installed)!r})
        print(repr(loaded))
    """)
    env = {**os.environ, "PYTHONPATH": str(installed)}
    r = subprocess.run(
        [sys.executable, "-c", code], cwd=work, env=env, capture_output=True, text=True, timeout=600
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.startswith("Run(out: 4 drives (synthetic), 2 predictors")
