"""The ``bench`` command line: the Typer app (:mod:`posbench.cli.app`), one module per
command, the option types they share and the terminal output."""

from posbench.cli.app import main

__all__ = ["main"]
