"""The whole content of ``results.json`` for a replay or for scored answers: what the run was
(command, config, package versions, git commit, data hashes) and its figures."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from posbench.aggregation.aggregate import aggregate
from posbench.aggregation.intervals import Statistics
from posbench.config import BUILT_IN_TUNING, RunConfig
from posbench.saved_run.provenance import git_commit, package_versions
from posbench.scoring.records import DriveRun


def build_results(
    runs: Sequence[DriveRun],
    cfg: RunConfig,
    data: list[dict[str, Any]],
    command: str,
    *,
    traces: pd.DataFrame | None = None,
    models: Mapping[str, Mapping[str, Any]] | None = None,
    statistics: Statistics | None = None,
    workers: int = 1,
    sections: Mapping[str, Any] | None = None,
    paper_figures: Callable[[], Sequence[tuple[str, str]]] | None = None,
) -> dict[str, Any]:
    """``results.json`` of ``runs`` replayed under ``cfg``: its provenance (``command``, the
    config, package versions, the git commit, ``data``: the data block,
    :func:`posbench.saved_run.provenance.data_provenance`) then the figures of
    :func:`posbench.aggregation.aggregate.aggregate`. ``models``: the learned models behind
    the predictors; None builds each learned predictor of ``cfg`` once to ask
    (:func:`posbench.replay.predictor_setup.learned_models`), ``{}`` for none.
    ``workers``: child processes computing the predictors' figures at a time (``aggregate``).

    The dict is built here once, complete, and never edited afterwards (its ``status`` aside,
    which says whether the files were written, :func:`posbench.saved_run.run.mark_unfinished`):
    after the figures come ``gps_conditions`` (drives per GPS condition scored), then
    ``sections``, what the run knows of itself beside its figures (``consistency``,
    ``unhonoured``, ``data_duplicates``, ``seeds``, a scored file's ``answers``), in their
    order, then ``paper_figures``: the (file, caption) pairs ``paper_figures()`` returns,
    called once the figures are combined (the paper's figures are drawn in another process
    meanwhile); none without it."""
    if models is None:
        from posbench.replay.predictor_setup import learned_models

        models = learned_models(cfg)
    tuning = tuning_provenance(cfg, runs)
    models = {
        **models,
        **{
            n: {
                "model": f"tuning {t['file']}",
                "bundled": t["built_in"],
                "train_drives": t["drives"],
            }
            for n, t in tuning.items()
            if t["drives"] and n not in models
        },
    }
    head = {
        "command": command,
        "config": cfg.to_dict(),
        "versions": package_versions(),
        "git_commit": git_commit(),
        "data": data,
        "tuning": tuning,
    }
    figures = aggregate(
        runs, cfg, traces=traces, models=models, statistics=statistics, workers=workers
    )
    drawn = paper_figures() if paper_figures is not None else []
    return {
        **head,
        **figures,
        "gps_conditions": scored_conditions(figures["drives"]),
        **(sections or {}),
        "paper_figures": [{"file": f, "caption": c} for f, c in drawn],
    }


def scored_conditions(drives: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """How many drives were scored under each GPS condition (``drives``: results.json's
    ``drives``; a skipped drive has none)."""
    counts = Counter(
        str(d["gps_condition"]) for d in drives if not d.get("skipped") and d.get("gps_condition")
    )
    return dict(sorted(counts.items()))


def tuning_provenance(cfg: RunConfig, runs: Sequence[DriveRun]) -> dict[str, dict[str, Any]]:
    """Per predictor of the run that ran with tuned parameters: ``file`` (the user's path as
    given, or :data:`BUILT_IN_TUNING`), ``sha256`` of it, ``built_in`` (the package's file),
    ``conditions`` (per GPS condition used: its ``params``, ``how`` they were obtained and the
    ``file`` they come from, with its ``sha256`` and the condition's development ``drives``: a
    user's file may hold some conditions, the package's the others; the predictor's ``file``
    is the first condition's) and ``drives`` (the development drives the tuning used over all
    conditions, marked in the run like a learned model's training drives)."""
    import hashlib

    from posbench.predictors.registry import TUNED_FILE, base_name, tuning_entry

    if not cfg.use_tuned:
        return {}
    conditions = sorted({r.gps_condition for r in runs if not r.skipped and r.gps_condition})
    out: dict[str, dict[str, Any]] = {}
    sha256: dict[Path, str] = {}  # each file hashed once
    for name in cfg.predictors:
        for cond in conditions:
            found = tuning_entry(base_name(name), cond, cfg.tuning)
            if found is None:
                continue
            path, entry = found
            built_in = path == TUNED_FILE  # named by its place in the package, not the disk
            file = BUILT_IN_TUNING if built_in else str(path)
            if path not in sha256:
                sha256[path] = hashlib.sha256(path.read_bytes()).hexdigest()
            t = out.setdefault(
                name,
                {
                    "file": file,
                    "built_in": built_in,
                    "sha256": sha256[path],
                    "conditions": {},
                    "drives": [],
                },
            )
            t["conditions"][cond] = {
                "params": entry.get("params", {}),
                "how": entry.get("how", ""),
                "file": file,
                "sha256": sha256[path],
                "drives": sorted(entry.get("drives", [])),
            }
            t["drives"] = sorted(set(t["drives"]) | set(entry.get("drives", [])))
    return out
