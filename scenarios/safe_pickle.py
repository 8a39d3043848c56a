"""A restricted unpickler for data pickles: NumPy arrays and plain containers only.

Unpickling an ordinary pickle runs whatever callables it names (``os.system``,
``subprocess.Popen``, ...). :class:`SafeUnpickler` resolves a name only if it is
in a fixed allow-list of NumPy array / dtype / scalar reconstructors, a few
harmless builtin containers and a Latin-1-only ``_codecs.encode`` (how
protocols 0-2 spell ``bytes``); any other name raises :class:`DataError` at the
moment the pickle asks for it, before anything it names is called.

Pickles written under NumPy 1.x name ``numpy.core.*``; NumPy 2 moved those to
``numpy._core.*`` (importing ``numpy.core`` still works but is deprecated). Both
spellings are admitted and resolved to whichever module the installed NumPy has.
"""

from __future__ import annotations

import _compat_pickle
import collections
import io
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from posbench.scenarios.errors import DataError


def _np_core(submodule: str, name: str) -> Callable[[], Any]:
    """Resolver of ``numpy[._]core.<submodule>.<name>`` for the installed NumPy."""

    def resolve() -> Any:
        import importlib

        for base in ("numpy._core", "numpy.core"):
            try:
                mod = importlib.import_module(f"{base}.{submodule}")
            except ImportError:
                continue
            if hasattr(mod, name):
                return getattr(mod, name)
        raise AttributeError(f"numpy has no core.{submodule}.{name}")

    return resolve


def _const(obj: Any) -> Callable[[], Any]:
    return lambda: obj


def _latin1_encode(obj: str, encoding: str = "utf-8", errors: str = "strict") -> bytes:
    """``_codecs.encode`` as protocol 0-2 pickles use it for ``bytes``: Latin-1 only."""
    if not isinstance(obj, str) or encoding.lower().replace("_", "-") not in ("latin1", "latin-1"):
        raise ValueError(f"refused _codecs.encode with encoding {encoding!r} (only latin1)")
    return obj.encode("latin-1", errors)


_NUMPY_CORE = {
    ("multiarray", "_reconstruct"),
    ("multiarray", "scalar"),
    ("numeric", "_frombuffer"),
}

#: (module, name) -> resolver; the only globals a data pickle may name.
ALLOWED: dict[tuple[str, str], Callable[[], Any]] = {
    ("numpy", "ndarray"): _const(np.ndarray),
    ("numpy", "dtype"): _const(np.dtype),
    ("collections", "OrderedDict"): _const(collections.OrderedDict),
    ("builtins", "set"): _const(set),
    ("builtins", "frozenset"): _const(frozenset),
    ("builtins", "complex"): _const(complex),
    ("builtins", "bytearray"): _const(bytearray),
    ("builtins", "slice"): _const(slice),
    # protocol 0-2 pickles spell bytes (e.g. array buffers) as _codecs.encode(str, "latin1")
    ("_codecs", "encode"): _const(_latin1_encode),
}
for _sub, _name in _NUMPY_CORE:
    for _base in ("numpy.core", "numpy._core"):
        ALLOWED[(f"{_base}.{_sub}", _name)] = _np_core(_sub, _name)


class SafeUnpickler(pickle.Unpickler):
    """:class:`pickle.Unpickler` that resolves only the names in :data:`ALLOWED`.

    Args:
        file: a binary file object positioned at the pickle.
        source: the file's path, named in errors.
    """

    def __init__(self, file: Any, source: str | Path) -> None:
        super().__init__(file)
        self.source = source

    def find_class(self, module: str, name: str) -> Any:
        # Python 2 spellings (protocols 0-2), e.g. __builtin__.set, as the stdlib maps them
        if (module, name) in _compat_pickle.NAME_MAPPING:
            module, name = _compat_pickle.NAME_MAPPING[(module, name)]
        elif module in _compat_pickle.IMPORT_MAPPING:
            module = _compat_pickle.IMPORT_MAPPING[module]
        resolver = ALLOWED.get((module, name))
        if resolver is None:
            raise DataError(
                self.source,
                f"refused to unpickle '{module}.{name}': only NumPy "
                "arrays and plain containers are allowed in data "
                "pickles (this one would run code when opened)",
            )
        return resolver()

    def persistent_load(self, pid: Any) -> Any:
        raise DataError(
            self.source,
            "refused to unpickle a persistent id: only NumPy arrays "
            "and plain containers are allowed in data pickles",
        )


def safe_loads(data: bytes, source: str | Path) -> Any:
    """Unpickle ``data`` with :class:`SafeUnpickler`; any failure is a :class:`DataError`."""
    try:
        return SafeUnpickler(io.BytesIO(data), source).load()
    except DataError:
        raise
    except (
        pickle.UnpicklingError,
        EOFError,
        ValueError,
        TypeError,
        AttributeError,
        IndexError,
        KeyError,
        MemoryError,
        OverflowError,
    ) as exc:
        raise DataError(
            source, f"not a readable pickle (truncated or corrupt?): {type(exc).__name__}: {exc}"
        ) from None


def safe_load(path: str | Path) -> Any:
    """Read and unpickle the file at ``path`` with :class:`SafeUnpickler`."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise DataError(p, f"cannot read: {exc.strerror or exc}") from None
    return safe_loads(data, p)
