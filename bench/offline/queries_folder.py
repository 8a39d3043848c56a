"""The queries folder: posbench's queries written out for a system that runs elsewhere.

``bench queries`` prepares drives exactly as ``bench run`` does (same config and seed:
the same GPS draws, dropouts, query times and references) and writes, into one folder:

==========================  =====  ===============================================================
file                        who    content
==========================  =====  ===============================================================
``queries.csv``             give   ``drive, kind, t_issue, t_query``: every query to answer
``inputs/DRIVE.csv``        give   what a predictor may see of that drive, in the long table
                                   format of :mod:`posbench.scenarios.loaders.table` (streams
                                   gps = the fixes fed after degradation and dropouts, imu, speed)
``manifest.json``           -      format version, posbench version, command, config, seed,
                                   data hashes, drives, sha256 of every file
``key/reference.parquet``   keep   the answer key: per query its reference position, label,
                                   speed, time since fix, outage, warm-up flag
``key/drives.json``         keep   per drive what the report needs (data set, reference kind,
                                   what its truth is, notes, outages, fixes fed, skipped drives
                                   and why)
==========================  =====  ===============================================================

Clock and frame: every time in ``queries.csv`` and ``inputs/`` is in seconds from the drive's
first input sample (the first row of its inputs file is at t = 0, so the table reader reads
it back on this same clock); that is the drive time of ``traces.parquet`` minus the drive's
``t0_s`` (in the manifest, 0 for most drives). Positions are metres in the drive's local
ENU frame (columns x, y; no lat/lon, so the reader uses them as given). Times are written as
Python's ``repr`` of the float, exact through a CSV round trip. ``drive`` is the inputs
file's stem (the drive name, with characters unsafe in file names replaced by ``_``).

:func:`write_queries` writes a folder; :func:`read_queries` reads and checks one back
(:class:`QueryFolder`); :mod:`posbench.offline.answer_scoring` scores answers against it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.config import RunConfig
from posbench.naming import unique_file_safe
from posbench.replay.prepare import prepare_drive
from posbench.replay.queries import query_frame
from posbench.replay.reference import truth_source
from posbench.replay.runner import skip_reason, skipped_run
from posbench.scenarios.drive import Drive, GpsStream, ImuStream, SpeedStream
from posbench.scenarios.errors import DataError
from posbench.scoring.records import DriveRun
from posbench.scoring.schema import KINDS, QUERY_COLUMNS, TRACK_QUERY_COLUMNS

#: what ``manifest.json`` says it is, and the version of this layout: a reader accepts every
#: MINOR of its MAJOR (MINOR grows when files or keys are added, MAJOR when one changes)
FORMAT = "posbench-queries"
FORMAT_VERSION = "1.2"
MANIFEST = "manifest.json"
INPUTS = "inputs"
KEY_QUERIES = "key/reference.parquet"
KEY_DRIVES = "key/drives.json"
#: file formats of the queries list and the inputs
FORMATS = ("csv", "parquet")
#: the columns of the public queries list
PUBLIC_COLUMNS = ("drive", "kind", "t_issue", "t_query")
#: the DriveRun fields the key keeps per drive (what aggregation and the report read)
DRIVE_FIELDS = (
    "name",
    "dataset",
    "reference",
    "notes",
    "warnings",
    "outages",
    "skipped",
    "gps_count",
    "duration_s",
    "gps_condition",
    "truth_source",
)


def drive_ids(names: Sequence[str]) -> list[str]:
    """A file-safe, unique id per drive name (the name itself where it is safe): characters
    other than letters, digits, ``.``, ``_`` and ``-`` become ``_``; clashes (also by case)
    get ``-2``, ``-3``, ... (:func:`posbench.naming.unique_file_safe`)."""
    return unique_file_safe(names)


def input_start_s(drive: Drive, gps: GpsStream) -> float:
    """The drive time [s] of the first sample a predictor is fed (fixes ``gps``, IMU, speed)."""
    starts = [s.t[0] for s in (gps, drive.imu, drive.speed) if s is not None and len(s)]
    return float(min(starts)) if starts else 0.0


def inputs_drive(drive: Drive, gps: GpsStream, t0: float) -> Drive:
    """What a predictor may see of ``drive`` as a :class:`Drive`: the fixes fed (x, y only),
    IMU and speed, times shifted to start at the first input sample (``t0`` [s]); no truth."""
    imu = drive.imu
    if imu is not None:
        imu = ImuStream(imu.t - t0, imu.ax, imu.ay, imu.yaw, imu.yaw_rate)
    speed = drive.speed
    if speed is not None:
        speed = SpeedStream(speed.t - t0, speed.v)
    return replace(drive, gps=GpsStream(gps.t - t0, gps.x, gps.y), imu=imu, speed=speed, truth=None)


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            h.update(chunk)
    return h.hexdigest()


def _write_frame(df: pd.DataFrame, path: Path) -> None:
    if path.suffix == ".parquet":
        df.to_parquet(path, index=False)
    else:
        df.to_csv(path, index=False)  # floats as repr: exact through a round trip


def _drive_record(run: DriveRun) -> dict[str, Any]:
    rec = {f: getattr(run, f) for f in DRIVE_FIELDS}
    rec["outages"] = [[float(a), float(b)] for a, b in run.outages]
    return rec


@dataclass
class QueriesWritten:
    """What :func:`write_queries` wrote: the files (relative to the folder) and counts."""

    files: list[str]
    queries: int
    drives: int
    skipped: int


def write_queries(
    drives: Sequence[Drive],
    cfg: RunConfig,
    out: Path,
    *,
    command: str,
    data: list[dict[str, Any]],
    fmt: str = "csv",
    on_done: Callable[[str], None] | None = None,
) -> QueriesWritten:
    """Prepare ``drives`` as ``bench run`` does under ``cfg`` and write the queries folder
    ``out`` (layout in the module docstring); ``data`` is the data block of the manifest
    (:func:`posbench.saved_run.provenance.data_provenance`), ``fmt`` csv or parquet for the queries
    list and inputs. ``on_done(drive name)`` is called as each drive is written (progress bar).
    Files of an earlier queries folder there are replaced; others are left alone."""
    from posbench.saved_run.provenance import git_commit, package_versions
    from posbench.scenarios.loaders.table import drive_to_frame

    ext = "." + fmt
    out.mkdir(parents=True, exist_ok=True)
    _remove_previous(out)
    (out / INPUTS).mkdir(exist_ok=True)
    (out / "key").mkdir(exist_ok=True)
    ids = drive_ids([d.name for d in drives])
    public: list[pd.DataFrame] = []  # per drive: its rows of the queries list
    key: list[pd.DataFrame] = []  # per drive: its query table, the answer key
    records: list[dict[str, Any]] = []  # per drive: its record in the answer key
    listed: list[dict[str, Any]] = []  # per drive: its entry of the manifest
    for drive, did in zip(drives, ids, strict=True):
        reason = skip_reason(drive, cfg)
        if reason:
            records.append(_drive_record(skipped_run(drive, reason)))
            listed.append(
                {
                    "drive": did,
                    "name": drive.name,
                    "inputs": None,
                    "t0_s": 0.0,
                    "queries": 0,
                    "skipped": reason,
                }
            )
        else:
            prep = prepare_drive(drive, cfg)
            q = pd.concat([query_frame(prep, k) for k in KINDS], ignore_index=True)
            t0 = input_start_s(drive, prep.gps)
            rel = f"{INPUTS}/{did}{ext}"
            _write_frame(drive_to_frame(inputs_drive(drive, prep.gps, t0)), out / rel)
            public.append(
                pd.DataFrame(
                    {
                        "drive": did,
                        "kind": q["kind"].astype(str),
                        "t_issue": q["t_issue"].to_numpy() - t0,
                        "t_query": q["t_query"].to_numpy() - t0,
                    }
                )
            )
            key.append(q)
            run = DriveRun(
                drive.name,
                prep.dataset,
                prep.reference,
                prep.notes,
                list(drive.meta.warnings),
                pd.DataFrame(),
                outages=prep.outages,
                gps_count=len(prep.gps),
                duration_s=drive.duration_s,
                gps_condition=prep.gps_condition,
                truth_source=truth_source(drive),
            )
            records.append(_drive_record(run))
            listed.append(
                {
                    "drive": did,
                    "name": drive.name,
                    "inputs": rel,
                    "t0_s": t0,
                    "queries": len(q),
                    "skipped": None,
                }
            )
        if on_done:
            on_done(drive.name)
    queries_rel = "queries" + ext
    pub = (
        pd.concat(public, ignore_index=True)
        if public
        else pd.DataFrame({c: [] for c in PUBLIC_COLUMNS})
    )
    _write_frame(pub, out / queries_rel)
    keyf = pd.concat(key, ignore_index=True) if key else pd.DataFrame(columns=list(QUERY_COLUMNS))
    keyf.to_parquet(out / KEY_QUERIES, index=False)
    (out / KEY_DRIVES).write_text(json.dumps(records, indent=1, allow_nan=False) + "\n")
    files = [queries_rel, *[d["inputs"] for d in listed if d["inputs"]], KEY_QUERIES, KEY_DRIVES]
    manifest = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "posbench": package_versions()["posbench"],
        "versions": package_versions(),
        "git_commit": git_commit(),
        "command": command,
        "config": cfg.to_dict(),
        "data": data,
        "queries": queries_rel,
        "give": [queries_rel, INPUTS + "/"],
        "keep": ["key/"],
        "drives": listed,
        "files": {f: sha256_file(out / f) for f in files},
    }
    (out / MANIFEST).write_text(json.dumps(manifest, indent=1, allow_nan=False) + "\n")
    n_skipped = sum(d["skipped"] is not None for d in listed)
    return QueriesWritten([*files, MANIFEST], len(keyf), len(listed) - n_skipped, n_skipped)


def _remove_previous(out: Path) -> None:
    """Remove the files an earlier queries folder in ``out`` listed in its manifest."""
    try:
        old = json.loads((out / MANIFEST).read_text())
        listed = list(old.get("files", {})) if old.get("format") == FORMAT else []
    except (OSError, ValueError, AttributeError):
        return
    root = out.resolve()
    for rel in [*listed, MANIFEST]:
        p = (out / rel).resolve()
        if isinstance(rel, str) and p.is_relative_to(root) and p.is_file():
            p.unlink()


# ------------------------------------------------------------------------------- reading
@dataclass
class QueryFolder:
    """A queries folder read back and checked (:func:`read_queries`).

    Attributes:
        folder: where it is.
        manifest: the content of ``manifest.json``.
        key: the answer key, one row per query, :data:`~posbench.scoring.schema.QUERY_COLUMNS`,
            drive times [s] as in ``traces.parquet``; per drive its future then its now queries.
        drives: per drive (manifest order) the :class:`~posbench.scoring.records.DriveRun` fields of
            :data:`DRIVE_FIELDS`, plus ``id`` (the drive in the public files) and ``t0_s``.
    """

    folder: Path
    manifest: dict[str, Any]
    key: pd.DataFrame
    drives: list[dict[str, Any]]

    def config(self, predictor: str) -> RunConfig:
        """The ``bench queries`` config with ``predictor`` as the one predictor run."""
        return RunConfig(
            **{**self.manifest["config"], "predictors": (predictor,), "predictor_options": {}}
        )

    def public_times(self) -> pd.DataFrame:
        """The key's drive, kind and t_query as the public files give them (drive id, times
        from the drive's first input sample), row for row."""
        ids = {d["name"]: d["id"] for d in self.drives}
        t0 = {d["name"]: d["t0_s"] for d in self.drives}
        names = self.key["drive"].astype(str)
        return pd.DataFrame(
            {
                "drive": names.map(ids).to_numpy(),
                "kind": self.key["kind"].astype(str).to_numpy(),
                "t_query": self.key["t_query"].to_numpy(float) - names.map(t0).to_numpy(float),
            }
        )

    def drive_run(self, d: dict[str, Any], traces: pd.DataFrame) -> DriveRun:
        """The :class:`~posbench.scoring.records.DriveRun` of drive record ``d`` with ``traces``."""
        # folders before 1.1 have no gps_condition, before 1.2 no truth_source
        kw = {f: d[f] for f in DRIVE_FIELDS if f in d}
        kw["outages"] = [(float(a), float(b)) for a, b in d["outages"]]
        return DriveRun(traces=traces, **kw)


def _manifest(folder: Path) -> dict[str, Any]:
    path = folder / MANIFEST
    if not folder.is_dir():
        raise DataError(folder, "no such folder: give a folder written by `bench queries`")
    if not path.is_file():
        raise DataError(folder, f"no {MANIFEST}: not a folder written by `bench queries`")
    try:
        man = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise DataError(path, f"not readable as JSON: {e}") from None
    if not isinstance(man, dict) or man.get("format") != FORMAT:
        raise DataError(path, f'not a `bench queries` manifest (no "format": "{FORMAT}")')
    version = str(man.get("format_version", "?"))
    if version.split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise DataError(
            path,
            f"format_version {version}, written by posbench "
            f"{man.get('posbench', '?')}; this posbench reads "
            f"{FORMAT_VERSION.split('.')[0]}.x: write the queries again with "
            f"this posbench (bench queries) or score with a matching one",
        )
    missing = [k for k in ("config", "drives", "files", "data", "command") if k not in man]
    if missing:
        raise DataError(path, f"incomplete manifest: no {', '.join(missing)}")
    known = set(RunConfig.__dataclass_fields__)
    if not isinstance(man["config"], dict) or set(man["config"]) - known:
        extra = sorted(set(man["config"]) - known) if isinstance(man["config"], dict) else []
        raise DataError(
            path,
            f"config keys this posbench does not know: {', '.join(extra)} "
            f"(written by posbench {man.get('posbench', '?')})"
            if extra
            else "config is not an object",
        )
    if not isinstance(man["drives"], list) or not all(
        isinstance(d, dict) and {"drive", "name", "t0_s"} <= set(d) for d in man["drives"]
    ):
        raise DataError(path, "malformed drives list (each needs drive, name, t0_s)")
    return man


def read_queries(folder: str | Path) -> QueryFolder:
    """Read and check a folder written by :func:`write_queries`.

    Raises:
        DataError: not such a folder, another format version, a key file missing or changed
            since it was written (sha256 in the manifest), or inconsistent with the manifest.
    """
    folder = Path(folder)
    man = _manifest(folder)
    for rel in (KEY_QUERIES, KEY_DRIVES):
        path = folder / rel
        if not path.is_file():
            raise DataError(
                path,
                "missing: the answer key of this queries folder is gone "
                "(write the folder again with bench queries)",
            )
        want = man["files"].get(rel)
        if want != sha256_file(path):
            raise DataError(
                path,
                "changed since `bench queries` wrote it (sha256 differs from "
                "the manifest): write the folder again",
            )
    try:
        records = json.loads((folder / KEY_DRIVES).read_text())
        key = pd.read_parquet(folder / KEY_QUERIES)
    except Exception as e:  # noqa: BLE001 - pyarrow raises several types for damaged files
        raise DataError(
            folder / "key", f"cannot read the answer key: {str(e).splitlines()[0]}"
        ) from None
    listed = man["drives"]
    if (
        not isinstance(records, list)
        or len(records) != len(listed)
        or any(
            not isinstance(r, dict) or set(DRIVE_FIELDS) - set(r) or r["name"] != d["name"]
            for r, d in zip(records, listed, strict=False)
        )
    ):
        raise DataError(folder / KEY_DRIVES, "does not list the drives of the manifest")
    drives = [
        {**r, "id": d["drive"], "t0_s": float(d["t0_s"])}
        for r, d in zip(records, listed, strict=True)
    ]
    for c in TRACK_QUERY_COLUMNS:  # a key written before the along/cross-track columns
        if c not in key.columns:
            key[c] = float("nan")
    if list(key.columns) != list(QUERY_COLUMNS):
        raise DataError(
            folder / KEY_QUERIES, f"columns {list(key.columns)}, expected {list(QUERY_COLUMNS)}"
        )
    return QueryFolder(folder, man, key, drives)
