"""mkdocs hook (mkdocs.yml ``hooks:``), run at the start of every build:

* puts this folder on ``sys.path``, so that the reference and results pages'
  markdown-exec blocks and ``::: mkdocs-click`` import the build-time generators beside
  it (``gen_cli``, ``gen_reference``, ``gen_results``), and tells ``gen_results`` where
  the repository and its web address are;
* lays out the source tree as the one ``posbench`` package it installs as, for
  mkdocstrings: the repository keeps posbench's subpackages in top-level folders
  (``predictors/`` is ``posbench.predictors``, pyproject's
  ``[tool.setuptools.package-dir]``), which griffe's static analysis cannot follow in an
  editable install. A temporary folder of symbolic links (``posbench/`` = ``bench/``'s
  entries plus ``predictors``, ``scenarios``, ``metrics``) is put first on the python
  handler's search paths, so the API reference is read from the source files, never by
  importing them.

The folder is no package and is left out of the built site (``exclude_docs``)."""

from __future__ import annotations

import atexit
import shutil
import sys
import tempfile
import tomllib
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority

HERE = str(Path(__file__).resolve().parent)


def package_tree(root: Path, into: Path) -> Path:
    """``into``/PACKAGE for each top-level package of pyproject's package-dir map: its
    folder's entries linked, and each mapped subpackage linked at its dotted place."""
    data = tomllib.loads((root / "pyproject.toml").read_text())
    mapping = data.get("tool", {}).get("setuptools", {}).get("package-dir", {})
    for name, folder in sorted(mapping.items(), key=lambda kv: kv[0].count(".")):
        target = into.joinpath(*name.split("."))
        source = (root / folder).resolve()
        if "." not in name:  # a top-level package: a real folder holding links
            target.mkdir(parents=True, exist_ok=True)
            for entry in source.iterdir():
                if entry.name != "__pycache__" and not (target / entry.name).exists():
                    (target / entry.name).symlink_to(entry)
        elif not target.exists():
            target.symlink_to(source, target_is_directory=True)
    return into


@event_priority(100)  # before mkdocstrings' on_config, which starts the python handler
def on_config(config: Any) -> None:
    """Set up the generators and mkdocstrings' search path (see the module docstring)."""
    if HERE not in sys.path:
        sys.path.insert(0, HERE)  # here, not at import: mkdocs restores sys.path after that
    import gen_results

    root = Path(config.config_file_path).resolve().parent
    gen_results.ROOT = root
    gen_results.REPO_URL = config.repo_url or ""

    plugin = config.plugins.get("mkdocstrings")
    if plugin is None or not (root / "pyproject.toml").is_file():
        return
    tmp = Path(tempfile.mkdtemp(prefix="posbench-docs-"))
    atexit.register(shutil.rmtree, tmp, ignore_errors=True)
    python = plugin.config.handlers.setdefault("python", {})
    python["paths"] = [str(package_tree(root, tmp)), *python.get("paths", [])]
