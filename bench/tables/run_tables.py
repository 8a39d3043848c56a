"""The tables of a run's figures, as report.md and the terminal show them: the headline
(future and now errors with their intervals, latency), warm-up, per data set, route type
(the paper's Table I layout), speed, outages, the outlier gate and per drive. Each reads
the run's ``results`` and returns a numeric :class:`~posbench.tables.table.Table`."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

from posbench.metrics.accuracy import speed_bin_order
from posbench.scenarios.labels import LABELS
from posbench.tables.limit import (
    drive_limit_mean,
    label_limit_mean,
    limit_rows,
    limit_scope,
    ratio_cells,
    ratio_digits,
    ratio_labels,
    with_ratio_columns,
)
from posbench.tables.table import Table, as_float, is_finite, rows_frame

PAPER_TABLE_CM = {"straight": 16.6, "turn": 12.1, "roundabout": 9.7, "start_stop": 4.2}
PAPER_OVERALL = "11 (LSTM), 46 (Kalman)"
LABEL_TITLES = {
    "straight": "Straight path / full speed",
    "turn": "Turn",
    "roundabout": "Roundabout",
    "start_stop": "Starting / stopping",
}
TRAINED_MARK = " *"


# ------------------------------------------------------------------ builders
def trained_in_run(res: Mapping[str, Any]) -> dict[str, list[str]]:
    """Per predictor with marked drives, those of this run: the drives its learned model was
    trained on, or the development drives of its tuning (a tuned baseline); non-empty only."""
    names = {d["name"] for d in res["drives"] if not d["skipped"]}
    out = {}
    for p, drives in res.get("training_drives", {}).items():
        mine = sorted(names & set(drives))
        if mine:
            out[p] = mine
    return out


def put_figure(
    row: dict[str, Any],
    col: str,
    summary: Mapping[str, Any] | None,
    figure: str,
    scale: float = 1.0,
) -> None:
    """``row[col]``: ``summary[figure]`` x ``scale``; ``row[col_lo]``, ``row[col_hi]``: its
    95 % interval (``ci95``; NaN when the run has none)."""
    summary = summary or {}
    row[col] = scale * as_float(summary.get(figure))
    lo, hi = ((summary.get("ci95") or {}).get(figure) or [None, None])[:2]
    row[f"{col}_lo"], row[f"{col}_hi"] = scale * as_float(lo), scale * as_float(hi)


def with_ci_columns(cols: Sequence[str], with_ci: Sequence[str]) -> list[str]:
    """``cols`` with each column of ``with_ci`` followed by its ``_lo``, ``_hi`` columns."""
    return [x for c in cols for x in ((c, f"{c}_lo", f"{c}_hi") if c in with_ci else (c,))]


def ci_map(cols: Sequence[str]) -> dict[str, tuple[str, str]]:
    return {c: (f"{c}_lo", f"{c}_hi") for c in cols}


SUMMARY_LABELS = {
    "predictor": "predictor",
    "future_mean": "future mean [m]",
    "future_median": "median",
    "future_rmse": "RMSE",
    "future_p95": "p95",
    "future_max": "max",
    "future_n": "n",
    "now_mean": "now mean [m]",
    "now_p95": "now p95",
    "now_n": "n",
    "missing": "missing",
    # measured in the replay's worker processes, beside each other on the machine's cores
    # (the report's glossary says so; `bench latency` gives single-process figures)
    "step_p50": "worker step p50 [us]",
    "step_p99": "worker step p99 [us]",
    "query_p50": "worker query p50 [us]",
}
LATENCY_DIGITS = {"step_p50": 1, "step_p99": 1, "query_p50": 1}
#: the columns of the summary table that carry a 95 % interval (all means, medians, p95s)
SUMMARY_CI = ("future_mean", "future_median", "future_p95", "now_mean", "now_p95")


def summary_table(res: Mapping[str, Any], held_out: bool = False, compact: bool = False) -> Table:
    """The headline: per predictor, future and now errors [m] with their 95 % intervals,
    unanswered queries, latency [us] as measured in the replay's workers. A predictor
    trained on some of the run's drives is marked ``*``. ``held_out``: over the drives no
    predictor trained or tuned on (no latency: it is run-wide). ``compact`` (the terminal):
    intervals on the means only. With a bound (schema 1.9), each predictor's ``x limit``
    beside its means and the bound's rows below (:mod:`posbench.tables.limit`; not over the
    held-out drives)."""
    trained = trained_in_run(res)
    src = res["held_out_all"]["predictors"] if held_out else res["predictors"]
    bound = None if held_out else limit_scope(res)
    rows = []
    for name, p in src.items():
        f, n = p["future"], p["now"]
        row: dict[str, Any] = {
            "predictor": name + (TRAINED_MARK if name in trained and not held_out else "")
        }
        for col, summ, fig in (
            ("future_mean", f, "mean_m"),
            ("future_median", f, "median_m"),
            ("future_rmse", f, "rmse_m"),
            ("future_p95", f, "p95_m"),
            ("future_max", f, "max_m"),
            ("now_mean", n, "mean_m"),
            ("now_p95", n, "p95_m"),
        ):
            put_figure(row, col, summ, fig)
        row.update(
            future_n=f["count"], now_n=n["count"], missing=f.get("missing", 0) + n.get("missing", 0)
        )
        if not held_out:
            lat = res["predictors"][name]
            row.update(
                step_p50=as_float(lat["latency_us"].get("p50")),
                step_p99=as_float(lat["latency_us"].get("p99")),
                query_p50=as_float(lat["query_us"].get("p50")),
            )
        if bound is not None:
            row.update(ratio_cells(res, name))
        rows.append(row)
    shown_ci = ("future_mean", "now_mean") if compact else SUMMARY_CI
    cols = with_ci_columns(
        list(SUMMARY_LABELS) if not held_out else list(SUMMARY_LABELS)[:11], shown_ci
    )
    labels, digits = dict(SUMMARY_LABELS), dict(LATENCY_DIGITS)
    if bound is not None:
        rows += limit_rows(res, bound, {"future": "future_n", "now": "now_n"})
        cols = with_ratio_columns(cols, bool(bound.get("imu")))
        labels.update(ratio_labels())
        digits.update(ratio_digits())
    return Table(
        rows_frame(rows, cols),
        "held_out" if held_out else "summary",
        labels,
        digits,
        ci=ci_map(shown_ci),
    )


#: the mark after a predictor's name on the first screen: report.md flags it (it lies below the
#: limit, loses to constant velocity, ...); the lines under the table say what
FLAG_MARK = " !"
#: the columns of the first screen's table (those of :func:`summary_table` it keeps)
FIRST_SCREEN_COLUMNS = ("predictor", "future_mean", "future_xlim", "now_mean", "step_p50")


def short_limit_name(name: str | None) -> str:
    """A bound's row name without its model in brackets: ``limit (PCRB, CA model)`` ->
    ``limit`` ("" for None)."""
    return (name or "").split(" (")[0]


def first_screen_table(
    res: Mapping[str, Any], flagged: Collection[str] = (), held_out: bool = False
) -> Table:
    """The terminal's headline, narrow enough to read at a glance (100 columns for the
    default run): per predictor its future and now mean error [m] with their 95 % intervals,
    its future ``x limit`` against the limit that applies to it (with IMU for a predictor that
    reads the IMU, results.json's ``limit.reads_imu``) and its median fix step [us], the
    bound's rows below; a predictor
    in ``flagged`` (report.md flags it) is marked ``!`` after its name; the bound's rows are
    named without their model (:func:`short_limit_name`). The same figures as
    :func:`summary_table`, a choice of its columns."""
    full = summary_table(res, held_out=held_out, compact=True)
    frame = full.frame.copy()
    keep = [x for c in FIRST_SCREEN_COLUMNS for x in (c, *full.ci.get(c, ())) if x in frame.columns]
    lim = res.get("limit") or {}
    short = {lim.get(k): short_limit_name(lim.get(k)) for k in ("name", "name_imu")}
    reads_imu = lim.get("reads_imu") or {}
    if "future_xlim_imu" in frame.columns and not held_out:  # the ratio that applies
        imu = frame["predictor"].map(lambda n: bool(reads_imu.get(n.removesuffix(TRAINED_MARK))))
        frame["future_xlim"] = frame["future_xlim_imu"].where(imu, frame["future_xlim"])
    frame["predictor"] = [
        short.get(name) or name + (FLAG_MARK if name.removesuffix(TRAINED_MARK) in flagged else "")
        for name in frame["predictor"]
    ]
    labels = {**full.labels, "step_p50": "step p50 [us]"}
    return Table(
        frame[keep],
        "first_screen" + ("_held_out" if held_out else ""),
        labels,
        full.digits,
        ci={c: b for c, b in full.ci.items() if c in keep},
    )


def warmup_table(res: Mapping[str, Any]) -> Table:
    """Per predictor, the errors of the warm-up queries left out of the headline."""
    rows = []
    for name, w in res.get("excluded", {}).get("warmup", {}).items():
        f, n = w["future"], w["now"]
        row: dict[str, Any] = {"predictor": name}
        put_figure(row, "future_mean", f, "mean_m")
        put_figure(row, "now_mean", n, "mean_m")
        row.update(
            future_max=as_float(f["max_m"]),
            future_n=f["count"],
            now_max=as_float(n["max_m"]),
            now_n=n["count"],
            missing=f.get("missing", 0) + n.get("missing", 0),
        )
        rows.append(row)
    labels = {
        "future_mean": "future mean [m]",
        "future_max": "max",
        "future_n": "n",
        "now_mean": "now mean [m]",
        "now_max": "max",
        "now_n": "n",
    }
    with_ci = ("future_mean", "now_mean")
    return Table(
        rows_frame(rows, with_ci_columns(["predictor", *labels, "missing"], with_ci)),
        "warmup",
        labels,
        ci=ci_map(with_ci),
    )


DATASET_CI = ("future_mean", "future_median", "future_p95", "now_mean", "now_p95")


def dataset_table(res: Mapping[str, Any], dataset: str) -> Table:
    """One data set: per predictor, future and now errors [m] with their 95 % intervals;
    with a bound (schema 1.9), each predictor's ``x limit`` and the bound's rows."""
    bound = limit_scope(res, dataset)
    rows = []
    for name, s in res["by_dataset"][dataset].items():
        f, n = s["future"], s["now"]
        row: dict[str, Any] = {"predictor": name}
        for col, summ, fig in (
            ("future_mean", f, "mean_m"),
            ("future_median", f, "median_m"),
            ("future_p95", f, "p95_m"),
            ("now_mean", n, "mean_m"),
            ("now_p95", n, "p95_m"),
        ):
            put_figure(row, col, summ, fig)
        row.update(future_n=f["count"], now_n=n["count"])
        if bound is not None:
            row.update(ratio_cells(res, name, dataset))
        rows.append(row)
    labels: dict[str, str] = {
        "future_mean": "future mean [m]",
        "future_median": "median",
        "future_p95": "p95",
        "future_n": "n",
        "now_mean": "now mean [m]",
        "now_p95": "now p95",
        "now_n": "n",
    }
    cols = with_ci_columns(["predictor", *labels], DATASET_CI)
    digits: dict[str, int] = {}
    if bound is not None:
        rows += limit_rows(res, bound, {"future": "future_n", "now": "now_n"})
        cols = with_ratio_columns(cols, bool(bound.get("imu")))
        labels.update(ratio_labels())
        digits.update(ratio_digits())
    return Table(
        rows_frame(rows, cols),
        f"dataset-{dataset}",
        labels,
        digits,
        ci=ci_map(DATASET_CI),
    )


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
