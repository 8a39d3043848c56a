"""Time-stamp hygiene shared by all loaders: sort, de-duplicate, count what changed.

Nothing is dropped silently: every removal or re-ordering is appended to the
``warnings`` list the caller passes in (it ends up in ``DriveMeta.warnings``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import overload

import numpy as np


def clean_index(t: np.ndarray, what: str, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Sort by time, drop non-finite times and exact duplicate stamps (keeping the first).

    Args:
        t: times [s].
        what: the stream's name for warnings, e.g. ``"gps"``.
        warnings: list to append human-readable notes to.
    Returns:
        (t cleaned, strictly increasing [s]; the kept samples' indices into ``t``, in that
        order: :func:`take` applies them to a column aligned with ``t``).
    """
    t = np.asarray(t, dtype=float)
    keep = np.isfinite(t)
    if not np.all(keep):
        warnings.append(f"{what}: dropped {int((~keep).sum())} samples with non-finite time")
    idx = np.flatnonzero(keep)
    order = np.argsort(t[idx], kind="stable")
    if np.any(np.diff(t[idx]) < 0):
        warnings.append(
            f"{what}: re-sorted {int((np.diff(t[idx]) < 0).sum())} out-of-order time stamps"
        )
    idx = idx[order]
    ts = t[idx]
    dup = np.zeros(ts.size, dtype=bool)
    if ts.size > 1:
        dup[1:] = np.diff(ts) <= 0
    if np.any(dup):
        warnings.append(f"{what}: dropped {int(dup.sum())} samples with duplicate time stamps")
        idx = idx[~dup]
    return t[idx], idx


@overload
def take(col: np.ndarray, idx: np.ndarray) -> np.ndarray: ...
@overload
def take(col: None, idx: np.ndarray) -> None: ...
def take(col: np.ndarray | None, idx: np.ndarray) -> np.ndarray | None:
    """The samples ``idx`` (from :func:`clean_index`) of a column, as floats; None stays None."""
    return None if col is None else np.asarray(col, dtype=float)[idx]


def clean_times(
    t: np.ndarray, cols: Mapping[str, np.ndarray], what: str, warnings: list[str]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """:func:`clean_index` applied to ``t`` and to columns aligned with it.

    Args:
        t: times [s].
        cols: columns aligned with ``t`` (a stream with optional columns uses
            :func:`clean_index` and :func:`take`, which pass ``None`` through).
        what: the stream's name for warnings, e.g. ``"gps"``.
        warnings: list to append human-readable notes to.
    Returns:
        (t, cols) cleaned, strictly increasing in t.
    """
    t, idx = clean_index(t, what, warnings)
    return t, {k: take(v, idx) for k, v in cols.items()}
