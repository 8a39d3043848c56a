"""Answers -> traces: the trace schema (:mod:`~posbench.scoring.schema`), scoring
(:mod:`~posbench.scoring.score`) and the per-drive records every later step reads
(:mod:`~posbench.scoring.records`)."""
