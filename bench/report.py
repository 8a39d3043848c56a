"""Write a run's outputs: ``report.md`` (tables a person reads first), ``results.json``,
per-query traces (Parquet) and the plots (:mod:`bench.plots`)."""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from bench.plots import shown_format, write_plots
from bench.prepare import LABELS
from bench.saved_run import Run
from metrics.accuracy import speed_bin_order

PAPER_TABLE_CM = {"straight": 16.6, "turn": 12.1, "roundabout": 9.7, "start_stop": 4.2}
PAPER_OVERALL_CM = {"lstm": 11.0, "kf-paper": 46.0}
LABEL_TITLES = {"straight": "Straight path / full speed", "turn": "Turn",
                "roundabout": "Roundabout", "start_stop": "Starting / stopping"}


def _fmt_m(v: float, digits: int = 3) -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def _fmt_cm(s: dict[str, Any]) -> str:
    if not s or s.get("count", 0) == 0:
        return "- (0)"
    return f"{100 * s['mean_m']:.1f} ({s['count']})"


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


TRAINED_MARK = " *"


def trained_in_run(res: dict[str, Any]) -> dict[str, list[str]]:
    """Per learned predictor, the drives of this run its model was trained on (non-empty only)."""
    names = {d["name"] for d in res["drives"] if not d["skipped"]}
    out = {}
    for p, drives in res.get("training_drives", {}).items():
        mine = sorted(names & set(drives))
        if mine:
            out[p] = mine
    return out


def summary_rows(res: dict[str, Any], held_out: bool = False) -> list[list[str]]:
    """Rows of the headline table: per predictor, future and now errors [m], queries
    without an answer, latency [us]. A predictor trained on some of the run's drives is
    marked ``*``. ``held_out``: figures over the drives no learned predictor trained on."""
    trained = trained_in_run(res)
    src = res["held_out_all"]["predictors"] if held_out else res["predictors"]
    rows = []
    for name, p in src.items():
        f, n = p["future"], p["now"]
        lat = res["predictors"][name]
        mark = TRAINED_MARK if name in trained and not held_out else ""
        row = [name + mark, _fmt_m(f["mean_m"]), _fmt_m(f["median_m"]), _fmt_m(f["rmse_m"]),
               _fmt_m(f["p95_m"]), _fmt_m(f["max_m"]), str(f["count"]),
               _fmt_m(n["mean_m"]), _fmt_m(n["p95_m"]), str(n["count"]),
               str(f.get("missing", 0) + n.get("missing", 0))]
        if not held_out:  # latency is measured over the whole run only
            row += [_fmt_m(lat["latency_us"]["p50"], 1), _fmt_m(lat["latency_us"]["p99"], 1),
                    _fmt_m(lat["query_us"]["p50"], 1)]
        rows.append(row)
    return rows


SUMMARY_HEADER = ["predictor", "future mean [m]", "median", "RMSE", "p95", "max", "n",
                  "now mean [m]", "now p95", "n", "missing", "step p50 [us]", "step p99 [us]",
                  "query p50 [us]"]
HELD_OUT_HEADER = SUMMARY_HEADER[:11]


def trained_note(res: dict[str, Any]) -> str:
    """The footnote of ``*`` rows: which model, trained on which of the run's drives."""
    trained = trained_in_run(res)
    if not trained:
        return ""
    n_drives = sum(1 for d in res["drives"] if not d["skipped"])
    parts = [f"{p} (model {res['models'][p]['model']}) was trained on {len(d)} of these "
             f"{n_drives} drives" for p, d in trained.items()]
    return "* " + "; ".join(parts) + ": its figures on them flatter it; see the held-out table."


def excluded_note(res: dict[str, Any]) -> str:
    """One sentence: how many queries the headline figures leave out, and why."""
    ex = res.get("excluded", {})
    first = next(iter(res["predictors"]), None)
    if first is None:
        return ""
    warm = ex.get("warmup", {}).get(first, {})
    n_warm = sum(warm.get(k, {}).get("count", 0) + warm.get(k, {}).get("missing", 0)
                 for k in ("future", "now"))
    n_noref = sum(ex.get("no_reference", {}).get(first, {}).values())
    return (f"Excluded from these figures, per predictor: {n_warm} warm-up queries (issued before "
            f"a drive's second received fix, when no predictor can know a velocity) and "
            f"{n_noref} queries without a reference position (past the end of the truth or of "
            f"the fixes).")


def warmup_rows(res: dict[str, Any]) -> list[list[str]]:
    """Per predictor, the error figures of the warm-up queries left out of the headline."""
    rows = []
    for name, w in res.get("excluded", {}).get("warmup", {}).items():
        f, n = w["future"], w["now"]
        rows.append([name, _fmt_m(f["mean_m"]), _fmt_m(f["max_m"]), str(f["count"]),
                     _fmt_m(n["mean_m"]), _fmt_m(n["max_m"]), str(n["count"]),
                     str(f.get("missing", 0) + n.get("missing", 0))])
    return rows


WARMUP_HEADER = ["predictor", "future mean [m]", "max", "n", "now mean [m]", "max", "n", "missing"]

MISSING_NOTE = ("`missing`: queries a predictor answered with no position (NaN) although a "
                "reference exists, e.g. before its first fix; they are counted, not averaged, so "
                "a predictor cannot look better by abstaining.")


def label_table(res: dict[str, Any], dataset: str, kind: str, held_out: bool = False) -> str:
    """The paper's Table I layout: route type x mean error [cm] (query count), one column
    per predictor, the paper's LSTM figure beside. ``held_out``: only drives no learned
    predictor was trained on."""
    preds = list(res["predictors"])
    paper = kind == "future"  # the paper's Table I measures the future point only
    header = ["route type"] + [f"{p} [cm] (n)" for p in preds] + (["paper LSTM [cm]"] if paper else [])
    if held_out:
        by_label = {p: v for p, v in res["held_out"][dataset]["by_label"].items()}
        overall_src = res["held_out"][dataset]["predictors"]
    else:
        by_label = res["by_label"].get(dataset, {})
        overall_src = res["by_dataset"].get(dataset, {})
    rows = []
    for lab in LABELS:
        row = [LABEL_TITLES[lab]]
        for p in preds:
            row.append(_fmt_cm(by_label.get(p, {}).get(kind, {}).get(lab, {})))
        if paper:
            row.append(f"{PAPER_TABLE_CM[lab]:.1f}")
        rows.append(row)
    overall = ["all"] + [_fmt_cm(overall_src.get(p, {}).get(kind, {}))
                         for p in preds] + (["11 (LSTM), 46 (Kalman)"] if paper else [])
    rows.append(overall)
    return _table(header, rows)


def write_report(run: Run, out: Path, formats: Iterable[str] = ("png",)) -> list[Path]:
    """Write the run's plots (in each of ``formats``: png, svg, pdf; ValueError on others)
    and ``report.md`` into ``out``; return the paths written. The run itself (results.json,
    traces) is written by :func:`bench.saved_run.save_run`."""
    shown = "." + shown_format(formats)  # checks the formats before anything is written
    out.mkdir(parents=True, exist_ok=True)
    plots = write_plots(run.traces, run.results, out, formats)
    (out / "report.md").write_text(render_markdown(
        run.results, [p.relative_to(out).as_posix() for p in plots.files if p.suffix == shown],
        plot_notes=plots.notes))
    return [*plots.files, out / "report.md"]


def render_markdown(res: dict[str, Any], plots: list[str],
                    plot_notes: dict[str, str] | None = None) -> str:
    """The report as Markdown. ``plots``: figure files relative to the report (those under
    ``drives/`` are listed as links, the others shown); ``plot_notes``: figure name -> why it
    was not written."""
    cfg = res["config"]
    lines = ["# posbench report", "",
             f"Command: `{res['command']}`", "",
             f"posbench {res['versions'].get('posbench')} at commit `{res.get('git_commit')}`; "
             f"horizon {cfg['horizon_s']} s; now-queries every {cfg['now_step_s']} s; "
             f"GPS profile `{cfg['gps_profile']}` (drives with truth); dropouts `{cfg['dropouts']}`; "
             f"seed {cfg['seed']}.", "",
             "Errors are Euclidean distances in metres in a local ENU frame (true metres). "
             "`future` = position at fix time + horizon, asked at the fix; `now` = current position, "
             "asked every now-step between fixes. Latency: `step` = one `observe_gps` plus the "
             "future query, `query` = one between-fix `position_at`, single process.", "",
             "## All drives", "", _table(SUMMARY_HEADER, summary_rows(res)), ""]
    for note in (trained_note(res), excluded_note(res), MISSING_NOTE):
        if note:
            lines += [note, ""]
    if res.get("held_out_all"):
        ho = res["held_out_all"]
        lines += [f"## Held-out drives ({len(ho['drives'])}: no learned predictor of this run "
                  f"was trained on them)", "", _table(HELD_OUT_HEADER, summary_rows(res, held_out=True)),
                  ""]
    if any(r[3] != "0" or r[6] != "0" for r in warmup_rows(res)):
        lines += ["## Warm-up queries (left out above)", "",
                  "Queries issued before a drive's second received fix: a cold start, not a "
                  "prediction.", "", _table(WARMUP_HEADER, warmup_rows(res)), ""]
    for ds in res["by_dataset"]:
        drives = [d for d in res["drives"] if d["dataset"] == ds]
        refs = sorted({d["reference"] for d in drives if d["reference"]})
        lines += [f"## Data set `{ds}`", "",
                  f"{len(drives)} drives; reference: {', '.join(refs) or '-'}.", ""]
        rows = []
        for name, s in res["by_dataset"][ds].items():
            f, n = s["future"], s["now"]
            rows.append([name, _fmt_m(f["mean_m"]), _fmt_m(f["median_m"]), _fmt_m(f["p95_m"]),
                         str(f["count"]), _fmt_m(n["mean_m"]), _fmt_m(n["p95_m"]), str(n["count"])])
        lines += [_table(["predictor", "future mean [m]", "median", "p95", "n", "now mean [m]",
                          "now p95", "n"], rows), ""]
        lines += ["### Route type (paper's Table I layout), future point, mean error in cm (queries)",
                  "", label_table(res, ds, "future"), ""]
        lines += ["### Route type, current position (now), mean error in cm (queries)", "",
                  label_table(res, ds, "now"), ""]
        ho = res.get("held_out", {}).get(ds)
        if ho:
            who = "; ".join(
                f"`{p}` (model {res['models'][p]['model']}) was trained on "
                + ", ".join(sorted(set(names) & set(ho["excluded_training_drives"])))
                for p, names in res.get("training_drives", {}).items()
                if set(names) & set(ho["excluded_training_drives"]))
            lines += [f"### Held-out drives only ({len(ho['drives'])} of {len(drives)})", "",
                      f"{who}: figures on those drives flatter it. On the held-out drives "
                      f"({', '.join(ho['drives']) or 'none'}):", ""]
            if ho["drives"]:
                lines += ["Future point, mean error in cm (queries):", "",
                          label_table(res, ds, "future", held_out=True), "",
                          "Current position (now), mean error in cm (queries):", "",
                          label_table(res, ds, "now", held_out=True), ""]
    if res.get("by_speed"):
        lines += ["## Future-point error by speed, mean [m] (queries)", ""]
        bins = [b for b in speed_bin_order() + ["unknown"]
                if any(res["by_speed"][p]["future"].get(b, {}).get("count", 0)
                       for p in res["by_speed"])]
        rows = []
        for p, s in res["by_speed"].items():
            rows.append([p] + [f"{_fmt_m(s['future'][b]['mean_m'])} ({s['future'][b]['count']})"
                               for b in bins])
        lines += [_table(["predictor"] + bins, rows), ""]
    if res.get("outages"):
        lines += ["## GPS outages", "",
                  "Current-position (now) error by time since the last received fix, mean [m] "
                  "(queries within 0.05 s of each checkpoint), and per outage: ADE (mean error "
                  "over the outage), FDE (error just before the fix returns), miss rate (share of "
                  "outages with FDE > 2 m).", ""]
        cps = list(next(iter(res["outages"].values()))["since_fix"])
        rows = []
        for p, o in res["outages"].items():
            sc = o["scores"]
            rows.append([p] + [f"{_fmt_m(o['since_fix'][c]['mean_m'])} ({o['since_fix'][c]['count']})"
                               for c in cps]
                        + [str(sc["outages"]), _fmt_m(sc["ade_mean_m"]), _fmt_m(sc["fde_mean_m"]),
                           _fmt_m(sc["fde_p95_m"]), _fmt_m(sc["miss_rate"], 2)])
        lines += [_table(["predictor"] + [f"{c} after fix" for c in cps]
                         + ["outages", "ADE [m]", "FDE [m]", "FDE p95 [m]", "miss rate"], rows), ""]
    lines += gate_lines(res)
    lines += ["## Drives", ""]
    preds = list(res["predictors"])
    rows = []
    for d in res["drives"]:
        if d["skipped"]:
            rows.append([d["name"], d["dataset"], f"skipped: {d['skipped']}"] + ["-"] * len(preds))
            continue
        mark = "".join(f" ({p} trained on it)" for p in d.get("trained_on", []))
        rows.append([d["name"] + mark, d["dataset"], d["reference"]] + [
            _fmt_m(d["predictors"].get(p, {}).get("future", {}).get("mean_m", float("nan")))
            for p in preds])
    lines += [_table(["drive", "data set", "reference"] + [f"{p} future mean [m]" for p in preds],
                     rows), ""]
    warn = [(d["name"], w) for d in res["drives"] for w in d["warnings"]]
    if warn:
        lines += ["## Loader warnings", ""] + [f"- `{n}`: {w}" for n, w in warn] + [""]
    if plots or plot_notes:
        shown = [p for p in plots if not p.startswith("drives/")]
        per_drive = [p for p in plots if p.startswith("drives/")]
        lines += ["## Plots", ""]
        lines += [f"![{p}]({p})" if p.endswith((".png", ".svg")) else f"- [{p}]({p})"
                  for p in shown] + [""] * bool(shown)
        if plot_notes:
            lines += ["Not drawn:", ""] + [f"- {k}: {v}" for k, v in plot_notes.items()] + [""]
        if per_drive:
            lines += ["Future-point error over time, per drive:", ""]
            lines += [f"- [{Path(p).stem.removesuffix('-error_over_time')}]({p})"
                      for p in per_drive] + [""]
    if res.get("paper_figures"):
        lines += ["## The paper's figures, from this run", ""]
        for f in res["paper_figures"]:
            lines += [f"![{f['file']}]({f['file']})", "", f"*{f['caption']}*", ""]
    lines += ["## Data", ""] + [f"- `{m['path']}`: {m['files']} files, {m['bytes']} bytes, "
                                f"sha256 `{m['sha256'][:16]}...`" for m in res["data"]] + [""]
    return "\n".join(lines)


def gate_lines(res: dict[str, Any]) -> list[str]:
    """The "GPS outlier gate" section: fixes rejected per predictor, and per drive."""
    gate = res.get("gate")
    if not gate:
        return []
    lines = ["## GPS outlier gate: fixes rejected per predictor", ""]
    if not gate.get("enabled"):
        return lines + ["Off (`--no-gate`): every fix reached the predictors, as in the paper.", ""]
    lines += ["A fix implying impossible motion (speed > 60 m/s, or a miss of the constant-velocity "
              "prediction beyond 15 m/s^2 of acceleration plus 4 sigma of fix noise; a repeated "
              "stale fix while moving) is dropped before the predictor and bridged like a "
              "missing fix. Scores still use the ungated reference.", ""]
    rows = [[p, str(g["rejected"]), str(g["fixes_fed"]),
             _fmt_m(100.0 * g["rejected"] / g["fixes_fed"] if g["fixes_fed"] else float("nan"), 2),
             str(g["drives_with_rejections"])] for p, g in gate["predictors"].items()]
    lines += [_table(["predictor", "rejected", "fixes fed", "rejected [%]", "drives with rejections"],
                     rows), ""]
    per_drive = [d for d in res["drives"] if any(d.get("rejected", {}).values())]
    if per_drive:
        preds = list(gate["predictors"])
        lines += [_table(["drive", "fixes fed"] + [f"{p} rejected" for p in preds],
                         [[d["name"], str(d["gps_fed"])]
                          + [str(d["rejected"].get(p, 0)) for p in preds] for d in per_drive]), ""]
    return lines
