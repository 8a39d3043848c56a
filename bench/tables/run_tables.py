"""The headline tables of a run's figures, as report.md and the terminal show them: the
summary (future and now errors with their intervals, latency), the first screen, warm-up and
per data set, and the helpers every run table shares (interval columns, the ``*`` of a
predictor trained on the run's drives). Each reads the run's ``results`` and returns a
numeric :class:`~posbench.tables.table.Table`; the breakdowns (route type, speed, outages,
gate, per drive) are :mod:`posbench.tables.breakdown_tables`."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

from posbench.tables.limit import (
    limit_rows,
    limit_scope,
    ratio_cells,
    ratio_digits,
    ratio_labels,
    with_ratio_columns,
)
from posbench.tables.table import Table, as_float, rows_frame

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
