"""What a run could not honour of its options, said before any replay: a run records what it
did, never what it was asked.

``--gps-profile none|rtk|consumer`` draws each drive's fixes from its truth; a drive without a
truth can only be fed and scored on its own receiver's fixes (``native``). ``--gps-latency``
delays drawn fixes only. ``--gps-profile native`` on a drive with no fixes of its own draws
``rtk`` fixes from its truth. When an option applies to none of the drives the run stops with
one line (:class:`~posbench.errors.UsageError`); when it applies to some, each drive it
misses is named in one note, and results.json's ``gps_conditions`` counts the drives by the
condition actually fed and scored (:func:`posbench.pipeline.results.scored_conditions`).
"""

from __future__ import annotations

from collections.abc import Sequence

from posbench.config import AUTO_PROFILE, RunConfig, gps_condition
from posbench.errors import UsageError
from posbench.naming import plural
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import DriveInfo, StoredDrive

#: at most this many drive names in a note
NAMED = 3


def _names(drives: Sequence[DriveInfo]) -> str:
    shown = ", ".join(d.name for d in drives[:NAMED])
    return shown + (f" and {len(drives) - NAMED} more" if len(drives) > NAMED else "")


def _what(drive: DriveInfo) -> str:
    """What a drive holds, for a message: ``fixes and IMU``, ``fixes, IMU and speed``."""
    parts = ["fixes" if drive.fix_count else "no fixes"]
    parts += [s for s, v in (("IMU", drive.has_imu), ("speed", drive.has_speed)) if v]
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def unhonoured(loaded: Sequence[Drive | StoredDrive], cfg: RunConfig) -> list[str]:
    """One note per option of ``cfg`` that some of the ``loaded`` drives cannot honour
    (module docstring); [] when every drive takes every option as asked.

    Raises:
        UsageError: an option that applies to none of the drives, naming it and what would
            have been scored instead.
    """
    drives = [DriveInfo.of(d) for d in loaded]
    notes: list[str] = []
    profile = cfg.gps_profile
    flag = f"--gps-profile {profile}"
    conditions = [gps_condition(cfg, d) for d in drives]  # what each drive is fed
    missed = [d for d, c in zip(drives, conditions, strict=True) if c != profile]
    if profile != AUTO_PROFILE and missed:
        no_truth = [d for d in missed if not d.has_truth]
        if no_truth and len(no_truth) == len(drives):
            d = no_truth[0]
            which = f"{d.name} holds {_what(d)}" if len(drives) == 1 else _names(no_truth)
            raise UsageError(
                f"{flag} draws fixes from each drive's truth, and no drive has one "
                f"({which}): the run would score the receiver's own fixes; use --gps-profile "
                "native (the default auto does the same), or add a truth (--topic truth=...)"
            )
        if no_truth:
            notes.append(
                f"{flag}: {plural(len(no_truth), 'drive')} without a truth "
                f"({_names(no_truth)}) fed and scored on their own receiver's fixes (native)"
            )
        without = [d for d in missed if d.has_truth]  # native, no fixes of its own
        if without:
            notes.append(
                f"{flag}: {plural(len(without), 'drive')} without fixes of their own "
                f"({_names(without)}) fed rtk fixes drawn from their truth"
            )
    if cfg.gps_latency_s > 0.0:
        own = [d for d, c in zip(drives, conditions, strict=True) if c == "native"]
        latency = f"--gps-latency {cfg.gps_latency_s:g}"
        if len(own) == len(drives):
            raise UsageError(
                f"{latency} delays fixes drawn from a truth, and no drive of this run is fed "
                f"drawn fixes (--gps-profile {profile}: their own receiver's): leave it out, or "
                "draw fixes with --gps-profile rtk|consumer|none"
            )
        if own:
            notes.append(
                f"{latency}: {plural(len(own), 'drive')} fed their own receiver's fixes "
                f"({_names(own)}) without the latency"
            )
    return notes
