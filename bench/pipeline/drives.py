"""The drives a run replays: recordings loaded (in parallel processes where asked), or the
built-in synthetic drives when no data is given."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from posbench.pipeline.reporter import SILENT, Reporter
from posbench.scenarios.drive import Drive


def load_drives(
    paths: Sequence[str | Path] | None,
    projection: str = "enu",
    topics: dict[str, str] | None = None,
    seed: int = 0,
    synthetic_duration_s: float | None = None,
    workers: int = 1,
    reporter: Reporter = SILENT,
) -> list[Drive]:
    """The drives at ``paths`` in order (``workers`` processes load recordings in parallel;
    ``projection``: the local frame of lat/lon sources, ``topics``: bag topics by role), or
    without paths the built-in synthetic drives of generator ``seed`` (one mixed drive of
    ``synthetic_duration_s`` [s] if given). Local paths only: URLs are fetched first
    (:func:`posbench.scenarios.remote.local_paths`). A recording given twice (or a
    byte-identical copy) is loaded once, said in one line
    (:func:`posbench.scenarios.loaders.distinct_recordings`)."""
    from posbench.scenarios.loaders import distinct_recordings, iter_load_many

    if not paths:
        from posbench.checks import check_synthetic_duration
        from posbench.scenarios.synthetic import default_drives, generate_drive

        if check_synthetic_duration(synthetic_duration_s, paths) is not None:
            return [generate_drive(seed=seed, route="mixed", duration_s=synthetic_duration_s)]
        return default_drives(seed=seed)
    from posbench.pipeline.preload import REPLAY_MODULES, Preload
    from posbench.pipeline.reporter import WARNING

    recordings = distinct_recordings(paths)
    for dup in recordings.duplicates:
        reporter.line(f"note: {dup.line()}", WARNING)
    drives = []
    preload = Preload(REPLAY_MODULES)  # for the replay workers, forked after loading
    with reporter.phase("loading drives...") as update:
        for d in iter_load_many(
            [rec for rec, _ in recordings.found],
            projection=projection,
            topics=topics,
            workers=workers,
        ):
            drives.append(d)
            if workers > 1:  # the loader processes exist by now: safe to import in a thread
                preload.start()
            update(f"loading drives... {len(drives)} ({d.name})")
    preload.join()
    return drives
