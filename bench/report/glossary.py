"""The report's glossary: the definitions written once beside each metric
(``DEFINITIONS`` of :mod:`posbench.metrics.accuracy`, :mod:`posbench.metrics.bootstrap`,
:mod:`posbench.metrics.outages`, :mod:`posbench.metrics.seeds`, :mod:`posbench.metrics.latency`,
:mod:`posbench.metrics.limit`, :mod:`posbench.metrics.pcrb` and
:mod:`posbench.aggregation.aggregate`), picked for the figures a run's report prints."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from posbench.metrics import (
    accuracy,
    bootstrap,
    latency,
    limit,
    outage_lengths,
    outages,
    pcrb,
    seeds,
)
from posbench.scoring.schema import DEFINITIONS, TRACE_COLUMNS


def glossary(res: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(term, definition) for every kind of figure in the report of ``res``, in reading
    order: queries and errors, the summary figures, intervals, the paired comparison, seeds,
    outages, the limit, latency."""
    terms: list[tuple[str, str]] = [
        ("future / now", TRACE_COLUMNS["kind"][2]),
        *DEFINITIONS.items(),
    ]
    acc = dict(accuracy.DEFINITIONS)
    if not res.get("by_speed"):
        acc.pop("speed bin")
    terms += acc.items()
    boot = bootstrap.DEFINITIONS
    stats = res.get("statistics") or {}
    if stats:
        terms += [("95 % CI", boot["95 % CI"]), ("block bootstrap", boot["block bootstrap"])]
    if (res.get("paired") or {}).get("baseline"):
        terms += [(k, boot[k]) for k in ("paired difference", "wins")]
    if stats:
        terms.append(("conclusive", boot["conclusive"]))
    if res.get("seeds"):
        terms += seeds.DEFINITIONS.items()
    if res.get("outages"):
        terms += outages.DEFINITIONS.items()
    if res.get("outage_lengths"):
        terms += outage_lengths.DEFINITIONS.items()
    if res.get("limit"):
        terms += limit.DEFINITIONS.items()
        terms += [(k, pcrb.DEFINITIONS[k]) for k in ("PCRB", "jerk PSD q", "slow error floor")]
    terms += [(t, _where_measured(t, d, res)) for t, d in latency.DEFINITIONS.items()]
    return list(terms)


#: where ``bench run`` measures its latency columns (the summary table's ``worker ...``)
REPLAY_LATENCY = (
    " In `bench run` (columns `worker ...`): measured in the replay's worker processes, "
    "several at once on the machine's cores; `bench latency` gives single-process figures."
)


def _where_measured(term: str, definition: str, res: Mapping[str, Any]) -> str:
    """A latency term's definition, with where a replay measured it (scored answers carry
    their own latency: unchanged)."""
    return definition if res.get("answers") else definition + REPLAY_LATENCY


def glossary_lines(res: Mapping[str, Any]) -> list[str]:
    """The glossary as Markdown lines (a section)."""
    return ["## Glossary", ""] + [f"- **{t}**: {d}" for t, d in glossary(res)] + [""]
