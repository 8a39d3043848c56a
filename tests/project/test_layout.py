"""The shape of the code, held as tests: one namespace, small modules, and a saved run that
loads, renders and compares in a fresh process without importing the replay or a predictor
(so loading stays cheap and works without onnxruntime or torch).

The import rules themselves (no cycle, packages one way, the readers apart from the replay,
only the entry point importing the command line) are import-linter contracts in
pyproject.toml, checked by .ci/checks."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import FOLDERS, ROOT, module_name, source_files


def test_modules_are_small_and_bench_has_few_of_its_own():
    big = {
        module_name(f): n for f in source_files() if (n := len(f.read_text().splitlines())) > 600
    }
    assert big == {}
    own = sorted(p.name for p in (ROOT / "bench").glob("*.py"))
    assert len(own) <= 12, own


def test_every_package_is_installed_under_posbench():
    """pyproject.toml lists every folder with an __init__.py, under its posbench name, and
    maps the four source folders into the one namespace."""
    import tomllib

    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = sorted(
        module_name(p) for folder in FOLDERS for p in (ROOT / folder).rglob("__init__.py")
    )
    assert sorted(cfg["packages"]) == found
    assert cfg["package-dir"] == {name: folder for folder, name in FOLDERS.items()}
    assert all(p == "posbench" or p.startswith("posbench.") for p in cfg["packages"])


def _run_python(code: str, cwd: Path | None = None) -> str:
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, timeout=300
    )
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_import_posbench_is_cheap():
    out = _run_python(
        "import sys, posbench; print(sorted(m for m in ('numpy', 'pandas', "
        "'typer', 'rich') if m in sys.modules))"
    )
    assert out.strip() == "[]"


FORBIDDEN = (
    "posbench.replay",
    "posbench.pipeline",
    "posbench.predictors",
    "posbench.aggregation",
    "posbench.predictor_tools",
    "onnxruntime",
    "torch",
    "rerun",
    "ray",
)


@pytest.mark.slow
def test_loading_and_rendering_a_saved_run_imports_no_replay_or_predictor(tmp_path):
    """A saved run (with traces) loaded in a fresh process: its summary, every report
    table in every form, report.md and the figures, and a comparison with itself."""
    out = tmp_path / "run"
    _run_python(
        f"import posbench; posbench.run(predictors='cv,kf', out={str(out)!r}, "
        f"workers=1, drive_plots=1)"
    )
    code = f"""
import sys
import posbench
run = posbench.load({str(out)!r})
run.summary(); run.traces
from posbench.report.table_files import report_tables
for t in report_tables(run.results):
    t.markdown(); t.csv(); t.latex()
run.report({str(tmp_path / "rendered")!r}, drive_plots=1)
posbench.compare(run, {str(out)!r})
print(sorted({{m.split('.')[0] if not m.startswith('posbench') else '.'.join(m.split('.')[:2])
              for m in sys.modules if m.startswith({FORBIDDEN!r})}}))
"""
    assert _run_python(code).strip() == "[]"
    assert (tmp_path / "rendered" / "report.md").is_file()
    assert (tmp_path / "rendered" / "error_cdf.png").is_file()


def test_preloaded_modules_exist():
    from posbench.pipeline.preload import MODULES, REPLAY_MODULES

    for name in (*MODULES, *REPLAY_MODULES):
        importlib.import_module(name)
