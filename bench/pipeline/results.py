"""The whole content of ``results.json`` for a replay or for scored answers: what the run was
(command, config, package versions, git commit, data hashes) and its figures."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import pandas as pd

from posbench.aggregation.aggregate import aggregate
from posbench.aggregation.intervals import Statistics
from posbench.config import RunConfig
from posbench.saved_run.provenance import git_commit, package_versions
from posbench.scoring.records import DriveRun


def build_results(runs: Sequence[DriveRun], cfg: RunConfig, data: list[dict[str, Any]],
                  command: str, *, traces: pd.DataFrame | None = None,
                  models: Mapping[str, Mapping[str, Any]] | None = None,
                  statistics: Statistics | None = None) -> dict[str, Any]:
    """``results.json`` of ``runs`` replayed under ``cfg``: its provenance (``command``, the
    config, package versions, the git commit, ``data``: the data block,
    :func:`posbench.saved_run.provenance.data_provenance`) then the figures of
    :func:`posbench.aggregation.aggregate.aggregate`. ``models``: the learned models behind
    the predictors; None builds each learned predictor of ``cfg`` once to ask
    (:func:`posbench.replay.predictor_setup.learned_models`), ``{}`` for none."""
    if models is None:
        from posbench.replay.predictor_setup import learned_models

        models = learned_models(cfg)
    head = {"command": command, "config": cfg.to_dict(), "versions": package_versions(),
            "git_commit": git_commit(), "data": data}
    return {**head, **aggregate(runs, cfg, traces=traces, models=models, statistics=statistics)}
