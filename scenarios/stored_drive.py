"""A drive kept on disk while a run needs it: loaded once, by a loading process, written
where the replay workers read it, and described to the main process by a few fields.

A fleet run must not hold its drives in the process that plans and combines: their samples
grow with drive hours (about 27 MB per drive hour of the synthetic corpus), and every
worker forked from that process would count them too. So a loading process writes each
drive as one pickle file (:func:`store_drive`) and returns a :class:`StoredDrive`: the
file and a :class:`DriveInfo` (name, metadata, span, sample counts, which streams it has,
its data-check verdicts), which is all the main process needs to check the options, report
the data check and plan the tasks. A worker loads the drive it replays
(:func:`as_drive`), one at a time.

The file is written and read by the same run of the same installation (a pickle: not an
exchange format); the run removes it when done.
"""

from __future__ import annotations

import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from posbench.scenarios.drive import Drive, DriveMeta

if TYPE_CHECKING:
    from posbench.scenarios.consistency import Consistency


@dataclass(frozen=True)
class DriveInfo:
    """What a run's main process knows of a drive without its samples.

    Attributes:
        meta: the drive's metadata (name, source, format, warnings, loader notes).
        duration_s: the span [s] of its streams (:attr:`Drive.duration_s`).
        fix_count: its GPS fixes.
        has_truth, has_imu, has_speed: which streams it holds.
        fixes_from_truth: :attr:`Drive.fixes_from_truth`.
        samples: its fixes, IMU and speed samples (the replay's work).
    """

    meta: DriveMeta
    duration_s: float
    fix_count: int
    has_truth: bool
    has_imu: bool
    has_speed: bool
    fixes_from_truth: bool
    samples: int

    @property
    def name(self) -> str:
        return self.meta.name

    @classmethod
    def of(cls, drive: Drive | StoredDrive) -> DriveInfo:
        """The description of ``drive`` (a stored drive's own)."""
        if isinstance(drive, StoredDrive):
            return drive.info
        streams = (drive.gps, drive.imu, drive.speed)
        return cls(
            meta=drive.meta,
            duration_s=drive.duration_s,
            fix_count=len(drive.gps),
            has_truth=drive.truth is not None,
            has_imu=drive.imu is not None,
            has_speed=drive.speed is not None,
            fixes_from_truth=drive.fixes_from_truth,
            samples=sum(len(s) for s in streams if s is not None),
        )


@dataclass(frozen=True)
class StoredDrive:
    """A drive written to ``path`` (:func:`store_drive`), with its description and, when
    the loading process checked it, its data-check verdicts (``check``)."""

    path: Path
    info: DriveInfo
    check: Consistency | None = None

    @property
    def name(self) -> str:
        return self.info.name

    def load(self) -> Drive:
        """The drive, read back from its file."""
        with open(self.path, "rb") as f:
            drive: Drive = pickle.load(f)
        return drive


def store_drive(drive: Drive, path: Path, check: bool = True) -> StoredDrive:
    """Write ``drive`` to ``path`` and describe it; ``check``: run the data consistency
    check on it here (:func:`~posbench.scenarios.consistency.check_drive`), so that the
    process reporting it never needs the samples."""
    from posbench.scenarios.consistency import check_drive

    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        pickle.dump(drive, f, protocol=pickle.HIGHEST_PROTOCOL)
    return StoredDrive(path, DriveInfo.of(drive), check_drive(drive) if check else None)


def as_drive(drive: Drive | StoredDrive) -> Drive:
    """The drive itself: ``drive``, or a stored drive read back."""
    return drive.load() if isinstance(drive, StoredDrive) else drive
