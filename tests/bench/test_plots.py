"""The run's figures (posbench.figures): never raise on thin data, formats, warm-up, bins,
per-drive error over time, and the report's Plots section."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import posbench.figures.per_drive as per_drive
import posbench.figures.style as style
from posbench.figures.distributions import (
    plot_error_cdf,
    plot_error_vs_since_fix,
    plot_error_vs_speed,
)
from posbench.figures.maps import plot_trajectory_error
from posbench.figures.per_drive import draw_error_over_time
from posbench.figures.style import NothingToPlot, PlotsWritten, check_formats
from posbench.figures.writer import FIGURES, write_plots
from posbench.metrics.outages import SINCE_FIX_CURVE_EDGES_S, since_fix_bins

MAGIC = {"png": b"\x89PNG", "pdf": b"%PDF", "svg": b"<?xml"}
ALL = [*FIGURES, "error_over_time"]


def make_traces(
    n_fix: int = 200,
    preds: tuple[str, ...] = ("cv", "kf"),
    drives: int = 2,
    dt: float = 0.5,
    seed: int = 0,
) -> pd.DataFrame:
    """Synthetic traces: per drive, a car on a 60 m circle at 10 m/s; one future query per
    fix (every ``dt`` s) and three now queries between fixes; errors ~ 5-50 cm; an outage
    (ids 0) from 30 to 34 s where the drive is long enough; labels straight / turn."""
    rng = np.random.default_rng(seed)
    frames = []
    for d in range(drives):
        t_fix = np.arange(n_fix) * dt
        for p_i, p in enumerate(preds):
            for kind, tq in (
                ("future", t_fix + 0.2),
                ("now", (t_fix[:, None] + np.array([0.1, 0.2, 0.3])).ravel()),
            ):
                a = tq * 10 / 60
                ref = np.c_[60 * np.cos(a), 60 * np.sin(a)]
                err = rng.lognormal(np.log(0.05 * (p_i + 1)), 0.5, tq.size)
                ang = rng.uniform(0, 2 * np.pi, tq.size)
                xy = ref + err[:, None] * np.c_[np.cos(ang), np.sin(ang)]
                outage = np.where((tq > 30) & (tq < 34), 0, -1)
                frames.append(
                    pd.DataFrame(
                        {
                            "dataset": "synthetic",
                            "drive": f"drive-{d}",
                            "predictor": p,
                            "kind": kind,
                            "t_issue": tq - (0.2 if kind == "future" else 0.0),
                            "t_query": tq,
                            "x": xy[:, 0],
                            "y": xy[:, 1],
                            "x_ref": ref[:, 0],
                            "y_ref": ref[:, 1],
                            "error_m": np.hypot(*(xy - ref).T),
                            "label": pd.Categorical(
                                np.where((tq % 40) < 20, "straight", "turn"),
                                categories=[
                                    "straight",
                                    "turn",
                                    "roundabout",
                                    "start_stop",
                                    "unlabelled",
                                ],
                            ),
                            "speed_mps": np.full(tq.size, 10.0),
                            "since_fix_s": tq - np.floor(tq / dt) * dt,
                            "outage": outage,
                            # reported covariance: isotropic, per-axis sigma near the error's size
                            "cov_xx": np.full(tq.size, (0.05 * (p_i + 1)) ** 2),
                            "cov_xy": 0.0,
                            "cov_yy": np.full(tq.size, (0.05 * (p_i + 1)) ** 2),
                        }
                    )
                )
    return pd.concat(frames, ignore_index=True)


def res_for(traces: pd.DataFrame) -> dict:
    return {"predictors": {p: {} for p in dict.fromkeys(traces.predictor)} if len(traces) else {}}


def check_files(w: PlotsWritten, formats=("png",)) -> None:
    """Every file is a real image of its format; every figure is written or has a note,
    and no note is a failure."""
    for f in w.files:
        assert f.read_bytes()[:5].startswith(MAGIC[f.suffix[1:]]), f
        assert f.suffix[1:] in formats
    names = {f.stem for f in w.files if f.parent.name != "drives"}
    drives = [f for f in w.files if f.parent.name == "drives"]
    for n in FIGURES:
        assert (n in names) != (n in w.notes), (n, w.notes)
    assert bool(drives) or "error_over_time" in w.notes
    assert not any(v.startswith("failed") for v in w.notes.values()), w.notes


@pytest.mark.slow
def test_full_traces_write_every_figure_and_one_file_per_drive(tmp_path):
    tr = make_traces()
    w = write_plots(tr, res_for(tr), tmp_path)
    check_files(w)
    assert w.notes == {}
    assert {f.name for f in w.files if f.parent == tmp_path} == {f"{n}.png" for n in FIGURES}
    assert sorted(
        f.relative_to(tmp_path).as_posix() for f in w.files if f.parent.name == "drives"
    ) == ["drives/drive-0-error_over_time.png", "drives/drive-1-error_over_time.png"]


@pytest.mark.slow
@pytest.mark.parametrize(
    "case",
    [
        "no columns",
        "0 rows",
        "1 row",
        "3 rows",
        "all NaN errors",
        "all zero errors",
        "single predictor",
        "no speed",
    ],
)
def test_thin_traces_never_raise(tmp_path, case):
    full = make_traces(n_fix=3, drives=1)
    tr = {
        "no columns": pd.DataFrame(),
        "0 rows": full.iloc[:0],
        "1 row": full.iloc[:1],
        "3 rows": full[full.kind == "future"].iloc[:3],
        "all NaN errors": full.assign(error_m=np.nan, x_ref=np.nan, y_ref=np.nan),
        "all zero errors": full.assign(error_m=0.0, x=full.x_ref, y=full.y_ref),
        "single predictor": make_traces(preds=("kf",), drives=1),
        "no speed": full.assign(speed_mps=np.nan),
    }[case]
    w = write_plots(tr, res_for(tr), tmp_path)
    check_files(w)
    if case in ("no columns", "0 rows"):
        assert w.files == [] and set(w.notes) == set(ALL)
        assert set(w.notes.values()) == {"no query in this run"}
    if case == "all NaN errors":
        assert w.files == []
        assert w.notes["error_vs_speed"] == "no query with a known speed"
        assert w.notes["error_cdf"].startswith("no query with a known error")
    if case == "no speed":
        assert w.notes["error_vs_speed"] == "no query with a known speed"
        assert (tmp_path / "error_cdf.png").exists()
    if case == "all zero errors":  # log axes: drawn at the 1 mm floor, and said so
        assert (tmp_path / "error_cdf.png").exists() and (tmp_path / "error_vs_speed.png").exists()
        fig = plot_error_cdf(tr, ["cv", "kf"])
        assert "< 1 mm drawn at 1 mm" in fig.axes[0].get_xlabel()
    if case == "single predictor":
        assert w.notes == {}


def test_gps_only_three_fixes_end_to_end_writes_report(tmp_path):
    """The reported crash: a GPS-only CSV with 3 fixes; the report is written and says why
    the figures are missing."""
    from posbench.config import RunConfig
    from posbench.pipeline.results import build_results
    from posbench.replay.runner import run_drive
    from posbench.report.markdown import write_report
    from posbench.scenarios.loaders.table import load_table
    from posbench.scoring.records import all_traces

    csv = tmp_path / "three.csv"
    csv.write_text("t,x,y\n0,0,0\n1,10,0\n2,20,0\n")
    cfg = RunConfig(predictors=("cv", "kf"))
    runs = [run_drive(load_table(csv), cfg)]
    traces = all_traces(runs)
    res = build_results(runs, cfg, [], "bench run", traces=traces)
    out = tmp_path / "out"
    from posbench.saved_run.run import Run

    written = write_report(Run.from_results(res, traces), out)
    report = (out / "report.md").read_text()
    assert out / "report.md" in written
    assert "- error_vs_speed: no query with a known speed" in report
    assert "## Plots" in report and "Not drawn:" in report


@pytest.mark.slow
def test_formats(tmp_path):
    tr = make_traces(n_fix=80, drives=1)
    w = write_plots(tr, res_for(tr), tmp_path, formats=("png", "svg", "pdf"))
    check_files(w, ("png", "svg", "pdf"))
    for n in FIGURES:
        assert all((tmp_path / f"{n}.{f}").exists() for f in ("png", "svg", "pdf")), n
    assert len(w.files) == 3 * (len(FIGURES) + 1)
    assert check_formats("PNG, svg,png") == ("png", "svg")
    assert check_formats("none") == check_formats(" None") == check_formats(()) == ()
    for bad in (("png", "jpg"), "gif", "none,png", ("png", "none"), ""):
        with pytest.raises(ValueError):
            check_formats(bad)
    with pytest.raises(ValueError, match="jpg"):
        write_plots(tr, res_for(tr), tmp_path / "bad", formats=("png", "jpg"))
    assert not (tmp_path / "bad").exists()


def test_paper_figures_reject_unknown_format_before_anything(tmp_path):
    from posbench.config import RunConfig
    from posbench.predictor_tools.paper_figures import paper_figures

    with pytest.raises(ValueError, match="tiff"):
        paper_figures(
            [], RunConfig(predictors=("cv",)), make_traces(n_fix=5), tmp_path, formats=("tiff",)
        )


def _line_max(fig) -> float:
    return max(
        float(np.nanmax(ln.get_xdata()))
        for ax in fig.axes
        for ln in ax.get_lines()
        if len(ln.get_xdata())
    )


def test_warmup_rows_excluded_from_headline_figures_and_shaded_over_time():
    tr = make_traces(n_fix=80, drives=1)
    warm = tr.t_query < 1.0
    tr.loc[warm, "error_m"] = 500.0  # a predictor's first queries before the second fix
    # old traces (no column): the warm-up errors are in the CDF
    assert _line_max(plot_error_cdf(tr, ["cv", "kf"])) == 500.0
    tr["warmup"] = warm
    cdf = plot_error_cdf(tr, ["cv", "kf"])
    assert _line_max(cdf) < 10 and "warm-up excluded" in cdf.get_suptitle()
    speed = plot_error_vs_speed(tr, ["cv", "kf"])
    assert max(float(np.nanmax(ln.get_ydata())) for ln in speed.axes[0].get_lines()) < 1
    traj = plot_trajectory_error(tr, ["cv", "kf"])
    assert traj.axes[-1].get_ylabel() == "future-point error [m]"  # the colour bar
    assert traj.axes[-1].get_ylim()[1] < 10
    # over time: the warm-up is kept (log10(500) ~ 2.7) and marked
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    assert draw_error_over_time(ax, tr, ["cv", "kf"], style.colors_for(["cv", "kf"]))
    ys = np.concatenate([ln.get_ydata() for ln in ax.get_lines()])
    assert np.nanmax(ys) == pytest.approx(np.log10(500.0))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "warm-up" in labels and "GPS outage (1)" in labels
    assert "straight" in labels and "turn" in labels


def test_error_over_time_shades_each_outage_min_to_max():
    tr = make_traces(n_fix=100, drives=1)
    tr.loc[(tr.t_query > 40) & (tr.t_query < 41), "outage"] = 1
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    draw_error_over_time(ax, tr, ["cv", "kf"], style.colors_for(["cv", "kf"]))
    hatched = [c for c in ax.collections if c.get_hatch()]
    assert len(hatched) == 1
    spans = sorted(
        (round(p.get_extents().x0, 2), round(p.get_extents().x1, 2)) for p in hatched[0].get_paths()
    )
    o = tr[tr.outage >= 0].groupby("outage").t_query.agg(["min", "max"]).round(2)
    assert spans == list(zip(o["min"], o["max"], strict=True))
    assert ax.get_xlabel() == "drive time [s]" and "[m]" in ax.get_ylabel()


def test_empty_bins_are_dropped_and_axes_have_units():
    tr = make_traces(n_fix=80, drives=1)  # 40 s: the outage at 30-34 s is in
    tr["speed_mps"] = np.where(tr.t_query < 15, 2.0, 12.0)  # bins 0.5-5 and 10-15 only
    fig = plot_error_vs_speed(tr, ["cv", "kf"])
    ax = fig.axes[0]
    ticks = [t.get_text().split("\n")[0] for t in ax.get_xticklabels()]
    assert ticks == ["0.5-5", "10-15"]
    assert ax.get_xlabel().startswith("speed [m/s]") and "[m]" in ax.get_ylabel()
    assert all(np.isfinite(ln.get_ydata()).all() for ln in ax.get_lines())
    sf = plot_error_vs_since_fix(tr, ["cv", "kf"])
    occupied = np.unique(
        since_fix_bins(tr[tr.kind == "now"].since_fix_s, SINCE_FIX_CURVE_EDGES_S, open_last=True)
    )
    assert all(len(ln.get_xdata()) == occupied.size for ln in sf.axes[0].get_lines())
    assert sf.axes[0].get_xlabel().startswith("time since last fix [s]")
    no_outage = tr.assign(outage=-1)
    with pytest.raises(NothingToPlot, match="no GPS outage"):
        plot_error_vs_since_fix(no_outage, ["cv", "kf"])


def test_trajectory_error_one_panel_per_predictor_one_colour_scale():
    tr = make_traces(n_fix=80, preds=("cv", "kf", "poly", "ekf"), drives=1)
    fig = plot_trajectory_error(tr, ["cv", "kf", "poly", "ekf"])
    panels = [ax for ax in fig.axes if ax.get_visible() and ax.get_xlabel() == "east [m]"]
    assert [ax.get_title().split(":")[0] for ax in panels] == ["cv", "kf", "poly", "ekf"]
    from matplotlib.collections import LineCollection

    norms = {id(c.norm) for ax in panels for c in ax.collections if isinstance(c, LineCollection)}
    assert len(norms) == 1
    # the colour of a segment is its predictor's error there: kf (2x cv's median) is brighter
    arrays = [
        next(c for c in ax.collections if isinstance(c, LineCollection)).get_array()
        for ax in panels[:2]
    ]
    assert np.median(np.asarray(arrays[1])) > np.median(np.asarray(arrays[0]))


@pytest.mark.slow
def test_drive_figures_are_capped_and_say_so(tmp_path, monkeypatch):
    monkeypatch.setattr(per_drive, "MAX_DRIVE_FIGURES", 2)
    tr = make_traces(n_fix=40, drives=3)
    w = write_plots(tr, res_for(tr), tmp_path)
    assert len([f for f in w.files if f.parent.name == "drives"]) == 2
    assert "2 of 3 drives with the largest mean future-point error" in w.notes["error_over_time"]


@pytest.mark.slow
def test_drive_plots_limit_picks_the_worst_drives(tmp_path):
    tr = make_traces(n_fix=40, drives=3)
    names = list(dict.fromkeys(tr.drive.astype(str)))
    worst = names[1]
    tr.loc[tr.drive.astype(str) == worst, "error_m"] *= 10
    chosen, note = per_drive.drives_to_plot(tr, 1)
    assert chosen == [worst] and "--drive-plots all" in note
    assert per_drive.drives_to_plot(tr, None) == (names, None)
    assert per_drive.drives_to_plot(tr, 0)[0] == []
    w = write_plots(tr, res_for(tr), tmp_path, drive_plots=1)
    assert [f.name for f in w.files if f.parent.name == "drives"] == [
        f"{worst}-error_over_time.png"
    ]


@pytest.mark.slow
def test_report_prints_notes_and_links_per_drive_files(tmp_path):
    from posbench.config import RunConfig
    from posbench.pipeline.results import build_results
    from posbench.replay.runner import run_drive
    from posbench.report.markdown import write_report
    from posbench.scenarios.synthetic import default_drives
    from posbench.scoring.records import all_traces

    cfg = RunConfig(predictors=("cv", "kf"))
    runs = [run_drive(default_drives()[0], cfg)]
    traces = all_traces(runs)
    res = build_results(runs, cfg, [], "bench run", traces=traces)
    from posbench.saved_run.run import Run

    write_report(Run.from_results(res, traces), tmp_path, formats=("svg", "png"))
    md = (tmp_path / "report.md").read_text()
    drive = runs[0].name
    assert f"- [{drive}](drives/{drive}-error_over_time.png)" in md
    assert "![path.png](path.png)" in md and "![trajectory_error.png](trajectory_error.png)" in md
    assert "- error_vs_since_fix: no GPS outage in this run" in md
    assert (tmp_path / "path.svg").exists() and (
        tmp_path / f"drives/{drive}-error_over_time.svg"
    ).exists()


def test_paper_figures_have_titles_and_every_format(tmp_path, monkeypatch):
    import posbench.predictor_tools.paper_figures as figures
    from posbench.config import RunConfig
    from posbench.replay.runner import run_drive
    from posbench.scenarios.synthetic import default_drives
    from posbench.scoring.records import all_traces

    drive = default_drives()[2]
    cfg = RunConfig(predictors=("kf-paper", "lstm"))
    runs = [run_drive(drive, cfg)]
    titles = []

    def spy(fig, folder, stem, formats, dpi=style.DPI):
        titles.append([ax.get_title() for ax in fig.axes])
        assert all(
            ax.get_xlabel() == "east [m]" and ax.get_ylabel() == "north [m]" for ax in fig.axes
        )
        return style.save_figure(fig, folder, stem, formats, dpi)

    monkeypatch.setattr(figures, "save_figure", spy)
    figs = figures.paper_figures(
        [drive], cfg, all_traces(runs), tmp_path, runs, formats=("svg", "png")
    )
    assert [f for f, _ in figs] == [
        "paper_fig_prediction.png",
        "paper_fig_current_position.png",
        "paper_fig_path.png",
        "paper_fig_kalman.png",
    ]
    assert len(titles) == 4 and all(t and all(t) for t in titles)
    for f, _ in figs:
        stem = f.removesuffix(".png")
        assert (tmp_path / f"{stem}.svg").read_bytes()[:5] == MAGIC["svg"]
        assert (tmp_path / f).read_bytes()[:4] == MAGIC["png"]
