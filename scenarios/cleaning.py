"""Time-stamp hygiene shared by all loaders: sort, de-duplicate, count what changed.

Nothing is dropped silently: every removal or re-ordering is appended to the
``warnings`` list the caller passes in (it ends up in ``DriveMeta.warnings``).
"""

from __future__ import annotations

import numpy as np


def clean_times(
    t: np.ndarray, cols: dict[str, np.ndarray | None], what: str, warnings: list[str]
) -> tuple[np.ndarray, dict[str, np.ndarray | None]]:
    """Sort by time, drop non-finite times and exact duplicate stamps (keeping the first).

    Args:
        t: times [s].
        cols: columns aligned with ``t`` (``None`` entries are passed through).
        what: the stream's name for warnings, e.g. ``"gps"``.
        warnings: list to append human-readable notes to.
    Returns:
        (t, cols) cleaned, strictly increasing in t.
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
    out = {k: (None if v is None else np.asarray(v, dtype=float)[idx]) for k, v in cols.items()}
    return t[idx], out


def drop_nonfinite(
    t: np.ndarray,
    cols: dict[str, np.ndarray | None],
    required: tuple[str, ...],
    what: str,
    warnings: list[str],
) -> tuple[np.ndarray, dict[str, np.ndarray | None]]:
    """Drop samples whose required columns are NaN/inf, counting them in ``warnings``."""
    keep = np.ones(np.asarray(t).size, dtype=bool)
    for k in required:
        c = cols[k]
        if c is not None:
            keep &= np.isfinite(c)
    if not np.all(keep):
        warnings.append(f"{what}: dropped {int((~keep).sum())} samples with non-finite values")
    return np.asarray(t)[keep], {k: (None if v is None else v[keep]) for k, v in cols.items()}
