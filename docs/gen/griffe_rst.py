"""Griffe extension (mkdocs.yml, python handler ``extensions``): the reStructuredText that
posbench's docstrings use read as Markdown in the API reference, without touching them.

* ``:class:`~posbench.saved_run.run.Run``` (any Sphinx role) -> `` `Run` `` (``~``: the
  last name, as Sphinx shows it) or the whole dotted name;
* double back-quotes -> single;
* a paragraph ending ``::`` (an RST literal block follows) -> ``:``; the indented block
  after it is a Markdown code block already.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":[a-z]+:`(~?)([^`<]+?)(?:\s*<[^>]*>)?`")


def markdown(text: str) -> str:
    """``text`` with the RST above rewritten as Markdown."""
    text = ROLE.sub(lambda m: f"`{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}`", text)
    text = text.replace("``", "`")
    return re.sub(r"(?m)(\S)::$", r"\1:", text)


class RstToMarkdown(griffe.Extension):
    """Rewrites every loaded object's docstring (see the module docstring)."""

    def on_object(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = markdown(obj.docstring.value)

    def on_module(self, *, mod: griffe.Module, **kwargs: Any) -> None:
        self.on_object(obj=mod)
