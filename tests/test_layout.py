"""The shape of the code, held as tests: one namespace, packages importing one way, no
cycle, small modules, and the reading side of the harness free of the replay and the
predictors (so loading a saved run stays cheap and works without onnxruntime or torch)."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest
from layout import FOLDERS, ROOT, module_name, source_files

#: packages that read saved runs or draw from traces: never the replay, the aggregation,
#: the pipelines, the predictors or the command line
READERS = ("tables", "report", "comparison", "figures", "saved_run", "recording", "scoring")
WRITERS = ("replay", "aggregation", "pipeline", "predictor_tools", "offline", "cli", "predictors")


def _imports(path: Path, top_level_only: bool) -> set[str]:
    """The posbench modules (or their parents) ``path`` imports; type-only imports left out."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            node.body = []
    nodes = (
        [n for n in tree.body if not isinstance(n, ast.If)]
        if top_level_only
        else list(ast.walk(tree))
    )
    out: set[str] = set()
    for n in nodes:
        if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("posbench"):
            out.add(n.module)
            out.update(f"{n.module}.{a.name}" for a in n.names)
        elif isinstance(n, ast.Import):
            out.update(a.name for a in n.names if a.name.startswith("posbench"))
    return out


def _graph(top_level_only: bool) -> dict[str, set[str]]:
    """Module -> the posbench modules it imports."""
    modules = {module_name(f): f for f in source_files()}

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for m, f in modules.items():
        graph[m] = {r for i in _imports(f, top_level_only) if (r := resolve(i)) and r != m}
    return graph


def _package(module: str) -> str:
    """``posbench.replay.loop`` -> ``replay``; ``posbench.predictors.kf`` -> ``predictors``;
    a module directly in posbench is its own package (``checks``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "posbench"


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_between_modules():
    assert _cycles(_graph(top_level_only=True)) == []


def test_packages_import_one_way():
    """No cycle between packages even counting the imports inside functions, the readers
    of saved runs never import the replay side, only the command line imports it, and the
    predictors, the data side and the metrics never import the harness."""
    packages: dict[str, set[str]] = defaultdict(set)
    for m, targets in _graph(top_level_only=False).items():
        for t in targets:
            a, b = _package(m), _package(t)
            if a != b:
                packages[a].add(b)
    assert _cycles(dict(packages)) == []
    for reader in READERS:
        assert not packages[reader] & set(WRITERS), (reader, packages[reader] & set(WRITERS))
    assert {p for p, deps in packages.items() if "cli" in deps} <= {"__main__"}
    harness = set(packages) - {"predictors", "scenarios", "metrics"}
    for side in ("predictors", "scenarios", "metrics"):
        assert not packages[side] & harness, (side, packages[side] & harness)
    assert packages["metrics"] <= {"metrics"} and "predictors" not in packages["scenarios"]


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
from posbench.report.markdown import report_tables
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
