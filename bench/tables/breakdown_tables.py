"""The run's figures broken down, as report.md and the terminal show them: by route type (the
paper's Table I layout, with the paper's LSTM figure beside), by speed, by time since the
last fix and per outage, the outlier gate's rejections, and per drive. Each reads the run's
``results`` and returns a numeric :class:`~posbench.tables.table.Table`; errors in metres
(route type: centimetres)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from posbench.metrics.accuracy import speed_bin_order
from posbench.scenarios.labels import LABELS
from posbench.tables.limit import drive_limit_mean, label_limit_mean, limit_scope
from posbench.tables.run_tables import ci_map, put_figure, with_ci_columns
from posbench.tables.table import Table, is_finite, rows_frame

PAPER_TABLE_CM = {"straight": 16.6, "turn": 12.1, "roundabout": 9.7, "start_stop": 4.2}
PAPER_OVERALL = "11 (LSTM), 46 (Kalman)"
LABEL_TITLES = {
    "straight": "Straight path / full speed",
    "turn": "Turn",
    "roundabout": "Roundabout",
    "start_stop": "Starting / stopping",
}


#: the drives table's column of the bound's future mean [m]
LIMIT_DRIVE_COLUMN = "limit future mean [m]"

#: the marker of a route-type cell whose 95 % interval is wider than its value
NOT_CONCLUSIVE = "?"


def not_conclusive(value: float, lo: float, hi: float) -> bool:
    """A figure whose 95 % interval is wider than the figure itself (hi - lo > value)."""
    return is_finite(value) and is_finite(lo) and is_finite(hi) and hi - lo > value


def label_table(res: Mapping[str, Any], dataset: str, kind: str, held_out: bool = False) -> Table:
    """The paper's Table I layout: route type x mean error [cm] with its 95 % interval
    (query count), one column per predictor, ``?`` where the interval is wider than the
    value (not conclusive); for the future point (what the paper measured) its LSTM figure
    beside. ``held_out``: only drives no predictor was trained or tuned on. With a bound
    (schema 1.9; not over the held-out drives), its mean [cm] as the column ``limit [cm]``."""
    preds = list(res["predictors"])
    paper = kind == "future"
    bound = not held_out and limit_scope(res, dataset) is not None
    if held_out:
        by_label = res["held_out"][dataset]["by_label"]
        overall_src = res["held_out"][dataset]["predictors"]
    else:
        by_label = res["by_label"].get(dataset, {})
        overall_src = res["by_dataset"].get(dataset, {})

    def cells(summaries: Mapping[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for p in preds:
            s = summaries.get(p) or {}
            col = f"{p} [cm]"
            put_figure(out, col, s if s.get("count") else {}, "mean_m", 100.0)
            out[f"{p} mark"] = (
                NOT_CONCLUSIVE
                if not_conclusive(out[col], out[f"{col}_lo"], out[f"{col}_hi"])
                else ""
            )
            out[f"{p} n"] = int(s.get("count", 0))
        return out

    rows = []
    for lab in LABELS:
        row = {
            "route type": LABEL_TITLES[lab],
            **cells({p: by_label.get(p, {}).get(kind, {}).get(lab, {}) for p in preds}),
        }
        if bound:
            row["limit [cm]"] = 100.0 * label_limit_mean(res, dataset, kind, lab)
        if paper:
            row["paper LSTM [cm]"] = PAPER_TABLE_CM[lab]
        rows.append(row)
    overall = {
        "route type": "all",
        **cells({p: overall_src.get(p, {}).get(kind, {}) for p in preds}),
    }
    if bound:
        overall["limit [cm]"] = 100.0 * label_limit_mean(res, dataset, kind, None)
    if paper:
        overall["paper LSTM [cm]"] = PAPER_OVERALL
    rows.append(overall)
    cols = ["route type"] + [
        c
        for p in preds
        for c in (f"{p} [cm]", f"{p} [cm]_lo", f"{p} [cm]_hi", f"{p} mark", f"{p} n")
    ]
    cols += ["limit [cm]"] if bound else []
    cols += ["paper LSTM [cm]"] if paper else []
    return Table(
        rows_frame(rows, cols),
        f"route-type-{dataset}-{kind}" + ("-held-out" if held_out else ""),
        {f"{p} [cm]": f"{p} [cm] (n)" for p in preds},
        {c: 1 for c in cols if c.endswith("[cm]")},
        {f"{p} [cm]": f"{p} n" for p in preds},
        ci=ci_map([f"{p} [cm]" for p in preds]),
        marks={f"{p} [cm]": f"{p} mark" for p in preds},
    )


def speed_table(res: Mapping[str, Any]) -> Table:
    """Future-point error by speed bin, mean [m] with its 95 % interval (queries); bins
    without queries left out."""
    by_speed = res["by_speed"]
    bins = [
        b
        for b in speed_bin_order() + ["unknown"]
        if any(by_speed[p]["future"].get(b, {}).get("count", 0) for p in by_speed)
    ]
    rows = []
    for p, s in by_speed.items():
        row: dict[str, Any] = {"predictor": p}
        for b in bins:
            put_figure(row, b, s["future"][b], "mean_m")
            row[f"{b} n"] = s["future"][b]["count"]
        rows.append(row)
    cols = ["predictor"] + [c for b in bins for c in (b, f"{b}_lo", f"{b}_hi", f"{b} n")]
    return Table(
        rows_frame(rows, cols), "speed", counts={b: f"{b} n" for b in bins}, ci=ci_map(bins)
    )


def outage_table(res: Mapping[str, Any]) -> Table:
    """Now-error by time since the last fix (mean [m], queries) and per-outage scores, each
    with its 95 % interval."""
    cps = list(next(iter(res["outages"].values()))["since_fix"])
    rows = []
    for p, o in res["outages"].items():
        sc = o["scores"]
        row: dict[str, Any] = {"predictor": p}
        for c in cps:
            put_figure(row, c, o["since_fix"][c], "mean_m")
            row[f"{c} n"] = o["since_fix"][c]["count"]
        row["outages"] = sc["outages"]
        ci = sc.get("ci95") or {}
        for col, fig in (
            ("ade", "ade_mean_m"),
            ("fde", "fde_mean_m"),
            ("fde_p95", "fde_p95_m"),
            ("miss_rate", "miss_rate"),
        ):
            put_figure(row, col, {fig: sc[fig], "ci95": ci}, fig)
        rows.append(row)
    scores = ["ade", "fde", "fde_p95", "miss_rate"]
    cols = ["predictor"] + [x for c in cps for x in (c, f"{c}_lo", f"{c}_hi", f"{c} n")]
    cols += ["outages"] + with_ci_columns(scores, scores)
    labels = {c: f"{c} after fix" for c in cps}
    labels.update(ade="ADE [m]", fde="FDE [m]", fde_p95="FDE p95 [m]", miss_rate="miss rate")
    return Table(
        rows_frame(rows, cols),
        "outages",
        labels,
        {"miss_rate": 2},
        {c: f"{c} n" for c in cps},
        ci=ci_map([*cps, *scores]),
    )


def gate_table(res: Mapping[str, Any]) -> Table:
    """Fixes the outlier gate rejected, per predictor."""
    rows = [
        {
            "predictor": p,
            "rejected": g["rejected"],
            "fixes fed": g["fixes_fed"],
            "rejected [%]": 100.0 * g["rejected"] / g["fixes_fed"]
            if g["fixes_fed"]
            else float("nan"),
            "drives with rejections": g["drives_with_rejections"],
        }
        for p, g in res["gate"]["predictors"].items()
    ]
    cols = ["predictor", "rejected", "fixes fed", "rejected [%]", "drives with rejections"]
    return Table(rows_frame(rows, cols), "gate", digits={"rejected [%]": 2})


def gate_drive_table(res: Mapping[str, Any]) -> Table:
    """Per drive with a rejection: fixes fed and rejected per predictor."""
    preds = list(res["gate"]["predictors"])
    rows = [
        {
            "drive": d["name"],
            "fixes fed": d["gps_fed"],
            **{f"{p} rejected": d["rejected"].get(p, 0) for p in preds},
        }
        for d in res["drives"]
        if any(d.get("rejected", {}).values())
    ]
    return Table(
        rows_frame(rows, ["drive", "fixes fed"] + [f"{p} rejected" for p in preds]), "gate-drives"
    )


def drives_table(res: Mapping[str, Any]) -> Table:
    """Per drive: data set, reference (or why it was skipped), each predictor's future mean
    [m] and, with a bound (schema 1.9), the bound's (``limit future mean [m]``)."""
    preds = list(res["predictors"])
    bound = bool(res.get("limit"))
    rows = []
    for d in res["drives"]:
        if d["skipped"]:
            rows.append(
                {
                    "drive": d["name"],
                    "data set": d["dataset"],
                    "reference": f"skipped: {d['skipped']}",
                }
            )
            continue
        mark = "".join(f" ({p} trained on it)" for p in d.get("trained_on", []))
        row = {"drive": d["name"] + mark, "data set": d["dataset"], "reference": d["reference"]}
        for p in preds:
            put_figure(
                row, f"{p} future mean [m]", d["predictors"].get(p, {}).get("future"), "mean_m"
            )
        if bound:
            row[LIMIT_DRIVE_COLUMN] = drive_limit_mean(d)
        rows.append(row)
    cols = [f"{p} future mean [m]" for p in preds]
    shown = with_ci_columns(["drive", "data set", "reference", *cols], cols)
    return Table(
        rows_frame(rows, shown + [LIMIT_DRIVE_COLUMN] * bound),
        "drives",
        ci=ci_map(cols),
    )
