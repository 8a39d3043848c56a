"""Format detection and dispatch: :func:`load` turns a path into drives.

A path may be one recording (a bag, a pickle, a CSV/Parquet file, a KITTI drive
folder, a comma2k19 segment folder) or a folder tree holding many; every
recording found becomes one :class:`~posbench.scenarios.drive.Drive`.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError

ROS1_SUFFIXES = (".bag",)
ROS2_SUFFIXES = (".db3", ".mcap")
PICKLE_SUFFIXES = (".pickle", ".pkl")
TABLE_SUFFIXES = (".csv", ".parquet", ".pq")


def _is_kitti_drive(p: Path) -> bool:
    return (p / "oxts" / "timestamps.txt").is_file() or (
        p.name == "oxts" and (p / "timestamps.txt").is_file()
    )


def _is_comma_segment(p: Path) -> bool:
    return (
        (p / "processed_log" / "GNSS").is_dir()
        or (p / "global_pose").is_dir()
        and (p / "processed_log").is_dir()
    )


def _is_ros2_folder(p: Path) -> bool:
    return (p / "metadata.yaml").is_file()


def detect_format(path: Path) -> str | None:
    """The format of one recording at ``path``, or ``None`` if it is not a recording itself."""
    if path.is_file():
        suf = path.suffix.lower()
        if suf in ROS1_SUFFIXES:
            return "ros1"
        if suf in ROS2_SUFFIXES:
            # a .db3/.mcap inside a ROS 2 bag folder is read through its folder
            return None if _is_ros2_folder(path.parent) else "ros2"
        if suf in PICKLE_SUFFIXES:
            return "aslan"
        if suf in TABLE_SUFFIXES:
            return "table"
        return None
    if path.is_dir():
        if _is_ros2_folder(path):
            return "ros2"
        if _is_kitti_drive(path):
            return "kitti"
        if _is_comma_segment(path):
            return "comma2k19"
    return None


def find_recordings(path: Path) -> list[tuple[Path, str]]:
    """All recordings at or under ``path`` with their formats, sorted by path."""
    fmt = detect_format(path)
    if fmt is not None:
        return [(path, fmt)]
    if not path.is_dir():
        return []
    found: list[tuple[Path, str]] = []
    for child in sorted(path.iterdir()):
        if child.name.startswith("."):
            continue
        found.extend(find_recordings(child))
    return found


def load_one(
    path: Path, fmt: str, projection: str = "enu", topics: dict[str, str] | None = None
) -> Drive:
    """Load one recording of a known format."""
    if fmt == "kitti":
        from posbench.scenarios.loaders.kitti import load_kitti_drive

        return load_kitti_drive(path, projection=projection)
    if fmt == "comma2k19":
        from posbench.scenarios.loaders.comma2k19 import load_comma_segment

        return load_comma_segment(path, projection=projection)
    if fmt == "aslan":
        from posbench.scenarios.loaders.aslan import load_aslan_pickle

        return load_aslan_pickle(path)
    if fmt in ("ros1", "ros2"):
        from posbench.scenarios.loaders.rosbag import load_rosbag

        return load_rosbag(path, projection=projection, topics=topics)
    if fmt == "table":
        from posbench.scenarios.loaders.table import load_table

        return load_table(path, projection=projection)
    raise DataError(path, f"unknown format {fmt!r}")


def iter_load(
    path: str | Path, projection: str = "enu", topics: dict[str, str] | None = None
) -> Iterator[Drive]:
    """Yield the drives at or under ``path``; raise :class:`DataError` if there are none."""
    for rec_path, fmt in _recordings(path):
        yield load_one(rec_path, fmt, projection=projection, topics=topics)


def _recordings(path: str | Path) -> list[tuple[Path, str]]:
    """The recordings at or under ``path``; :class:`DataError` when there are none."""
    p = Path(path)
    if not p.exists():
        raise DataError(p, "no such file or folder")
    recs = find_recordings(p)
    if not recs:
        raise DataError(
            p,
            "unknown format: not a ROS bag (.bag/.db3/.mcap or folder with "
            "metadata.yaml), KITTI oxts drive, comma2k19 segment, route pickle "
            "(.pickle) or CSV/Parquet table, and no such recordings below it",
        )
    return recs


def iter_load_many(
    paths: Iterable[str | Path],
    projection: str = "enu",
    topics: dict[str, str] | None = None,
    workers: int = 1,
) -> Iterator[Drive]:
    """The drives at or under each of ``paths``, in the order given (as :func:`iter_load` of
    each), loaded by ``workers`` processes at a time (forked; one recording each). Every path
    is checked for recordings before any is loaded. A loader's :class:`DataError` is raised
    here, from whichever process met it, once the drives before it are yielded."""
    recs = [r for p in paths for r in _recordings(p)]
    if workers <= 1 or len(recs) <= 1 or not _can_fork():
        for rec_path, fmt in recs:
            yield load_one(rec_path, fmt, projection=projection, topics=topics)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(
        max_workers=min(workers, len(recs)), mp_context=mp.get_context("fork")
    ) as pool:
        futures = [
            pool.submit(load_one, rec_path, fmt, projection, topics) for rec_path, fmt in recs
        ]
        try:
            for fut in futures:
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _can_fork() -> bool:
    import multiprocessing as mp

    return "fork" in mp.get_all_start_methods()


def load(
    path: str | Path, projection: str = "enu", topics: dict[str, str] | None = None
) -> list[Drive]:
    """All drives at or under ``path`` (format detected). See :func:`iter_load`."""
    return list(iter_load(path, projection=projection, topics=topics))


def load_many(
    paths: Iterable[str | Path], projection: str = "enu", topics: dict[str, str] | None = None
) -> list[Drive]:
    """Drives from several paths, in the order given."""
    out: list[Drive] = []
    for p in paths:
        out.extend(load(p, projection=projection, topics=topics))
    return out
