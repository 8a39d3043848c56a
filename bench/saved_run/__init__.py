"""A run as data: :class:`Run` (results.json and its traces), written by :func:`save_run`
and read back by :func:`load_run`; the data provenance and the output bookkeeping."""

from posbench.saved_run.run import Run, load_run, save_run

__all__ = ["Run", "load_run", "save_run"]
