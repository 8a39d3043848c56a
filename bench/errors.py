"""posbench.errors (split from the flat bench/; docstring to write)."""

from __future__ import annotations


class UsageError(Exception):
    """A command-line mistake: reported in one line, exit status 2."""
