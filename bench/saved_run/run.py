"""A run as data: one versioned, documented object, written and read by one pair.

``save_run(out, run)`` writes ``results.json`` (validated against the JSON Schema shipped
as ``posbench/saved_run/schemas/results.schema.json``, version :data:`SCHEMA_VERSION`) and
``traces.parquet`` (columns: :data:`posbench.scoring.schema.TRACE_COLUMNS`); ``load_run(path)``
reads them back as a :class:`Run`, its traces loaded only when first used. The report,
the figures, the terminal tables and every later command read a :class:`Run`.

A run that did not end well says so (schema 1.7): ``status`` is ``complete``, ``failed``
(the command exited non-zero: nothing could be scored, every drive was skipped, the rerun
recording could not be written) or ``interrupted`` (Ctrl-C while its files were written),
and ``reason`` is the one error line. :func:`load_run` refuses a run that is not complete
unless asked (``allow_failed=True``); a results.json written before 1.7 has no status and
reads as complete. results.json is written last and atomically (a temporary file renamed
over it), so a folder whose writing was cut short never reads as a complete run.

Each data set names its reference (schema 1.8, ``references``): its truth, or the
receiver's own fixes (no independent truth); a run saved before says it through its drives'
``reference`` (:func:`posbench.scoring.reference.references` reads both).

Each run carries the bound beside its predictors (schema 1.9, ``limit``): the posterior
Cramér-Rao bound on the mean error over the same queries, each predictor's ``x limit`` and
the predictors below it; a run saved before has none, and shows no limit row.

A run with the ``outage-lengths`` dropout profile carries its outage curve (schema 1.10,
``outage_lengths``): FDE and ATE at the end of 1-60 s outages, in metres and as % of the
distance travelled since the last fix; a run saved before has none, and shows no such section.

Example (a notebook)::

    import posbench
    run = posbench.load("bench-out")       # this module's load_run
    run.summary()                          # (predictor, kind) x mean_m, median_m, ... [m]
    tr = run.traces                        # one row per query
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from posbench.scenarios.errors import DataError
from posbench.scoring.schema import COV_COLUMNS
from posbench.scoring.trace_set import TraceSet

#: MAJOR.MINOR of results.json: a reader accepts every MINOR of its MAJOR; MINOR grows when
#: keys are added, MAJOR when a key changes meaning or goes
SCHEMA_VERSION = "1.10"
RESULTS = "results.json"
TRACES = "traces.parquet"
PROVENANCE_KEYS = ("command", "versions", "git_commit", "data")
#: ``status`` of results.json (schema 1.7; older files, which have none, read as complete)
COMPLETE, FAILED, INTERRUPTED = "complete", "failed", "interrupted"


def results_schema() -> dict[str, Any]:
    """The JSON Schema of ``results.json`` (shipped with the package)."""
    schema: dict[str, Any] = json.loads(
        (resources.files("posbench.saved_run") / "schemas" / "results.schema.json").read_text()
    )
    return schema


def to_json_value(o: Any) -> Any:
    """``o`` with NaN/inf as None and NumPy scalars/arrays as Python values (strict JSON)."""
    if isinstance(o, dict):
        return {str(k): to_json_value(v) for k, v in o.items()}
    if isinstance(o, list | tuple):
        return [to_json_value(v) for v in o]
    if isinstance(o, np.ndarray):
        return to_json_value(o.tolist())
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, float | np.floating):
        return float(o) if math.isfinite(o) else None
    if o is None or isinstance(o, str | int | bool):
        return o
    return str(o)


@dataclass
class Run:
    """One bench run: ``results`` (the content of results.json) and its per-query traces.

    Attributes:
        results: aggregated figures, config and provenance (see the JSON Schema).
        folder: where the run was saved or loaded from (None while only in memory).
    """

    results: dict[str, Any]
    folder: Path | None = None
    _traces: pd.DataFrame | None = field(default=None, repr=False)
    #: the traces' Parquet parts, while they are on disk and not in :attr:`folder`
    _trace_parts: tuple[Path, ...] = field(default=(), repr=False)

    @classmethod
    def from_results(
        cls,
        results: dict[str, Any],
        traces: pd.DataFrame | TraceSet | None = None,
        folder: Path | None = None,
    ) -> Run:
        """A run from freshly aggregated ``results``: stamped with :data:`SCHEMA_VERSION`
        and ``status`` (complete unless ``results`` says otherwise) and converted to strict
        JSON values (NaN -> None), exactly as a load would give it."""
        stamp = ("schema_version", "status", "reason")
        res = to_json_value(
            {
                "schema_version": SCHEMA_VERSION,
                "status": results.get("status", COMPLETE),
                "reason": results.get("reason"),
                **{k: v for k, v in results.items() if k not in stamp},
            }
        )
        if isinstance(traces, TraceSet):
            if traces.in_memory is None:
                return cls(res, folder, None, traces.parts)
            traces = traces.in_memory
        return cls(res, folder, traces)

    @property
    def status(self) -> str:
        """:data:`COMPLETE`, :data:`FAILED` or :data:`INTERRUPTED` (schema 1.7; a run saved
        before has none and is complete)."""
        return str(self.results.get("status", COMPLETE))

    @property
    def reason(self) -> str | None:
        """Why a run that is not complete ended: the one error line it exited with."""
        reason = self.results.get("reason")
        return None if reason is None else str(reason)

    @property
    def config(self) -> dict[str, Any]:
        """The run's configuration (``RunConfig`` as a dict: horizon_s, gps_profile, ...)."""
        config: dict[str, Any] = self.results["config"]
        return config

    @property
    def provenance(self) -> dict[str, Any]:
        """Command line, package versions, git commit and data hashes."""
        return {k: self.results.get(k) for k in PROVENANCE_KEYS}

    @property
    def predictors(self) -> list[str]:
        """Predictor names in run order."""
        return list(self.results["predictors"])

    @property
    def trace_set(self) -> TraceSet:
        """The traces where they are, read one predictor or one drive at a time
        (:class:`~posbench.scoring.trace_set.TraceSet`): what the figures, the report and the
        recording read, so that a large run is never held whole."""
        if self._traces is not None:
            return TraceSet(self._traces)
        if self._trace_parts:
            return TraceSet(parts=self._trace_parts)
        path = None if self.folder is None else self.folder / TRACES
        if path is not None and path.is_file():
            import pyarrow.parquet as pq

            if all(c in pq.read_schema(path).names for c in COV_COLUMNS):
                return TraceSet(parts=[path])
        return TraceSet(self.traces)

    @property
    def traces(self) -> pd.DataFrame:
        """Per-query traces (loaded from the folder on first use; columns:
        :data:`posbench.scoring.schema.TRACE_COLUMNS`). Empty when nothing was scored."""
        if self._traces is None and self._trace_parts:
            self._traces = TraceSet(parts=self._trace_parts).materialize()
        if self._traces is None:
            path = None if self.folder is None else self.folder / TRACES
            if path is None or not path.is_file():
                if any(d.get("skipped") is None for d in self.results.get("drives", [])):
                    raise DataError(path, "no traces: the run was saved without traces.parquet")
                self._traces = pd.DataFrame()
            else:
                self._traces = pd.read_parquet(path)
                for c in COV_COLUMNS:  # traces written before schema 1.4
                    if c not in self._traces:
                        self._traces[c] = np.nan
        return self._traces

    def summary(self, kind: str | None = None) -> pd.DataFrame:
        """The headline figures as a numeric frame: one row per predictor and kind (index
        ``(predictor, kind)``), columns count, missing, mean_m, median_m, rmse_m, p95_m,
        max_m [m] and, for runs with intervals (schema 1.1), their 95 % bounds mean_m_lo,
        mean_m_hi, median_m_lo, ... [m]. ``kind`` (``future`` or ``now``): only its rows,
        indexed by predictor."""
        from posbench.metrics.accuracy import SUMMARY_KEYS
        from posbench.scoring.schema import KINDS

        rows = {}
        for p, v in self.results["predictors"].items():
            for k in KINDS if kind is None else (kind,):
                s = v[k]
                row = {f: s.get(f) for f in SUMMARY_KEYS}
                for fig, (lo, hi) in (
                    (f, b) for f, b in s.get("ci95", {}).items() if isinstance(b, list)
                ):
                    row[f"{fig}_lo"], row[f"{fig}_hi"] = lo, hi
                rows[(p, k) if kind is None else p] = row
        frame = pd.DataFrame.from_dict(rows, orient="index").astype(float)
        if kind is None and not frame.empty:
            frame.index = pd.MultiIndex.from_tuples(frame.index, names=["predictor", "kind"])
        return frame

    def track_summary(self, kind: str = "future") -> pd.DataFrame:
        """Along/cross-track figures of one kind as a numeric frame: one row per predictor,
        columns of :data:`posbench.metrics.track_errors.TRACK_SUMMARY_KEYS` [m] (schema 1.3); empty
        for older runs, which have none."""
        from posbench.metrics.track_errors import TRACK_SUMMARY_KEYS

        block = self.results.get("track_errors", {}).get("predictors", {})
        rows = {p: {k: v[kind].get(k) for k in TRACK_SUMMARY_KEYS} for p, v in block.items()}
        return pd.DataFrame.from_dict(
            rows, orient="index", columns=list(TRACK_SUMMARY_KEYS)
        ).astype(float)

    def report(
        self,
        out: str | Path,
        plot_formats: Sequence[str] = ("png",),
        drive_plots: int | None = 20,
        table_formats: Sequence[str] = ("csv", "latex"),
    ) -> list[Path]:
        """Write this run's report into folder ``out``: its figures (in ``plot_formats``;
        per-drive ones for at most ``drive_plots`` drives, None: all), ``report.md`` and its
        tables as files (``table_formats``: csv, latex); the paths written. Needs the traces
        for the figures (:attr:`traces`)."""
        from posbench.report.markdown import write_report

        return write_report(
            self,
            Path(out),
            formats=tuple(plot_formats),
            drive_plots=drive_plots,
            table_formats=tuple(table_formats),
        )

    def save(self, out: str | Path) -> list[Path]:
        """Write ``results.json`` and ``traces.parquet`` into folder ``out``
        (:func:`save_run`); the paths written. The run then lives there (:attr:`folder`)."""
        if self._traces is None and self.folder is not None:
            self.traces  # noqa: B018 - loaded from the old folder before it moves
        return save_run(Path(out), self)

    def __repr__(self) -> str:
        """A few lines: where, how many drives, which predictors, their future mean error."""
        res = self.results
        drives = [d for d in res.get("drives", []) if not d.get("skipped")]
        sets = sorted({str(d.get("dataset")) for d in drives})
        cfg = res.get("config", {})
        where = str(self.folder) if self.folder is not None else "in memory"
        head = (
            f"Run({where}: {len(drives)} drive{'' if len(drives) == 1 else 's'} "
            f"({', '.join(sets) or 'none'}), {len(self.predictors)} predictors, horizon "
            f"{cfg.get('horizon_s')} s, GPS {cfg.get('gps_profile')})"
        )
        means = ", ".join(
            f"{p} {v['future'].get('mean_m'):.3f}"
            if v["future"].get("mean_m") is not None
            else f"{p} -"
            for p, v in res.get("predictors", {}).items()
        )
        status = "" if self.status == COMPLETE else f"\n  {self.status}: {self.reason}"
        return f"{head}\n  future mean error [m]: {means}{status}"


def write_traces(out: Path, traces: pd.DataFrame | TraceSet | None) -> Path | None:
    """``out/traces.parquet`` from ``traces`` (nothing without rows; parts on disk are
    copied one at a time, :meth:`~posbench.scoring.trace_set.TraceSet.write`); the path, or
    None."""
    if traces is None or traces.empty:
        return None
    out.mkdir(parents=True, exist_ok=True)
    if isinstance(traces, TraceSet):
        return traces.write(out / TRACES)
    traces.to_parquet(out / TRACES, index=False)
    return out / TRACES


def save_run(
    out: Path,
    run: Run,
    also_written: Sequence[Path] = (),
    traces_written: Callable[[], Path | None] | None = None,
) -> list[Path]:
    """Write ``run`` into folder ``out``: ``traces.parquet`` (when there are traces) and
    ``results.json`` last, listing under ``outputs`` every file the run wrote there
    (``also_written``: report, figures) so the next run into ``out`` replaces exactly those.
    ``traces_written``: returns the traces file :func:`write_traces` already wrote (or is
    writing, in another process) for ``run``; None: written here. Returns the two paths
    written."""
    from posbench.saved_run.outputs import relative_outputs

    out.mkdir(parents=True, exist_ok=True)
    source = TraceSet(parts=run._trace_parts) if run._trace_parts else run._traces
    traces = traces_written() if traces_written is not None else write_traces(out, source)
    written = [traces] if traces is not None else []
    run._trace_parts = ()  # from now on, read from the folder
    written.append(out / RESULTS)
    run.results["outputs"] = relative_outputs(out, [*also_written, *written])
    write_results(out, run.results)
    run.folder = out
    return written


def write_results(out: Path, results: dict[str, Any]) -> Path:
    """``out/results.json`` from ``results`` (strict JSON), atomically: written to a
    temporary file beside it, then renamed over it, so an interrupted write leaves the
    previous file or none, never half of one. The path."""
    path = out / RESULTS
    text = json.dumps(to_json_value(results), indent=2, allow_nan=False) + "\n"
    tmp = out / f".{RESULTS}.{os.getpid()}.tmp"
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def mark_unfinished(run: Run, status: str, reason: str, out: Path | None = None) -> None:
    """Record that ``run`` did not complete (:data:`FAILED` or :data:`INTERRUPTED`, with
    ``reason``, the one error line) in it and in its results.json: in the folder it is
    saved in, or, not saved yet, in ``out`` (None: in memory only)."""
    run.results["status"], run.results["reason"] = status, reason
    folder = run.folder if run.folder is not None else out
    if folder is not None and folder.is_dir():
        run.results.setdefault("outputs", [RESULTS])
        write_results(folder, run.results)
        run.folder = folder


@contextmanager
def marked_if_unfinished(
    run: Run, doing: str = "writing the run's files", out: Path | None = None
) -> Iterator[None]:
    """Inside, an exception marks ``run`` as not complete, and its results.json (in its
    folder, or in ``out`` if it is not saved yet: :func:`mark_unfinished`), before it goes
    on: a KeyboardInterrupt as :data:`INTERRUPTED` (``doing``: what was interrupted), any
    other as :data:`FAILED`, its one line the reason. Marking is best effort: if it fails
    too, the first error is the one raised."""
    try:
        yield
    except BaseException as e:
        if isinstance(e, KeyboardInterrupt):
            status, reason = INTERRUPTED, f"interrupted (Ctrl-C) while {doing}"
        else:
            status, reason = FAILED, " ".join(str(e).split()) or type(e).__name__
        try:
            mark_unfinished(run, status, reason, out)
        except Exception:  # noqa: BLE001 - the error being raised says more
            pass
        raise


def check_complete(run: Run, path: str | Path | None = None) -> None:
    """Raise unless ``run`` is complete (schema 1.7 ``status``; older runs are).

    Raises:
        DataError: a failed or interrupted run, in one line with its reason and how to read
            it anyway; ``path`` (default: the run's results.json) is named.
    """
    if run.status == COMPLETE:
        return
    what = {FAILED: "a failed run", INTERRUPTED: "an interrupted run"}.get(
        run.status, f"a run of status {run.status!r}"
    )
    where = path if path is not None else run.folder / RESULTS if run.folder else None
    raise DataError(
        where,
        f"{what} ({run.reason or 'no reason recorded'}); --allow-failed (bench compare) or "
        "allow_failed=True (posbench.load, posbench.compare) reads it anyway",
    )


def load_run(path: str | Path, allow_failed: bool = False) -> Run:
    """A saved run from its folder (or its ``results.json``); traces load lazily.
    ``allow_failed``: also a run that did not complete (``status`` failed or interrupted:
    its command exited non-zero; see :attr:`Run.status` and :attr:`Run.reason`).

    Raises:
        DataError: no results.json there, not JSON, written by an incompatible posbench
            (another schema MAJOR version), or, without ``allow_failed``, a run that failed
            or was interrupted (:func:`check_complete`).
    """
    p = Path(path)
    res_path = p / RESULTS if p.is_dir() else p
    if not res_path.is_file():
        raise DataError(
            res_path, "no such file: give a bench run output folder or its results.json"
        )
    try:
        results = json.loads(res_path.read_text())
    except (OSError, ValueError) as e:
        raise DataError(res_path, f"not readable as JSON: {e}") from None
    if not isinstance(results, dict) or "predictors" not in results:
        raise DataError(res_path, "not a posbench results.json (no 'predictors')")
    version = str(results.get("schema_version", "0"))
    if version.split(".")[0] != SCHEMA_VERSION.split(".")[0]:
        raise DataError(
            res_path,
            f"schema_version {version} (this posbench reads "
            f"{SCHEMA_VERSION.split('.')[0]}.x): re-run it or use a matching "
            f"posbench",
        )
    run = Run(results, res_path.parent)
    if not allow_failed:
        check_complete(run, res_path)
    return run
