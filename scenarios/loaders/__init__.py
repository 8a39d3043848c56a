"""Format detection and dispatch: :func:`load` turns a path into drives.

A path may be one recording (a bag, a pickle, a CSV/Parquet file, a KITTI drive
folder, a comma2k19 segment folder) or a folder tree holding many; every
recording found becomes one :class:`~posbench.scenarios.drive.Drive`.
:func:`distinct_recordings` finds the recordings of several paths with each counted once
(the same file given twice, or a byte-identical copy under another name).
"""

from __future__ import annotations

import functools
import hashlib
import os
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError

ROS1_SUFFIXES = (".bag",)
ROS2_SUFFIXES = (".db3", ".mcap")
PICKLE_SUFFIXES = (".pickle", ".pkl")
TABLE_SUFFIXES = (".csv", ".parquet", ".pq")

T = TypeVar("T")


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
    """Load one recording of a known format. A fix or truth sample farther from the drive's
    origin than any point on Earth is refused
    (:func:`~posbench.scenarios.drive.refuse_far_positions`)."""
    from posbench.scenarios.drive import refuse_far_positions

    drive = _load_format(path, fmt, projection, topics)
    refuse_far_positions(drive, path)
    return drive


def _load_format(
    path: Path, fmt: str, projection: str = "enu", topics: dict[str, str] | None = None
) -> Drive:
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
    keep: Callable[[int, Drive], T] | None = None,
) -> Iterator[Drive] | Iterator[T]:
    """The drives at or under each of ``paths``, in the order given (as :func:`iter_load` of
    each), loaded by ``workers`` processes at a time (forked; one recording each). Every path
    is checked for recordings before any is loaded. A loader's :class:`DataError` is raised
    here, from whichever process met it, once the drives before it are yielded.

    ``keep``: what to make of each drive in the process that loaded it, given its index in
    the order of the recordings (e.g. write it to disk and describe it:
    :func:`posbench.scenarios.stored_drive.store_drive`); its results are yielded instead of
    the drives, so no drive crosses back to this process: with ``keep`` and ``workers`` > 1 a
    single recording is loaded in a child too, so that this process never holds a drive's
    loading peak (nor do the processes forked from it later)."""
    recs = [r for p in paths for r in _recordings(p)]
    job = functools.partial(_load_and_keep, projection=projection, topics=topics, keep=keep)
    alone = len(recs) <= 1 and keep is None  # one drive that comes back here anyway
    if workers <= 1 or alone or not _can_fork():
        for i, (rec_path, fmt) in enumerate(recs):
            yield job(i, rec_path, fmt)
        return
    import multiprocessing as mp

    from posbench.scenarios.child_processes import WorkerPool  # end with us, no Ctrl-C

    with WorkerPool(max_workers=min(workers, len(recs)), mp_context=mp.get_context("fork")) as pool:
        futures = [pool.submit(job, i, rec_path, fmt) for i, (rec_path, fmt) in enumerate(recs)]
        try:
            for fut in futures:
                yield fut.result()
        finally:
            for fut in futures:
                fut.cancel()


def _load_and_keep(
    index: int,
    path: Path,
    fmt: str,
    projection: str,
    topics: dict[str, str] | None,
    keep: Callable[[int, Drive], T] | None,
) -> Drive | T:
    drive = load_one(path, fmt, projection=projection, topics=topics)
    return drive if keep is None else keep(index, drive)


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


# ------------------------------------------------------------------ each recording once


@dataclass(frozen=True)
class Duplicate:
    """A recording given more than once: ``path`` is left out, ``kept`` (met first) counts.

    Attributes:
        path: the recording left out, as it was reached (a path given, or one found in a
            folder given).
        kept: the recording counted in its place.
        same_file: ``path`` is the very file or folder ``kept`` is (given twice, through a
            symbolic link, or both alone and inside a folder given); False: another file or
            folder with the same content (a byte-identical copy under another name).
    """

    path: Path
    kept: Path
    same_file: bool

    def line(self) -> str:
        """What was done, in one line: which paths are the same recording, which one counts."""
        if self.same_file and self.path == self.kept:
            return f"{self.path} given twice: counted once"
        why = "the same file" if self.same_file else "identical bytes"
        same = f"{self.path} is the same recording as {self.kept} ({why})"
        return f"{same}: counted once, as {self.kept}"


@dataclass(frozen=True)
class Recordings:
    """The recordings at or under some paths, each counted once (:func:`distinct_recordings`).

    Attributes:
        found: ``(path, format)`` of every recording counted, in the order given.
        duplicates: the recordings left out, in the order met, each the same as one of found.
        sources: the paths given that hold a recording counted, in the order given, each once.
    """

    found: list[tuple[Path, str]]
    duplicates: list[Duplicate]
    sources: list[Path]


def distinct_recordings(paths: Iterable[str | Path]) -> Recordings:
    """The recordings at or under each of ``paths`` (as :func:`iter_load_many` reads them),
    each counted once: a recording reached again (the same file or folder: a path given
    twice, a symbolic link to it, a file given alone and inside a folder given) or with the
    content of an earlier one (the same format and bytes: a file's, or a folder recording's
    files' relative paths and bytes) is left out, as a :class:`Duplicate` of the first.

    Only recordings whose every file has the size of another's are hashed (sha256), each
    file once per process: where no two are alike no file is read here.

    Raises:
        DataError: a path that does not exist or holds no recording (every path is checked
            before any file is read).
    """
    given = [Path(p) for p in paths]
    reached = [(i, rec, fmt) for i, p in enumerate(given) for rec, fmt in _recordings(p)]
    first: dict[Path, int] = {}  # resolved path -> its first position in ``reached``
    dropped: dict[int, Duplicate] = {}
    for n, (_, rec, _) in enumerate(reached):
        real = rec.resolve()
        if real in first:
            dropped[n] = Duplicate(rec, reached[first[real]][1], same_file=True)
        else:
            first[real] = n
    for n, m in _same_content([(n, r[1], r[2]) for n, r in enumerate(reached) if n not in dropped]):
        dropped[n] = Duplicate(reached[n][1], reached[m][1], same_file=False)
    kept = [r for n, r in enumerate(reached) if n not in dropped]
    held = {i for i, _, _ in kept}
    return Recordings(
        found=[(rec, fmt) for _, rec, fmt in kept],
        duplicates=[dropped[n] for n in sorted(dropped)],
        sources=[p for i, p in enumerate(given) if i in held],
    )


def _same_content(recs: list[tuple[int, Path, str]]) -> Iterator[tuple[int, int]]:
    """``(n, m)`` for every recording ``n`` of ``recs`` (position, path, format) whose
    format and content are those of an earlier one, ``m``: only recordings whose files have
    the same relative paths and sizes are hashed (and only those of a format met twice are
    listed)."""
    formats = Counter(fmt for _, _, fmt in recs)
    alike: dict[tuple[object, ...], list[tuple[int, list[tuple[str, Path, os.stat_result]]]]]
    alike = defaultdict(list)
    for n, rec, fmt in recs:
        if formats[fmt] < 2:
            continue
        files = _recording_files(rec)
        alike[(fmt, *((name, st.st_size) for name, _, st in files))].append((n, files))
    for group in alike.values():
        seen: dict[str, int] = {}
        for n, files in group if len(group) > 1 else ():
            digest = _content_sha256(files)
            if digest in seen:
                yield n, seen[digest]
            else:
                seen[digest] = n


def _recording_files(rec: Path) -> list[tuple[str, Path, os.stat_result]]:
    """The files of a recording with their ``stat``: a file alone (its name is no part of
    its content), or every file under a folder recording by relative POSIX path, sorted
    (symbolic links to folders not followed)."""
    if rec.is_file():
        return [("", rec, rec.stat())]
    out = []
    for folder, dirs, names in os.walk(rec):
        dirs.sort()
        for name in sorted(names):
            f = Path(folder, name)
            if f.is_file():
                out.append((f.relative_to(rec).as_posix(), f, f.stat()))
    return sorted(out, key=lambda e: e[0])


def _content_sha256(files: list[tuple[str, Path, os.stat_result]]) -> str:
    """sha256 over the relative paths and the sha256 of each of ``files``."""
    h = hashlib.sha256()
    for name, f, st in files:
        h.update(f"{name}\0{_file_sha256(f.resolve(), st.st_size, st.st_mtime_ns)}\n".encode())
    return h.hexdigest()


@functools.lru_cache(maxsize=4096)
def _file_sha256(path: Path, size: int, mtime_ns: int) -> str:
    """sha256 of one file's bytes; remembered while its size and modification time stay."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()
