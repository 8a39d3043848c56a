"""The ``bench`` command line as a click command, for mkdocs-click (``reference/cli.md``):
typer builds it from :data:`posbench.cli.app.app` exactly as ``bench`` runs it."""

from __future__ import annotations

import re

import typer.main

from posbench.cli.app import app

#: the click group behind ``bench`` (typer's own copy of click; mkdocs-click takes it)
click_app = typer.main.get_command(app)


def command_names(group=click_app, prefix: str = "") -> list[str]:  # noqa: ANN001
    """Every (sub)command's path below ``group``, e.g. ``run``, ``data inspect``."""
    out: list[str] = []
    for name, cmd in getattr(group, "commands", {}).items():
        path = f"{prefix}{name}"
        sub = getattr(cmd, "commands", None)
        out += command_names(cmd, path + " ") if sub else [path]
    return out


def _escape_headings(cmd) -> None:  # noqa: ANN001
    """mkdocs-click renders help as Markdown: a help line starting with ``#`` (a wrapped
    ``# comments``) would be a heading; escaped here, on the docs' copy of the command."""
    if getattr(cmd, "help", None):
        cmd.help = re.sub(r"(?m)^(\s*)#", r"\1\\#", cmd.help)
    for sub in getattr(cmd, "commands", {}).values():
        _escape_headings(sub)


_escape_headings(click_app)
