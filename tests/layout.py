"""Where posbench's source lives in this repository and what it is called once installed.

The repository keeps its top-level folders; the install maps each to a package of the one
namespace ``posbench`` (pyproject.toml ``[tool.setuptools.package-dir]``).
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: source folder -> the installed package it becomes
FOLDERS = {
    "bench": "posbench",
    "predictors": "posbench.predictors",
    "scenarios": "posbench.scenarios",
    "metrics": "posbench.metrics",
}


def module_name(path: Path) -> str:
    """The installed module of a source file: ``bench/config.py`` -> ``posbench.config``,
    ``predictors/lstm/__init__.py`` -> ``posbench.predictors.lstm``."""
    parts = path.resolve().relative_to(ROOT).with_suffix("").parts
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join((FOLDERS[parts[0]], *parts[1:]))


def source_files() -> list[Path]:
    """Every Python file of the installed packages, in a stable order."""
    return [f for folder in FOLDERS for f in sorted((ROOT / folder).rglob("*.py"))]
