"""posbench.naming (split from the flat bench/; docstring to write)."""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # matplotlib is imported when a figure is drawn: importing this module is cheap
    pass


def _safe_name(name: str) -> str:
    """A drive name usable as a file name (no path separators or odd characters)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "drive"
