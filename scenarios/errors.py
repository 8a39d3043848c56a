"""Errors raised for bad user input (files, formats, values).

The CLI turns a :class:`DataError` into a one-line message and exit status 2,
never a traceback: every message names the file and, where it applies, the
topic, column or row at fault.
"""

from __future__ import annotations

from pathlib import Path


class DataError(Exception):
    """A user's data cannot be read as given.

    Args:
        path: the file or folder at fault.
        detail: what is wrong, naming topic / row / column where relevant.
    """

    def __init__(self, path: str | Path | None, detail: str) -> None:
        self.path = None if path is None else str(path)
        self.detail = detail
        super().__init__(f"{self.path}: {detail}" if self.path else detail)

    def __reduce__(self) -> tuple:
        # pickle (process pools, Ray) rebuilds an exception from ``args`` = (message,), which
        # does not fit ``__init__(path, detail)``: rebuild it from its own arguments instead
        return type(self), (self.path, self.detail), self.__dict__
