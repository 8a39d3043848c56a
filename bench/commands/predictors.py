"""`bench predictors`: the registered predictors."""

from __future__ import annotations

from bench.commands.common import (
    console,
)


def list_predictors() -> None:
    """List the registered predictors."""
    from predictors.registry import available

    for name, e in available().items():
        console.print(f"[bold]{name:13s}[/] {e.description}")
