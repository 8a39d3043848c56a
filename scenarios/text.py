"""How values read in messages and reports: a quoted value as plain Python shows it
(:func:`quoted`), and figures to a fixed number of decimals that stay short however large
(:func:`fixed`).
"""

from __future__ import annotations

import math
from typing import Any

#: from this magnitude on a figure is written in scientific notation (``1.414e+308``, not
#: 309 digits): above any figure of a real drive (distances, times, errors), so that those
#: print as they always have
SCIENTIFIC_FROM = 1e9


def quoted(value: Any) -> str:
    """``value`` as a message quotes it: its ``repr``, a numpy scalar as the Python value it
    holds (``95.0``, not numpy 2's ``np.float64(95.0)``)."""
    item = getattr(value, "item", None)
    if callable(item) and getattr(value, "shape", None) == ():
        value = item()
    return repr(value)


def fixed(value: float, decimals: int, sign: str = "") -> str:
    """``value`` to ``decimals`` decimals (``sign`` ``"+"``: always signed), or in scientific
    notation with as many decimals from a magnitude of :data:`SCIENTIFIC_FROM` on (``nan``
    and ``inf`` as Python writes them)."""
    form = "e" if math.isfinite(value) and abs(value) >= SCIENTIFIC_FROM else "f"
    return f"{value:{sign}.{decimals}{form}}"
