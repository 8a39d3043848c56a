"""Accuracy metrics: pure functions on arrays of positions and errors (metres).

Per-sequence figures first (one drive, one predictor), then combined, as in
TrackEval: :func:`summarize` works on any 1-D array of Euclidean errors, and
:func:`summarize_groups` applies it per key (drive, scenario label, speed bin).
NaN errors (a predictor had no estimate) are not averaged: they are counted as
``missing`` so a predictor cannot look better by abstaining.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

SUMMARY_KEYS = ("count", "missing", "mean_m", "median_m", "rmse_m", "p95_m", "max_m")

#: what each figure of :func:`summarize` means (the report's glossary collects these); a
#: figure is over the errors of the queries its row or cell covers, pooled over drives
DEFINITIONS = {
    "error": "Euclidean distance [m] between a predictor's answer and the reference position "
    "at the query time, in the drive's local ENU frame.",
    "mean": "arithmetic mean of the errors [m] (pooled: each drive weighs by its queries).",
    "median": "50th percentile of the errors [m] (linear interpolation, as numpy).",
    "RMSE": "root mean square of the errors [m].",
    "p95": "95th percentile of the errors [m] (linear interpolation, as numpy).",
    "max": "largest error [m].",
    "n": "number of answered queries a figure is over (in parentheses after a value).",
    "missing": "queries answered with no position (NaN) although a reference exists; counted, "
    "never averaged, so abstaining cannot flatter a predictor.",
    "speed bin": "the reference speed at the query time [m/s], in bins [a, b).",
}


def euclidean_error(pred_xy: np.ndarray, ref_xy: np.ndarray) -> np.ndarray:
    """Per-row Euclidean distance [m] between (N, 2) predicted and reference positions."""
    d = np.asarray(pred_xy, dtype=float) - np.asarray(ref_xy, dtype=float)
    distance: np.ndarray = np.hypot(d[:, 0], d[:, 1])
    return distance


def summarize(errors: np.ndarray) -> dict[str, float | int]:
    """count, missing, mean, median, RMSE, p95 (linear interpolation) and max of errors [m].

    ``count`` is the number of finite errors; ``missing`` the number of NaN ones.
    With no finite error, the statistics are NaN.
    """
    e = np.asarray(errors, dtype=float).ravel()
    finite = np.isfinite(e)
    v = e[finite]
    out: dict[str, float | int] = {"count": int(v.size), "missing": int((~finite).sum())}
    if v.size == 0:
        out.update({k: float("nan") for k in SUMMARY_KEYS[2:]})
        return out
    out["mean_m"] = float(v.mean())
    out["median_m"] = float(np.median(v))
    out["rmse_m"] = float(np.sqrt(np.mean(v * v)))
    out["p95_m"] = float(np.percentile(v, 95))
    out["max_m"] = float(v.max())
    return out


def summarize_groups(
    errors: np.ndarray, keys: np.ndarray, order: Sequence[str] | None = None
) -> dict[str, dict[str, float | int]]:
    """:func:`summarize` per distinct key (e.g. scenario label), in ``order`` if given
    (keys in ``order`` with no samples get count 0), else sorted."""
    e = np.asarray(errors, dtype=float)
    k = np.asarray(keys)
    names = list(order) if order is not None else sorted(set(k.tolist()))
    return {str(n): summarize(e[k == n]) for n in names}


def speed_bin_index(
    speed_mps: np.ndarray, edges_mps: Sequence[float] = (0.5, 5, 10, 15, 20, 30)
) -> np.ndarray:
    """Each speed's [m/s] bin as an index into :func:`speed_bin_order` plus ``"unknown"``
    (the last index: the speed is not finite); int8."""
    s = np.asarray(speed_mps, dtype=float)
    idx = np.searchsorted(list(edges_mps), s, side="right").astype(np.int8)
    idx[~np.isfinite(s)] = len(edges_mps) + 1
    return idx


def speed_bin_labels(
    speed_mps: np.ndarray, edges_mps: Sequence[float] = (0.5, 5, 10, 15, 20, 30)
) -> np.ndarray:
    """Bin names like ``"5-10 m/s"`` for each speed [m/s]; ``"<0.5 m/s"`` and ``">=30 m/s"``
    at the ends; ``"unknown"`` where the speed is not finite. An object array whose rows
    share one string per bin (8 bytes a row, not a fixed-width string each)."""
    names = [*speed_bin_order(edges_mps), "unknown"]
    out: np.ndarray = np.asarray(names, dtype=object)[speed_bin_index(speed_mps, edges_mps)]
    return out


def speed_bin_order(edges_mps: Sequence[float] = (0.5, 5, 10, 15, 20, 30)) -> list[str]:
    """The bin names of :func:`speed_bin_labels` in increasing speed."""
    edges = list(edges_mps)
    return (
        [f"<{edges[0]:g} m/s"]
        + [f"{a:g}-{b:g} m/s" for a, b in zip(edges[:-1], edges[1:], strict=True)]
        + [f">={edges[-1]:g} m/s"]
    )


def error_cdf(errors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted finite errors [m] and their cumulative fractions (0, 1]."""
    v = np.sort(np.asarray(errors, dtype=float)[np.isfinite(errors)])
    return v, (np.arange(1, v.size + 1) / v.size) if v.size else np.empty(0)
