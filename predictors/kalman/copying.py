"""Copies of the filters' state objects that leave the original as fast as it was.

A bank's shadows copy its members' helpers (heading tracker, bias estimator, fix-noise
model) every few seconds. ``copy.copy`` reads an object's ``__dict__``, and in CPython 3.11+
reading it turns the object's inline attribute storage into a real dict for good: every attribute
access of the *original* is then slower (measured: the kf bank's fix step +20 % at p50
after one copy). So the filters copy their attributes by name (each class lists them in
``_ATTRS``; a test checks that the list holds every attribute an instance has), which
never touches the original's ``__dict__``.
"""

from __future__ import annotations

from typing import TypeVar

T = TypeVar("T")


def copy_attrs(obj: T, names: tuple[str, ...]) -> T:
    """A new object of ``obj``'s class (``__init__`` not called) holding the same values of
    the attributes ``names``: a shallow copy, to be completed by the caller for what is
    mutable."""
    new = object.__new__(type(obj))
    for name in names:
        setattr(new, name, getattr(obj, name))
    return new
