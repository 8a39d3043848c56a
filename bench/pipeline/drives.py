"""The drives a run replays: recordings loaded (in parallel processes where asked), or the
built-in synthetic drives when no data is given."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from posbench.pipeline.reporter import SILENT, Reporter
from posbench.scenarios.drive import Drive
from posbench.scenarios.stored_drive import StoredDrive, store_drive


def load_drives(
    paths: Sequence[str | Path] | None,
    projection: str = "enu",
    topics: dict[str, str] | None = None,
    seed: int = 0,
    synthetic_duration_s: float | None = None,
    workers: int = 1,
    reporter: Reporter = SILENT,
) -> list[Drive]:
    """The drives at ``paths`` in order, held here: :func:`stored_drives`'s without a
    folder."""
    found: list[Drive] = _gather(
        paths, projection, topics, seed, synthetic_duration_s, workers, reporter, None
    )
    return found


def stored_drives(
    paths: Sequence[str | Path] | None,
    folder: Path,
    projection: str = "enu",
    topics: dict[str, str] | None = None,
    seed: int = 0,
    synthetic_duration_s: float | None = None,
    workers: int = 1,
    reporter: Reporter = SILENT,
) -> list[StoredDrive]:
    """The drives at ``paths`` in order (``workers`` processes load recordings in parallel;
    ``projection``: the local frame of lat/lon sources, ``topics``: bag topics by role), or
    without paths the built-in synthetic drives of generator ``seed`` (one mixed drive of
    ``synthetic_duration_s`` [s] if given). Local paths only: URLs are fetched first
    (:func:`posbench.scenarios.remote.local_paths`). A recording given twice (or a
    byte-identical copy) is loaded once, said in one line
    (:func:`posbench.scenarios.loaders.distinct_recordings`).

    The loading processes write each drive into ``folder``, checked
    (:func:`posbench.scenarios.stored_drive.store_drive`): the drives are returned as
    :class:`~posbench.scenarios.stored_drive.StoredDrive` descriptions and never held here
    (the built-in synthetic drives are made in this process, then stored the same way)."""
    found: list[StoredDrive] = _gather(
        paths, projection, topics, seed, synthetic_duration_s, workers, reporter, folder
    )
    return found


def _gather(
    paths: Sequence[str | Path] | None,
    projection: str,
    topics: dict[str, str] | None,
    seed: int,
    synthetic_duration_s: float | None,
    workers: int,
    reporter: Reporter,
    store: Path | None,
) -> list[Any]:
    """The drives, or (given ``store``) their stored descriptions."""
    from posbench.scenarios.loaders import distinct_recordings, iter_load_many

    if not paths:
        from posbench.checks import check_synthetic_duration
        from posbench.scenarios.synthetic import default_drives, generate_drive

        if check_synthetic_duration(synthetic_duration_s, paths) is not None:
            made = [generate_drive(seed=seed, route="mixed", duration_s=synthetic_duration_s)]
        else:
            made = default_drives(seed=seed)
        if store is None:
            return made
        return [_store_at(store, i, d) for i, d in enumerate(made)]
    from posbench.pipeline.preload import REPLAY_MODULES, Preload
    from posbench.pipeline.reporter import WARNING

    recordings = distinct_recordings(paths)
    for dup in recordings.duplicates:
        reporter.line(f"note: {dup.line()}", WARNING)
    drives: list[Any] = []
    keep = None if store is None else functools.partial(_store_at, store)
    preload = Preload(REPLAY_MODULES)  # for the replay workers, forked after loading
    with reporter.phase("loading drives...") as update:
        for d in iter_load_many(
            [rec for rec, _ in recordings.found],
            projection=projection,
            topics=topics,
            workers=workers,
            keep=keep,
        ):
            drives.append(d)
            if workers > 1:  # the loader processes exist by now: safe to import in a thread
                preload.start()
            update(f"loading drives... {len(drives)} ({d.name})")
    preload.join()
    return drives


def _store_at(folder: Path, index: int, drive: Drive) -> StoredDrive:
    """``drive`` (the ``index``-th recording) written into ``folder``, checked and described."""
    return store_drive(drive, folder / f"drive-{index:06d}.pickle")
