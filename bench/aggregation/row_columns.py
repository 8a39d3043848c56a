"""Per-row columns gathered one part of the traces at a time into arrays allocated once.

A section that reduces each part of the traces to a few numbers a row (a query's d^2, its
drive's code) and then needs them all at once would otherwise keep a list of small arrays
per part and join them: on a long run that is hundreds of small heap blocks per column,
interleaved with each part's freed frame, which the allocator cannot give back, and the
joined copy beside them (at 64 drive hours, 0.8 GB resident for 0.23 GB of columns).
:class:`RowColumns` writes each part's rows into one array per column, sized once from an
upper bound on the rows (the parts' metadata: :meth:`TraceSet.row_bound`), and hands each
column over at the end, trimmed or put in a given order, one column at a time.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import DTypeLike


class RowColumns:
    """Columns of per-row values, filled piece by piece in row order.

    Args:
        dtypes: column name -> dtype (a 2-D column: ``(dtype, width)``).
        capacity: at most this many rows will be added (None: not known; then the pieces
            are kept and joined at the end, as ``np.concatenate`` would).
    """

    def __init__(
        self, dtypes: Mapping[str, DTypeLike | tuple[DTypeLike, int]], capacity: int | None
    ):
        self._shapes = {
            name: (spec if isinstance(spec, tuple) else (spec, 0)) for name, spec in dtypes.items()
        }
        self._capacity = capacity
        self._filled: dict[str, np.ndarray] = {}
        self._pieces: dict[str, list[np.ndarray]] = {name: [] for name in dtypes}
        if capacity is not None:
            for name, (dtype, width) in self._shapes.items():
                shape = (capacity, width) if width else (capacity,)
                self._filled[name] = np.empty(shape, dtype=dtype)
        self.rows = 0

    def add(self, **columns: np.ndarray) -> None:
        """One piece's rows, every column of the same length; past the capacity: an error
        (the bound was wrong)."""
        sizes = {len(v) for v in columns.values()}
        if set(columns) != set(self._shapes) or len(sizes) != 1:
            raise ValueError(f"a piece needs every column, of one length: {sorted(self._shapes)}")
        n = sizes.pop()
        if self._capacity is None:
            for name, values in columns.items():
                self._pieces[name].append(np.asarray(values, dtype=self._shapes[name][0]))
        else:
            if self.rows + n > self._capacity:
                raise ValueError(f"more rows than the bound of {self._capacity}")
            for name, values in columns.items():
                self._filled[name][self.rows : self.rows + n] = values
        self.rows += n

    def group_order(self, name: str, values: int) -> tuple[np.ndarray, list[slice]]:
        """Take integer column ``name`` (values 0 .. ``values`` - 1; any other, e.g. -1, in
        no group) and return the order that puts the rows in groups by value, each group's
        rows in their own order (a stable sort), and each value's slice in that order:
        :meth:`take` the other columns in this order and each group is a slice, not a copy."""
        key = self.take(name)
        order = np.argsort(key, kind="stable")
        bounds = np.searchsorted(key[order], np.arange(values + 1))
        return order, [slice(int(bounds[i]), int(bounds[i + 1])) for i in range(values)]

    def take(self, name: str, order: np.ndarray | None = None) -> np.ndarray:
        """Column ``name``'s rows (in ``order``, given one: indices of the rows), as a new
        array; the column's buffer is let go (take each column once)."""
        if self._capacity is None:
            dtype, width = self._shapes[name]
            pieces = self._pieces.pop(name)
            empty = np.empty((0, width) if width else (0,), dtype=dtype)
            joined = np.concatenate(pieces) if pieces else empty
            del pieces
            return joined if order is None else joined[order]
        buffer = self._filled.pop(name)
        if order is None and self.rows == len(buffer):
            return buffer  # filled to the bound: the buffer is the column
        rows = buffer[: self.rows]
        out = rows.copy() if order is None else rows[order]
        del rows, buffer
        return out


def extend_codes(values: object, table: list[object], index: dict[object, int]) -> np.ndarray:
    """``values`` (a part's text column or array; missing as NaN/None) as int16 indices
    into ``table``, which grows by the values not in it yet, in order of first appearance
    (``index``: value -> its index, kept beside ``table``); -1 where missing. Parts read one
    at a time so get one numbering for all of them."""
    import pandas as pd

    codes, uniques = pd.factorize(values, use_na_sentinel=True)
    mapping = np.array([*(index.setdefault(u, len(index)) for u in uniques), -1], dtype=np.int16)
    table.extend(list(index)[len(table) :])
    out: np.ndarray = mapping[codes]
    return out
