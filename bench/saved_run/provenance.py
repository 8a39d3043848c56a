"""Where a run came from, as results.json records it: package versions, the git commit of the
posbench checkout, and a content hash of every data path (:func:`tree_hash`)."""

from __future__ import annotations

import hashlib
import os
import platform
import subprocess
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

#: the packages whose versions results.json records (``posbench``: this harness)
VERSIONED = (
    "posbench",
    "numpy",
    "scipy",
    "pandas",
    "numba",
    "onnxruntime",
    "rosbags",
    "pymap3d",
)


def package_versions() -> dict[str, str]:
    """Python's version and that of each package of :data:`VERSIONED` (``not installed``)."""
    from posbench.naming import DISTRIBUTION

    out = {"python": platform.python_version()}
    for name in VERSIONED:
        try:  # the key "posbench" names the harness, whatever its distribution is called
            out[name] = metadata.version(DISTRIBUTION if name == "posbench" else name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def data_provenance(paths: Sequence[str | Path] | None, seed: int) -> list[dict[str, Any]]:
    """The ``data`` block of results.json: :func:`tree_hash` of each data path, or the built-in
    synthetic drives' generator seed when there is none."""
    if paths:
        return [tree_hash(p) for p in paths]
    return [
        {
            "path": "built-in synthetic drives",
            "files": 0,
            "bytes": 0,
            "sha256": f"generator seed {seed}",
        }
    ]


def git_commit() -> str | None:
    """The commit of the posbench checkout, with ``-dirty`` if it has changes; None outside git."""
    root = Path(__file__).resolve().parents[1]
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return None


def _tree_files(root: str) -> list[tuple[str, ...]]:
    """Every file at or under folder ``root`` as its relative path's parts, sorted as
    ``sorted(Path(root).rglob("*"))`` orders them (part by part); as ``rglob``, symbolic
    links to folders are not followed, those to files are kept."""
    out: list[tuple[str, ...]] = []
    stack: list[tuple[str, tuple[str, ...]]] = [(root, ())]
    while stack:
        folder, parts = stack.pop()
        try:
            with os.scandir(folder) as it:
                entries = list(it)
        except PermissionError:
            continue
        for e in entries:
            if e.is_dir(follow_symlinks=False):
                stack.append((e.path, (*parts, e.name)))
            elif e.is_file():
                out.append((*parts, e.name))
    out.sort()
    return out


def tree_hash(path: str | Path) -> dict[str, Any]:
    """sha256 over the sorted relative paths and contents of every file at or under ``path``."""
    p = Path(path)
    files = (
        [(p.name, str(p))]
        if p.is_file()
        else [("/".join(parts), os.path.join(p, *parts)) for parts in _tree_files(str(p))]
    )
    h = hashlib.sha256()
    size = 0
    for name, full in files:
        h.update(name.encode())
        fd = os.open(full, os.O_RDONLY)
        try:
            while chunk := os.read(fd, 1 << 20):
                h.update(chunk)
                size += len(chunk)
        finally:
            os.close(fd)
    return {"path": str(path), "files": len(files), "bytes": size, "sha256": h.hexdigest()}
