"""The lstm's and the hybrid's training drives: loaded, synthetic and corpus drives, split
by route (never by window), with GPS degraded from a truth under each profile, and what the
model card records about them (file hashes, the corpus's envelope)."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path

from posbench.predictors.lstm.windows import WindowSet, drive_windows
from posbench.scenarios.drive import Drive
from posbench.scenarios.errors import DataError

#: the route split: per source group in name order, every VAL_EVERY-th drive from index
#: VAL_OFFSET is held out for validation
VAL_EVERY = 5
VAL_OFFSET = 2


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def manifest(paths: Sequence[str | Path]) -> list[dict]:
    """sha256 of every file at or under each path."""
    out = []
    for p in map(Path, paths):
        files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file())
        out.append(
            {
                "path": str(p),
                "files": [
                    {
                        "file": str(f.relative_to(p)) if f != p else f.name,
                        "bytes": f.stat().st_size,
                        "sha256": sha256_file(f),
                    }
                    for f in files
                ],
            }
        )
    return out


SYNTH_SEED_BASE = 10_000
#: drive formats training refuses: KITTI is evaluation only (licence and the benchmark's rule)
EVALUATION_ONLY = ("kitti",)


def synthetic_seeds(n: int, seed: int) -> list[int]:
    """Generator seeds of the training drives: 10000 + 1000 * seed + i, far from the small
    seeds the benchmark's own synthetic data set uses (no train/test overlap)."""
    return [SYNTH_SEED_BASE + 1000 * seed + i for i in range(n)]


def synthetic_drives(n: int, seed: int) -> list[Drive]:
    """``n`` drives from the project's synthetic generator, routes in turn (seeded)."""
    if n <= 0:
        return []
    from posbench.scenarios.synthetic import ROUTES, generate_drive

    return [
        generate_drive(seed=s, route=ROUTES[i % len(ROUTES)])
        for i, s in enumerate(synthetic_seeds(n, seed))
    ]


def group_of(drive: Drive) -> str:
    """Source group used for the split and the per-source metrics."""
    fmt = (drive.meta.format or "").lower()
    return fmt if fmt else "other"


def split_by_route(drives: Sequence[Drive]) -> tuple[list[Drive], list[Drive]]:
    """Per source group, in name order, every 5th drive from the 3rd is held out (groups of
    fewer than 3 drives train only). Falls back to holding out the last drive if that
    leaves no validation drive, and to validating on the training drive if there is one."""
    groups: dict[str, list[Drive]] = {}
    for d in drives:
        groups.setdefault(group_of(d), []).append(d)
    train: list[Drive] = []
    val: list[Drive] = []
    for g in sorted(groups):
        ds = sorted(groups[g], key=lambda d: d.name)
        for i, d in enumerate(ds):
            (val if len(ds) >= 3 and i % VAL_EVERY == VAL_OFFSET else train).append(d)
    if not val and len(train) > 1:
        val.append(train.pop())
    if not val:
        val = list(train)
    return train, val


def gps_variants(drive: Drive, n_seeds: int, seed: int, profiles: Sequence[str] = ("rtk",)) -> list:
    """GPS streams to train on: the drive's own (no truth) or, per profile, ``n_seeds``
    degradations of its truth (each with freshly drawn fix times)."""
    if drive.truth is None or len(drive.truth) < 2:
        return [drive.gps]
    from posbench.scenarios.degrade import degrade_gps

    return [
        degrade_gps(drive.truth, prof, seed=seed * 1000 + 100 * j + k)
        for j, prof in enumerate(profiles)
        for k in range(n_seeds)
    ]


def build_windows(
    drives: Sequence[Drive],
    n_seeds: int,
    seed: int,
    frame: str,
    profiles: Sequence[str] = ("rtk",),
    fix_offset: bool = False,
) -> WindowSet:
    return WindowSet.concat(
        [
            drive_windows(d, g, frame, fix_offset=fix_offset)
            for d in drives
            for g in gps_variants(d, n_seeds, seed, profiles)
        ]
    )


def corpus(hours: float, seed: int) -> list[Drive]:
    """``hours`` of the vehicle-dynamics corpus
    (:func:`posbench.scenarios.corpus.corpus_drives`)."""
    if hours <= 0:
        return []
    from posbench.scenarios.corpus import corpus_drives

    return list(corpus_drives(hours, seed=seed))


def gather_drives(
    data_paths: Sequence[str | Path],
    synthetic: int,
    corpus_hours: float,
    seed: int,
    drives: Sequence[Drive] | None = None,
) -> tuple[list[Drive], list[Drive], list[Drive]]:
    """Every training source loaded and split by route: (train, validation, the corpus
    drives among them); a one-line DataError when there is none."""
    from posbench.scenarios.loaders import load

    all_drives: list[Drive] = []
    for p in data_paths:
        loaded = load(p)
        kitti = [d.name for d in loaded if (d.meta.format or "").lower() in EVALUATION_ONLY]
        if kitti:
            raise DataError(
                p,
                f"KITTI is evaluation-only data (non-commercial licence; never "
                f"trained on): {len(kitti)} drive(s), e.g. {kitti[0]}",
            )
        all_drives.extend(loaded)
    all_drives.extend(synthetic_drives(synthetic, seed))
    corpus_d = corpus(corpus_hours, seed)
    all_drives.extend(corpus_d)
    all_drives.extend(drives or [])
    if not all_drives:
        raise DataError(
            None, "no training drives: give --data PATH, --synthetic N or --corpus-hours H"
        )
    train_d, val_d = split_by_route(all_drives)
    return train_d, val_d, corpus_d


def corpus_card(drives: Sequence[Drive], hours: float, seed: int) -> dict:
    """What the model card says about the corpus drives: hours asked, the generator, the
    seed and the envelope the drives cover (:func:`posbench.scenarios.corpus.envelope`)."""
    if not drives:
        return {"hours": 0}
    from posbench.scenarios.corpus import envelope

    return {
        "hours": hours,
        "seed": seed,
        "generator": "posbench.scenarios.corpus.corpus_drives",
        "drives": len(drives),
        "envelope": envelope(drives),
    }
