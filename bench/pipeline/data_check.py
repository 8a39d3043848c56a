"""The data consistency check before a run: every stream of every drive judged
(:mod:`posbench.scenarios.consistency`, pure: against the truth where a drive has one, else
against its fixes), the predictors that used a failing stream,
``--strict`` and the ``consistency`` key of results.json. How it reads, in the terminal and
in report.md, is :mod:`posbench.report.data_check`."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict
from typing import Any

from posbench.pipeline.reporter import INFO, SILENT, WARNING, Reporter
from posbench.scenarios.consistency import (
    TOLERANCES,
    Consistency,
    check_drive,
)
from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError
from posbench.scenarios.stored_drive import StoredDrive, as_drive

#: streams whose failure marks only the predictors that observe them (by overriding the
#: named method of :class:`posbench.predictors.base.Predictor`); every other stream marks all
STREAM_METHODS = {
    "imu.yaw_rate": "observe_imu",
    "imu.ax": "observe_imu",
    "imu.yaw": "observe_imu",
    "speed": "observe_speed",
}


def check_drives(drives: Iterable[Drive | StoredDrive]) -> dict[str, Consistency]:
    """:func:`posbench.scenarios.consistency.check_drive` of every drive, by drive name (a
    stored drive's verdicts as its loading process found them)."""
    out = {}
    for d in drives:
        found = d.check if isinstance(d, StoredDrive) else None
        out[d.name] = found if found is not None else check_drive(as_drive(d))
    return out


def uses_stream(cls: type, stream: str) -> bool:
    """Whether predictor class ``cls`` uses ``stream``: an IMU or speed stream only if it
    overrides ``observe_imu`` / ``observe_speed``; GPS and truth concern every predictor."""
    from posbench.predictors.base import Predictor

    method = STREAM_METHODS.get(stream)
    if method is None:
        return True
    return getattr(cls, method, None) is not getattr(Predictor, method)


def affected_predictors(
    names: Sequence[str], checks: dict[str, Consistency]
) -> dict[str, list[str]]:
    """Predictor name -> ``"drive: stream"`` for every failing stream it used."""
    from posbench.predictors.registry import predictor_class

    failing = [(d, c.stream) for d, res in checks.items() for c in res.failures()]
    out: dict[str, list[str]] = {}
    for name in names:
        cls = predictor_class(name)
        hit = [f"{d}: {s}" for d, s in failing if uses_stream(cls, s)]
        if hit:
            out[name] = hit
    return out


def strict_error(checks: dict[str, Consistency]) -> DataError | None:
    """The ``--strict`` error for the first failing stream (drive order), or None."""
    for drive, res in checks.items():
        for c in res.failures():
            return DataError(None, f"--strict: drive {drive}: {c.stream}: {c.reason}")
    return None


def to_results(checks: dict[str, Consistency], names: Sequence[str] = ()) -> dict[str, Any]:
    """The ``consistency`` key of results.json: tolerances, per drive and stream the
    verdict, reason and figures, and the predictors that used a failing stream."""
    return {
        "tolerances": asdict(TOLERANCES),
        "drives": {d: r.to_dict() for d, r in checks.items()},
        "affected_predictors": affected_predictors(names, checks) if names else {},
    }


def run_data_check(
    drives: Iterable[Drive | StoredDrive],
    names: Sequence[str],
    strict: bool = False,
    reporter: Reporter = SILENT,
) -> dict[str, Any]:
    """The data consistency check of every loaded drive, before any predictor runs: the
    ``consistency`` key of results.json; its failures and warnings told to ``reporter``.

    Raises:
        DataError: with ``strict``, the first failing stream (drive, stream and figure).
    """
    from posbench.report.data_check import summary_lines

    checks = check_drives(drives)
    err = strict_error(checks) if strict else None
    if err is not None:
        raise err
    section = to_results(checks, names)
    for line in summary_lines(section):
        reporter.line(line, WARNING if line.startswith("data check FAIL") else INFO)
    return section
