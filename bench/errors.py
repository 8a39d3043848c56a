"""The error for a user's mistake in what they asked posbench to do.

:class:`UsageError`: an option, a value or a combination that cannot work, found before any
work starts; :class:`~posbench.scenarios.errors.DataError` (re-exported here): data that
cannot be read as given. Both become one line ``error: ...`` and exit status 2 on the
command line, and are raised as they are by the Python API (:func:`posbench.run`, ...).
"""

from __future__ import annotations

from posbench.scenarios.errors import DataError

__all__ = ["DataError", "UsageError"]


class UsageError(Exception):
    """A mistake in what was asked (an option, a value, a combination), in one line naming
    the option: ``bench`` prints it as ``error: ...`` and exits with status 2."""
