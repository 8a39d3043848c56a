"""How posbench names things: its distribution, file-safe names, unique ids for drives,
counted nouns.

One definition each, used by the per-drive figures (``drives/<name>-error_over_time.png``),
the queries folder (``inputs/<id>.csv``) and the rerun recording (``drives/<name>/...``
entity paths)."""

from __future__ import annotations

import re
from collections.abc import Iterable

#: the distribution that installs the ``posbench`` package (``pip install posbench-harness``;
#: the name ``posbench`` on PyPI belongs to an unrelated project)
DISTRIBUTION = "posbench-harness"

_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def file_safe(name: str, empty: str = "drive") -> str:
    """``name`` usable as a file name or an entity-path part: runs of characters other than
    letters, digits, ``.``, ``_`` and ``-`` become ``_``, leading and trailing ``.`` and
    ``_`` go (no hidden files, no ``..``); ``empty`` when nothing is left."""
    return _UNSAFE.sub("_", str(name)).strip("._") or empty


def unique_file_safe(names: Iterable[str], sep: str = "-", empty: str = "drive") -> list[str]:
    """:func:`file_safe` of each name, made unique in order: a name that clashes with an
    earlier one (also by case, for case-insensitive file systems) gets ``<sep>2``,
    ``<sep>3``, ..."""
    out: list[str] = []
    taken: set[str] = set()
    for name in names:
        base = file_safe(name, empty)
        cand, n = base, 1
        while cand.lower() in taken:
            n += 1
            cand = f"{base}{sep}{n}"
        taken.add(cand.lower())
        out.append(cand)
    return out


def plural(n: int, word: str) -> str:
    """``1 drive``, ``2 drives``."""
    return f"{n} {word}" + ("" if n == 1 else "s")
