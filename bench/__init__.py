"""posbench: benchmark real-time vehicle position predictors on your drives.

The same functions the ``bench`` command line calls, for notebooks and scripts::

    import posbench

    run = posbench.run(predictors=("cv", "kf"))          # bench run: a Run, in memory
    run.summary()                                       # (predictor, kind) x figures [m]
    saved = posbench.run(data="drives/", predictors="kf,lstm", out="bench-out")
    old = posbench.load("bench-out")                    # a saved run; traces load lazily
    cmp = posbench.compare(old, saved)                  # bench compare: a Comparison
    posbench.check("cv")                                # bench check: a ContractReport
    posbench.score("answers.csv", "bench-queries")      # bench score: a Run

Units everywhere: seconds, metres (local ENU), microseconds for latency. Every user
mistake raises :class:`~posbench.errors.UsageError` or
:class:`~posbench.scenarios.errors.DataError` with the one line ``bench`` would print.
Importing this package imports nothing heavy: each function imports what it needs.

The packages: :mod:`posbench.scenarios` (drives, loaders, synthetic data),
:mod:`posbench.predictors` (the Predictor interface and every predictor),
:mod:`posbench.metrics` (statistics, pure functions on arrays), and the harness:
:mod:`posbench.scoring`, :mod:`posbench.replay`, :mod:`posbench.offline`,
:mod:`posbench.aggregation`, :mod:`posbench.saved_run`, :mod:`posbench.tables`,
:mod:`posbench.figures`, :mod:`posbench.recording`, :mod:`posbench.comparison`,
:mod:`posbench.report`, :mod:`posbench.predictor_tools`, :mod:`posbench.pipeline` and
:mod:`posbench.cli`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from posbench.naming import DISTRIBUTION

if TYPE_CHECKING:
    from posbench.comparison.comparison import Comparison
    from posbench.predictor_tools.contract import ContractReport
    from posbench.saved_run.run import Run

__all__ = ["DISTRIBUTION", "check", "compare", "load", "run", "score"]


def _tuple(value: Any) -> tuple[Any, ...]:
    """``value`` as a tuple: None -> (), one str or path -> (it,), a sequence -> its items."""
    if value is None:
        return ()
    if isinstance(value, (str, Path)):
        return (value,)
    return tuple(value)


def _formats(value: str | Sequence[str]) -> tuple[str, ...]:
    """``"png,pdf"`` or ``("png", "pdf")`` as a tuple of names."""
    items = value.split(",") if isinstance(value, str) else list(value)
    return tuple(s.strip().lower() for s in items if str(s).strip())


def _call(name: str, args: Mapping[str, Any]) -> str:
    """How a call is recorded in results.json (where ``bench`` records its command line)."""
    shown = ", ".join(f"{k}={v!r}" for k, v in args.items() if v not in (None, (), {}))
    return f"posbench.{name}({shown})"


def run(
    data: str | Path | Sequence[str | Path] | None = None,
    predictors: str | Sequence[str] | None = None,
    out: str | Path | None = None,
    *,
    progress: bool = False,
    **options: Any,
) -> Run:
    """Replay drives through predictors, as ``bench run`` does; the run, saved in ``out`` if
    given (report.md, results.json, traces, figures), else kept in memory.

    Args:
        data: recordings or folders of them (ROS 1/2 bags, KITTI raw, comma2k19 segments,
            the paper's route pickles, CSV/Parquet) or fsspec URLs; None: the built-in
            synthetic drives.
        predictors: names (``"kf,lstm"`` or ``("kf", "lstm")``), ``NAME@ALIAS`` or
            ``module:Class``; None: ``bench run``'s default set.
        out: the output folder; None: nothing is written.
        progress: show progress bars and the data check's lines (as the command does).
        **options: any other option of :class:`posbench.pipeline.plan.RunOptions`, e.g.
            ``horizon_s=0.2``, ``gps_profile="consumer"``, ``dropouts="outages"``,
            ``seeds=5``, ``models={"lstm@mine": "model-dir"}``,
            ``options={"kf": {"jerk_psd": 4.0}}``, ``workers=2``.

    Returns:
        the :class:`~posbench.saved_run.run.Run`: ``summary()``, ``traces``, ``results``.

    Raises:
        UsageError: an option that cannot work (before any drive is loaded).
        DataError: a recording that cannot be read, or a run that scored no query of any
            drive (report.md is written to ``out`` first; the message says why).
    """
    from dataclasses import fields

    from posbench.config import DEFAULT_PREDICTORS
    from posbench.pipeline.plan import RunOptions, plan_run
    from posbench.pipeline.run import execute_run
    from posbench.scenarios.text import quoted

    known = {f.name for f in fields(RunOptions)}
    unknown = sorted(set(options) - known)
    if unknown:
        raise TypeError(
            f"run() got unknown option(s) {', '.join(unknown)}; options: "
            f"{', '.join(sorted(known - {'data', 'predictors', 'out'}))}"
        )
    if "table_formats" in options:
        options["table_formats"] = _formats(options["table_formats"])
    for key in ("rerun",):
        if options.get(key) is not None:
            options[key] = Path(options[key])
    if isinstance(options.get("seeds"), (int, str)):
        from posbench.checks import parse_seeds

        options["seeds"] = tuple(parse_seeds(options["seeds"]))
    if options.get("drive_plots") == "all":
        options["drive_plots"] = None
    opts = RunOptions(
        data=_tuple(data),
        predictors=_tuple(predictors) or DEFAULT_PREDICTORS,
        out=None if out is None else Path(out),
        **options,
    )
    given = {
        (n, k): f"options={{{n!r}: {{{k!r}: {quoted(v)}}}}}"
        for n, o in opts.options.items()
        for k, v in o.items()
    }
    plan = plan_run(opts, given)
    command = _call("run", {"data": data, "predictors": predictors, "out": out, **options})
    return execute_run(plan, command, _reporter(progress)).run


def score(
    answers: str | Path,
    queries: str | Path,
    name: str = "answers",
    out: str | Path | None = None,
    *,
    plot_formats: str | Sequence[str] = ("png",),
    drive_plots: int | None = 20,
    table_formats: str | Sequence[str] = ("csv", "latex"),
    progress: bool = False,
) -> Run:
    """Score answers produced elsewhere (a CSV or Parquet file: drive, kind, t_query [s],
    x, y [m]) against the queries folder ``bench queries`` wrote, exactly as ``bench run``
    scores a predictor, as predictor ``name``; the run, saved in ``out`` if given.

    Raises:
        UsageError: a bad name, a missing file or folder.
        DataError: answers that do not match the queries (the file and row named).
    """
    from posbench.checks import parse_plot_formats
    from posbench.pipeline.score import check_score_options, score_answers_file

    answers, queries = Path(answers), Path(queries)
    out_path = None if out is None else Path(out)
    check_score_options(answers, queries, name, out_path)
    command = _call(
        "score", {"answers": str(answers), "queries": str(queries), "name": name, "out": out}
    )
    return score_answers_file(
        answers,
        queries,
        name,
        out_path,
        command,
        plot_formats=parse_plot_formats(plot_formats),
        drive_plots=drive_plots,
        table_formats=_formats(table_formats),
        reporter=_reporter(progress),
    ).run


def load(path: str | Path, *, allow_failed: bool = False) -> Run:
    """A run saved by ``bench run``, ``bench score`` or :meth:`Run.save`, from its folder or
    its results.json; the traces load on first use. ``allow_failed``: also a run whose
    command failed or was interrupted (results.json ``status`` failed or interrupted, with
    its ``reason``: ``run.status``, ``run.reason``); its figures are not a whole run's.

    Raises:
        DataError: no results.json there, not one of posbench's, from an incompatible
            posbench, or (without ``allow_failed``) a run that failed or was interrupted.
    """
    from posbench.saved_run.run import load_run

    return load_run(path, allow_failed=allow_failed)


def compare(
    *runs: Run | str | Path,
    metric: str = "future.mean_m",
    scopes: Sequence[str] = ("all", "dataset"),
    bootstrap_seed: int = 0,
    gates: Sequence[str] = (),
    uncertainty: bool = False,
    allow_config_change: bool = False,
    allow_failed: bool = False,
) -> Comparison:
    """Compare saved runs (:class:`Run` objects or their folders) as ``bench compare``
    does: ``metric`` (``KIND.STAT``, e.g. ``now.p95_m``) aligned per predictor, data set,
    route type and drive (``scopes``), each later run's paired difference from the first
    with its 95 % cluster-bootstrap CI, the uncertainty figures if asked, and the
    ``gates`` (``"lstm:future.mean_m:5%"``: two runs, OLD then NEW) checked. A run that
    failed or was interrupted (results.json ``status``) is refused unless ``allow_failed``
    (then named in ``notes``).

    Returns:
        a :class:`~posbench.comparison.comparison.Comparison` (``frame``, ``table``,
        ``differences``, ``gates``, ``passed``, ``figure()``).
    """
    from posbench.comparison.comparison import compare_runs

    return compare_runs(
        runs, metric, scopes, bootstrap_seed, gates, uncertainty, allow_config_change, allow_failed
    )


def check(
    predictor: str,
    *,
    model: str | Path | None = None,
    options: Mapping[str, Any] | None = None,
    gate: bool = True,
    clauses: Sequence[str] | None = None,
) -> ContractReport:
    """Check a predictor against the streaming contract as ``bench check`` does: a
    registered name, ``NAME@ALIAS`` or ``module:Class``, built with ``options`` (and its
    ``model`` file), behind the GPS outlier gate unless ``gate=False``; every clause, or
    those named in ``clauses``.

    Returns:
        a :class:`~posbench.predictor_tools.contract.ContractReport` (``passed``,
        ``clauses``, ``failed``).
    """
    from posbench.predictor_tools.contract import check_contract
    from posbench.replay.predictor_options import model_options
    from posbench.replay.predictor_setup import validate_predictors

    opts = {predictor: dict(options or {})}
    if model is not None:
        opts[predictor].update(model_options({predictor: model})[predictor])
    resolved = validate_predictors([predictor], opts)
    return check_contract(predictor, resolved.get(predictor), gate=gate, clauses=clauses)


def _reporter(progress: bool) -> Any:
    """The reporter of a library call: silent, or progress bars and lines with ``progress``."""
    from posbench.pipeline.reporter import SILENT, RichReporter

    return RichReporter() if progress else SILENT
