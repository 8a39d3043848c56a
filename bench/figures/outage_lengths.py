"""The outage curve: error at the end of GPS outages against outage length, one line per
predictor with its 95 % interval as a band; left in metres, right in % of the distance
travelled since the last fix. Drawn from results.json's ``outage_lengths`` (schema 1.10;
the intervals are the aggregation's cluster bootstrap, which the traces alone do not give)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from posbench.figures.style import NothingToPlot, colors_for

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: the figure's file stem
NAME = "outage_lengths"
#: panel -> (figure of results.json, axis label)
PANELS = (
    ("fde_mean_m", "mean FDE [m]"),
    ("fde_pct", "FDE [% of distance since the last fix]"),
)


def _nan(v: Any) -> float:
    return float("nan") if v is None else float(v)


def curve(entries: Mapping[str, Any], keys: list[str], figure: str) -> np.ndarray:
    """(len(keys), 3) array of ``figure`` and its interval's lo, hi per length key (NaN where
    a length has no outage)."""
    out = np.full((len(keys), 3), np.nan)
    for i, k in enumerate(keys):
        e = entries.get(k) or {}
        lo, hi = ((e.get("ci95") or {}).get(figure) or [None, None])[:2]
        out[i] = (_nan(e.get(figure)), _nan(lo), _nan(hi))
    return out


def plot_outage_lengths(res: Mapping[str, Any]) -> Figure:
    """FDE [m] and FDE [% of distance] against outage length [s] (log axes), one line per
    predictor, its 95 % interval shaded; lengths without an outage are left out; a
    predictor whose curve equals an earlier one's is dashed and named ``p (= q)``."""
    from matplotlib.figure import Figure

    sec = res.get("outage_lengths")
    if not sec or not sec.get("predictors"):
        raise NothingToPlot("no outage-lengths section in this run")
    keys = list(sec["counts"])
    lengths = np.asarray([sec["counts"][k]["length_s"] for k in keys], dtype=float)
    counts = [sec["counts"][k]["outages"] for k in keys]
    if not any(counts):
        raise NothingToPlot("no drive was long enough for an outage")
    preds = list(sec["predictors"])
    colors = colors_for(preds)
    fig = Figure(figsize=(11, 4.5), layout="constrained")
    axes = fig.subplots(1, 2, sharex=True)
    for ax, (figure, label) in zip(axes, PANELS, strict=True):
        drawn: dict[str, np.ndarray] = {}
        for p in preds:
            c = curve(sec["predictors"][p], keys, figure)
            ok = np.isfinite(c[:, 0]) & (c[:, 0] > 0)
            if not ok.any():
                continue
            # a curve equal to one drawn before would hide it: dashed, and named so
            same = next((q for q, d in drawn.items() if np.allclose(d, c, equal_nan=True)), None)
            drawn[p] = c
            ax.plot(
                lengths[ok],
                c[ok, 0],
                marker="o",
                label=p if same is None else f"{p} (= {same})",
                color=colors[p],
                ls="-" if same is None else "--",
            )
            band = ok & np.isfinite(c[:, 1]) & np.isfinite(c[:, 2]) & (c[:, 1] > 0)
            if band.any():
                ax.fill_between(
                    lengths[band], c[band, 1], c[band, 2], color=colors[p], alpha=0.15, lw=0
                )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(lengths, [f"{x:g}\n(n={n})" for x, n in zip(lengths, counts, strict=True)])
        ax.minorticks_off()
        ax.set_xlabel("outage length [s] (n = outages)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=8)
    fig.suptitle(
        "Error at the end of GPS outages by length (bands: 95 % CI, cluster bootstrap over drives)"
    )
    return fig
