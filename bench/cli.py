"""The ``bench`` command line: thin commands over scenarios, predictors, metrics and bench.

Bad user input (missing file, unknown format, unknown predictor, ...) prints one
line naming what is wrong and exits with status 2, never a traceback.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from scenarios.errors import DataError

app = typer.Typer(
    help="posbench: benchmark real-time vehicle position predictors on your drives.\n\n"
         "Start with `bench run` (built-in synthetic drives, no data needed), then point it at "
         "your recordings: `bench run --data PATH... --predictors lstm,kf`.",
    no_args_is_help=True, add_completion=False, pretty_exceptions_enable=False,
    rich_markup_mode=None)
data_app = typer.Typer(help="Look at recordings before benchmarking them.", no_args_is_help=True,
                       rich_markup_mode=None)
app.add_typer(data_app, name="data")

console = Console(width=None if sys.stdout.isatty() else 200)
err_console = Console(stderr=True)

DEFAULT_PREDICTORS = "cv,poly,kf,kf-paper,ekf,lstm"
MULTI_VALUE_OPTIONS = ("--data", "--topic", "--model")


class UsageError(Exception):
    """A command-line mistake: reported in one line, exit status 2."""


def _fail(msg: str) -> typer.Exit:
    from rich.markup import escape  # "posbench[ray]" is text, not markup

    err_console.print(f"[bold red]error:[/] {escape(msg)}", highlight=False, soft_wrap=True)
    return typer.Exit(2)


def _parse_pairs(values: list[str] | None, what: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for v in values or []:
        if "=" not in v:
            raise UsageError(f"{what} expects ROLE=VALUE, got {v!r}")
        k, val = v.split("=", 1)
        out[k.strip()] = val.strip()
    return out


def _model_options(values: list[str] | None) -> dict[str, dict[str, str]]:
    """``--model name=PATH`` pairs as per-predictor constructor options."""
    return {k: {"model": v} for k, v in _parse_pairs(values, "--model").items()}


def _command_line() -> str:
    """This invocation as a shell command, recorded in reports and model descriptions."""
    return "bench " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _parse_topics(values: list[str] | None) -> dict[str, str] | None:
    topics = _parse_pairs(values, "--topic")
    bad = set(topics) - {"gps", "imu", "speed", "truth"}
    if bad:
        raise UsageError(f"--topic roles are gps, imu, speed, truth; got {', '.join(sorted(bad))}")
    return topics or None


def _load_drives(paths: list[Path] | None, projection: str, topics: dict[str, str] | None,
                 seed: int = 0, synthetic_duration: float | None = None):
    from scenarios.loaders import iter_load

    if not paths:
        from scenarios.synthetic import default_drives, generate_drive

        if synthetic_duration is not None:
            if not synthetic_duration > 1.0:
                raise UsageError("--synthetic-duration must be more than 1 s")
            return [generate_drive(seed=seed, route="mixed", duration_s=synthetic_duration)]
        return default_drives(seed=seed)
    drives = []
    with console.status("loading drives...") as status:
        for p in paths:
            for d in iter_load(p, projection=projection, topics=topics):
                drives.append(d)
                status.update(f"loading drives... {len(drives)} ({d.name})")
    return drives


DataOpt = Annotated[list[Path] | None, typer.Option(
    "--data", "-d", help="Recordings or folders of them (any mix of ROS 1/2 bags, KITTI raw, "
    "comma2k19 segments, the paper's route pickles, CSV/Parquet). Several paths may follow one "
    "--data. Default: the built-in synthetic drives.")]
TopicOpt = Annotated[list[str] | None, typer.Option(
    "--topic", help="Pick bag topics by role when ambiguous: gps=/name imu=/name speed=/name "
    "truth=/name.")]
ProjectionOpt = Annotated[str, typer.Option(
    help="Local frame for lat/lon sources: 'enu' (true metres, default) or 'mercator' (the paper's "
         "spherical Mercator, for parity only: +1/cos(lat) scale error, ~+52 %% at 49 deg N).")]


@app.command()
def run(
    data: DataOpt = None,
    predictors: Annotated[str, typer.Option(
        "--predictors", "-p", help="Comma-separated predictor names (see `bench predictors`).")
    ] = DEFAULT_PREDICTORS,
    horizon: Annotated[float, typer.Option(help="Future-point horizon after each fix [s].")] = 0.2,
    gps_profile: Annotated[str, typer.Option(
        help="GPS input for drives with truth: native (their own fixes), none (exact), rtk (~2 cm), "
             "consumer (~1 m, correlated).")] = "rtk",
    gps_latency: Annotated[float, typer.Option(help="Receiver latency of drawn fixes [s].")] = 0.0,
    dropouts: Annotated[str, typer.Option(
        help="GPS dropouts: none, random:P, outages (0.5/1/2/5 s), outage:L.")] = "none",
    seed: Annotated[int, typer.Option(help="Master seed (GPS draws, dropouts, synthetic data).")] = 0,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")] = Path("bench-out"),
    workers: Annotated[int, typer.Option(help="Parallel processes (one drive each).")] = 2,
    model: Annotated[list[str] | None, typer.Option(
        "--model", help="Model file per predictor, e.g. lstm-authors=PATH.onnx or lstm=DIR.")] = None,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
    include_poor_truth: Annotated[bool, typer.Option(
        help="Also score drives whose truth is poor (median accuracy > 1 m).")] = False,
    synthetic_duration: Annotated[float | None, typer.Option(
        help="Without --data: one synthetic mixed drive of this length [s] instead of the "
             "built-in set (e.g. 36000 for a 10-hour soak test).")] = None,
    rerun: Annotated[Path | None, typer.Option(
        "--rerun", help="Also write a rerun recording (.rrd) of every drive (needs the viz extra; "
        "open it with `bench view FILE.rrd`).")] = None,
    executor: Annotated[str, typer.Option(
        help="Where to run: local (processes, --workers) or ray (one Ray task per drive and "
             "predictor; needs the ray extra).")] = "local",
    address: Annotated[str | None, typer.Option(
        help="Ray cluster to use with --executor ray (e.g. ray://head:10001 or auto); default: "
             "start a local Ray instance with --workers CPUs.")] = None,
    gate: Annotated[bool, typer.Option(
        "--gate/--no-gate", help="GPS outlier gate: drop fixes implying impossible motion before "
        "the predictors see them (counted in the report). --no-gate: the paper's ungated input.")
    ] = True,
) -> None:
    """Replay drives through predictors and write report.md, results.json, traces and plots.

    Example: bench run --predictors lstm,kf --data ../shared/data/kitti_raw
    """
    from bench.config import GPS_PROFILES, RunConfig
    from bench.executors import EXECUTORS, RAY_MISSING, ExecutorError, ray_available
    from bench.fetch import local_paths
    from predictors.registry import available

    try:
        if executor not in EXECUTORS:
            raise UsageError(f"--executor must be one of {', '.join(EXECUTORS)}")
        if address and executor != "ray":
            raise UsageError("--address is for --executor ray")
        if executor == "ray" and not ray_available():
            raise UsageError(RAY_MISSING)
        names = tuple(p.strip() for p in predictors.split(",") if p.strip())
        unknown = [n for n in names if n not in available()]
        if unknown:
            raise UsageError(f"unknown predictor(s) {', '.join(unknown)}; known: "
                             f"{', '.join(sorted(available()))}")
        if gps_profile not in GPS_PROFILES:
            raise UsageError(f"--gps-profile must be one of {', '.join(GPS_PROFILES)}")
        options = _model_options(model)
        if "lstm-authors" in names and "lstm-authors" not in options:
            raise UsageError("lstm-authors needs the authors' network: --model lstm-authors=PATH.onnx "
                             "(e.g. ../shared/models/authors/gps_interpolation_model2.onnx)")
        cfg = RunConfig(predictors=names, horizon_s=horizon, gps_profile=gps_profile,
                        gps_latency_s=gps_latency, dropouts=dropouts, seed=seed,
                        exclude_poor_truth=not include_poor_truth, predictor_options=options,
                        gate=gate)
        if rerun is not None:
            try:
                import rerun as _rr  # noqa: F401
            except ImportError:
                raise UsageError("--rerun needs the viz extra: pip install 'posbench[viz]'") from None
        with local_paths(data) as data:  # fsspec URLs -> local copies for the loaders
            drives = _load_drives(data, projection, _parse_topics(topic), seed=seed,
                                  synthetic_duration=synthetic_duration)
            _run(drives, cfg, data, out, workers, rerun, executor, address)
    except (DataError, UsageError, ExecutorError) as e:
        raise _fail(str(e)) from None


def _run(drives, cfg, data, out: Path, workers: int, rerun: Path | None = None,
         executor: str = "local", address: str | None = None) -> None:
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
    from rich.table import Table

    from bench.executors import run_drives
    from bench.report import SUMMARY_HEADER, summary_rows, write_report
    from bench.results import aggregate, all_traces, tree_hash

    command = _command_line()
    with Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), TextColumn("{task.fields[last]}"), console=console) as prog:
        task = prog.add_task(f"{len(drives)} drives x {len(cfg.predictors)} predictors",
                             total=len(drives), last="")
        runs = run_drives(drives, cfg, executor, workers=workers, address=address,
                          on_done=lambda r: prog.update(task, advance=1, last=r.name))
    manifest = ([tree_hash(p) for p in data] if data else
                [{"path": "built-in synthetic drives", "files": 0, "bytes": 0,
                  "sha256": f"generator seed {cfg.seed}"}])
    traces = all_traces(runs)
    res = aggregate(runs, cfg, manifest, command, traces=traces)
    from bench.figures import paper_figures

    out.mkdir(parents=True, exist_ok=True)
    res["paper_figures"] = [{"file": f, "caption": c} for f, c in
                            paper_figures(list(drives), cfg, traces, out, runs)]
    write_report(res, traces, out)
    table = Table(title=f"{len(runs)} drives - errors in metres, latency in microseconds")
    for h in SUMMARY_HEADER:
        table.add_column(h, justify="left" if h == "predictor" else "right")
    for row in summary_rows(res):
        table.add_row(*row)
    console.print(table)
    skipped = [r for r in runs if r.skipped]
    if skipped:
        console.print(f"skipped {len(skipped)} drives: " + "; ".join(
            f"{r.name} ({r.skipped})" for r in skipped))
    console.print(f"wrote {out / 'report.md'}, results.json, traces.parquet and plots")
    if rerun is not None:
        from bench.rerun_log import write_recording

        with console.status(f"writing rerun recording {rerun}..."):
            write_recording(rerun, runs, list(cfg.predictors))
        console.print(f"wrote {rerun} (open it with: bench view {rerun})")


@data_app.command("inspect")
def inspect(
    paths: Annotated[list[Path] | None, typer.Argument(
        help="Recordings or folders (default: the built-in synthetic drives).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON list, one object per drive.")
                       ] = False,
    topic: TopicOpt = None,
    projection: ProjectionOpt = "enu",
) -> None:
    """Show what is in each drive: duration, distance, fix intervals, IMU rate, speeds, truth."""
    from rich.table import Table

    from scenarios.summary import summarize_drive

    try:
        drives = _load_drives(paths, projection, _parse_topics(topic))
    except (DataError, UsageError) as e:
        raise _fail(str(e)) from None
    rows = [summarize_drive(d) for d in drives]
    if as_json:
        print(json.dumps(rows, indent=2, default=float))
        return
    t = Table(title=f"{len(rows)} drives")
    t.add_column("drive", no_wrap=True)
    for h in ("format", "dur [s]", "dist [m]", "fixes", "fix dt p5/p50/p95/max [ms]",
              "IMU [Hz]", "speed [m/s]", "stopped", "str/turn/rbt/stop [%]", "truth (acc.)",
              "warn."):
        t.add_column(h, justify="left" if h == "format" else "right")
    for r in rows:
        q = r["gps_interval_ms"]
        acc = r["truth_median_accuracy_m"]
        truth = ("yes" + (f" ({acc:.2f} m)" if acc is not None else "")) if r["has_truth"] else "no"
        t.add_row(r["name"], r["format"], f"{r['duration_s']:.1f}", f"{r['distance_m']:.0f}",
                  str(r["gps_count"]), f"{q['p5']:.0f}/{q['p50']:.0f}/{q['p95']:.0f}/{q['max']:.0f}",
                  f"{r['imu_rate_hz']:.0f}", f"{r['speed_mps']['min']:.1f}-{r['speed_mps']['max']:.1f}",
                  f"{100 * r['fraction_stopped']:.0f}%",
                  "/".join(f"{100 * v:.0f}" for v in r["label_shares"].values()), truth,
                  str(len(r["warnings"])))
    console.print(t)
    for r in rows:
        for w in r["warnings"]:
            console.print(f"[yellow]warning[/] {r['name']}: {w}", highlight=False)


@app.command()
def view(recording: Annotated[Path, typer.Argument(help="A .rrd file written by bench run --rerun.")]
         ) -> None:
    """Open a rerun recording in the rerun viewer (needs the viz extra and a display)."""
    import shutil
    import subprocess

    if not recording.is_file():
        raise _fail(f"{recording}: no such file")
    exe = shutil.which("rerun")
    if exe is None:
        raise _fail("the rerun viewer is not installed: pip install 'posbench[viz]'")
    raise typer.Exit(subprocess.call([exe, str(recording)]))


@app.command("predictors")
def list_predictors() -> None:
    """List the registered predictors."""
    from predictors.registry import available

    for name, e in available().items():
        console.print(f"[bold]{name:13s}[/] {e.description}")


@app.command()
def train(
    data: DataOpt = None,
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for model.onnx and model.json.")
                   ] = Path("model-out"),
    epochs: Annotated[int, typer.Option(help="Maximum epochs (early stopping may end sooner).")] = 40,
    seed: Annotated[int, typer.Option(help="Seed for split, sampling and initialisation.")] = 0,
    synthetic: Annotated[int, typer.Option(help="Number of synthetic drives to add.")] = 0,
) -> None:
    """Train the LSTM predictor (needs the `train` extra: pip install 'posbench[train]')."""
    try:
        import torch  # noqa: F401
    except ImportError:
        raise _fail("bench train needs PyTorch: pip install 'posbench[train]'") from None
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from predictors.lstm.train import run_training

    command = _command_line()
    try:
        with Progress(TextColumn("[bold]training"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), TextColumn("{task.fields[loss]}"), console=console) as prog:
            task = prog.add_task("train", total=epochs, loss="")

            def progress(epoch: int, n_epochs: int, train_loss: float, val_loss: float) -> None:
                prog.update(task, completed=epoch, total=n_epochs,
                            loss=f"train {train_loss:.4f} val {val_loss:.4f}")

            info = run_training([str(p) for p in data or []], out, epochs=epochs, seed=seed,
                                synthetic=synthetic, progress=progress, command=command)
    except (DataError, UsageError) as e:
        raise _fail(str(e)) from None
    console.print(json.dumps(info.get("validation", info), indent=2, default=float))
    console.print(f"wrote {out / 'model.onnx'} and {out / 'model.json'}")


@app.command()
def latency(
    predictors: Annotated[str, typer.Option(
        "--predictors", "-p", help="Comma-separated predictor names.")] = "cv,poly,kf,kf-paper,ekf,lstm",
    steps: Annotated[int, typer.Option(help="Fix steps to time per predictor (after warm-up).")
                     ] = 2000,
    data: DataOpt = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of tables.")] = False,
    model: Annotated[list[str] | None, typer.Option(
        "--model", help="Model file per predictor, e.g. lstm-authors=PATH.onnx.")] = None,
) -> None:
    """Per-call latency percentiles (us) in one process and thread, with the lstm's stages and
    batch throughput, beside the paper's figures (2 ms fit + 2 ms LSTM, 4-6 ms per step)."""
    from bench.latency import PAPER_MS, batch_throughput, lstm_stages, single_thread, time_predictor
    from predictors.registry import available

    single_thread()
    try:
        names = [p.strip() for p in predictors.split(",") if p.strip()]
        unknown = [n for n in names if n not in available()]
        if unknown:
            raise UsageError(f"unknown predictor(s) {', '.join(unknown)}")
        options = _model_options(model)
        drives = _load_drives(data, "enu", None)
        drive = max(drives, key=lambda d: len(d.gps))
        res: dict = {}
        with console.status("timing...") as status:
            for n in names:
                status.update(f"timing {n} on {drive.name}...")
                res[n] = time_predictor(n, drive, steps, options.get(n))
            if "lstm" in names:
                status.update("timing lstm stages...")
                res["lstm_stages"] = lstm_stages(drive, steps)
                status.update("timing batch throughput...")
                res["batch"] = batch_throughput()
        res["drive"] = drive.name
        res["paper_ms"] = PAPER_MS
    except (DataError, UsageError) as e:
        raise _fail(str(e)) from None
    if as_json:
        print(json.dumps(res, indent=2))
        return
    from rich.table import Table

    t = Table(title=f"per-call latency (us) on {drive.name} (one process, one thread)")
    for h in ("predictor", "step p50", "p90", "p99", "max", "query p50", "query p99", "paper"):
        t.add_column(h, justify="left" if h in ("predictor", "paper") else "right")
    paper = {"lstm": "4000-6000 (step)", "kf-paper": "1000 (Kalman)"}
    for n in names:
        s, q = res[n]["step_us"], res[n]["query_us"]
        t.add_row(n, f"{s['p50']:.1f}", f"{s['p90']:.1f}", f"{s['p99']:.1f}", f"{s['max']:.0f}",
                  f"{q['p50']:.1f}", f"{q['p99']:.1f}", paper.get(n, ""))
    console.print(t)
    if "lstm_stages" in res:
        st = Table(title="lstm fix step by stage (us)")
        for h in ("stage", "p50", "p90", "p99", "paper"):
            st.add_column(h, justify="left" if h in ("stage", "paper") else "right")
        pp = {"resample_positions": "~2000 (L-BFGS regression)", "inference": "~2000 (LSTM)",
              "cubic_fit_lbfgs": "~2000"}
        for k, v in res["lstm_stages"].items():
            st.add_row(k, f"{v['p50']:.1f}", f"{v['p90']:.1f}", f"{v['p99']:.1f}", pp.get(k, ""))
        console.print(st)
        bt = Table(title="batch throughput (onnxruntime, one thread)")
        for h in ("batch", "windows/s", "us/window"):
            bt.add_column(h, justify="right")
        for b, v in res["batch"].items():
            bt.add_row(b, f"{v['windows_per_s']:.0f}", f"{v['us_per_window']:.1f}")
        console.print(bt)


@app.command()
def tune(
    predictor: Annotated[str, typer.Argument(help="Predictor to tune (kf or ekf).")],
    gps_profile: Annotated[str, typer.Option(
        help="GPS condition to tune for: none, rtk, consumer (synthetic development drives, "
             "seeds 1000+) or native (give --data: the development routes).")] = "rtk",
    data: DataOpt = None,
    drives: Annotated[int, typer.Option(help="Synthetic development drives per route type.")] = 1,
    workers: Annotated[int, typer.Option(help="Parallel processes.")] = 2,
    save: Annotated[bool, typer.Option(help="Write the winner to predictors/tuned.json.")] = True,
) -> None:
    """Grid-search a filter's noise parameters on development drives (never evaluation drives)."""
    from bench.tune import GRIDS, grid_search, save_tuned

    if predictor not in GRIDS:
        raise _fail(f"no tuning grid for {predictor!r}; tunable: {', '.join(GRIDS)}")
    try:
        if gps_profile == "native":
            if not data:
                raise UsageError("--gps-profile native tunes on recorded fixes: give --data PATH...")
            dev = _load_drives(data, "enu", None)
            source = "development routes " + ", ".join(str(p) for p in data)
        else:
            from scenarios.synthetic import default_drives

            dev = [d for s in range(1000, 1000 + drives) for d in default_drives(seed=s)]
            source = f"synthetic development drives, seeds 1000-{999 + drives}"
        n = len(list(__import__("itertools").product(*list(GRIDS[predictor].values())[:2]))) + sum(
            len(v) for v in list(GRIDS[predictor].values())[2:])
        from rich.progress import Progress

        with Progress(console=console) as prog:
            task = prog.add_task(f"tuning {predictor} ({gps_profile})", total=n)
            best, trials = grid_search(predictor, dev, gps_profile, GRIDS[predictor], workers=workers,
                                       on_step=lambda p, v: prog.update(task, advance=1))
    except (DataError, UsageError) as e:
        raise _fail(str(e)) from None
    best_val = min(v for _, v in trials)
    console.print(f"best {best} -> future+now mean error {best_val:.4f} m over {len(dev)} drives")
    if save:
        command = _command_line()
        save_tuned(predictor, gps_profile, best,
                   f"`{command}`: {source}; objective mean future + mean now error "
                   f"{best_val:.4f} m; {len(trials)} trials")
        console.print("saved to predictors/tuned.json")


def _normalise_argv(argv: list[str]) -> list[str]:
    """Let multi-value options take several values after one flag (``--data a b``)."""
    out: list[str] = []
    current: str | None = None
    for a in argv:
        if a.startswith("-"):
            current = a if a in MULTI_VALUE_OPTIONS else None
            out.append(a)
            continue
        if current is not None and out and out[-1] != current:
            out.append(current)
        out.append(a)
    return out


def main() -> None:
    """Console-script entry point."""
    argv = _normalise_argv(sys.argv[1:])
    try:
        app(args=argv, prog_name="bench")
    except KeyboardInterrupt:
        err_console.print("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
