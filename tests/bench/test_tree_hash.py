"""bench.results.tree_hash (the data provenance of results.json) gives the hash of its
first, pathlib-based form: the same files, in the same order, with the same bytes."""

from __future__ import annotations

import hashlib
from pathlib import Path

from posbench.saved_run.provenance import tree_hash


def pathlib_hash(path: Path) -> dict:
    """The reference: sorted rglob, relative path then contents of each file."""
    files = [path] if path.is_file() else sorted(f for f in path.rglob("*") if f.is_file())
    h = hashlib.sha256()
    size = 0
    for f in files:
        h.update(str(f.relative_to(path) if f != path else f.name).encode())
        data = f.read_bytes()
        h.update(data)
        size += len(data)
    return {"path": str(path), "files": len(files), "bytes": size, "sha256": h.hexdigest()}


def test_tree_hash_matches_the_pathlib_reference(tmp_path: Path) -> None:
    root = tmp_path / "data"
    # "a-b" sorts before "a/..." as a string but after it part by part ("a" < "a-b")
    for rel, text in {
        "a-b": "1",
        "a/b": "2",
        "a/c/d.bin": "3" * 3_000_000,
        "A": "",
        ".hidden": "h",
        "z/a.txt": "z",
        "a0/x": "x",
    }.items():
        f = root / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    (root / "link-to-dir").symlink_to(root / "a", target_is_directory=True)  # not followed
    (root / "link-to-file").symlink_to(root / "z" / "a.txt")  # hashed as a file
    assert tree_hash(root) == pathlib_hash(root)
    assert tree_hash(root)["files"] == 8
    assert tree_hash(root / "a-b") == pathlib_hash(root / "a-b")
