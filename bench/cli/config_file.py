"""Options from a TOML file (``--config FILE.toml``), and a command's options written as one
(``bench run --print-config``).

A config file holds one table per command, named as the command is called (``[run]``,
``[compare]``, ``[data.inspect]``); its keys are the long option names without the dashes
(``gps-profile``, ``data``, ``no-gate`` is ``gate = false``; underscores work too), its values
TOML values (a list for a repeatable option). They become the command's defaults: an option
given on the command line wins. A key the command does not take is an error naming the file,
the table and the key. Example::

    [run]
    predictors = ["kf", "lstm"]
    data = ["../shared/data/kitti_raw"]
    gps-profile = "consumer"
    seeds = "5"
"""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import typer

from posbench.errors import UsageError

#: options that are never written by --print-config nor read from a file
NOT_SAVED = ("config", "print_config", "quiet", "verbose", "help")


def option_key(param: Any) -> str:
    """The key of ``param`` in a config file: its first long option name without the dashes
    (``--gps-profile`` -> ``gps-profile``; ``--gate/--no-gate`` -> ``gate``), else its name."""
    longs = [o for o in param.opts if o.startswith("--")]
    return longs[0][2:] if longs else str(param.name)


def _section(data: Mapping[str, Any], path: list[str]) -> Mapping[str, Any] | None:
    node: Any = data
    for part in path:
        if not isinstance(node, Mapping) or part not in node:
            return None
        node = node[part]
    return node if isinstance(node, Mapping) else None


def read_section(file: Path, command_path: list[str], params: list[Any]) -> dict[str, Any]:
    """The table of ``command_path`` (``["run"]``, ``["data", "inspect"]``) in the TOML
    ``file`` as ``{parameter name: value}`` for the command's ``params``; empty when the file
    has no such table.

    Raises:
        UsageError: no such file, not TOML, or a key the command does not take.
    """
    try:
        data = tomllib.loads(file.read_text())
    except FileNotFoundError:
        raise UsageError(f"--config {file}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise UsageError(f"--config {file}: cannot read it: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise UsageError(f"--config {file}: not TOML: {e}") from None
    table = _section(data, command_path)
    if table is None:
        return {}
    keys: dict[str, Any] = {}
    for p in params:
        if p.name in NOT_SAVED or getattr(p, "hidden", False):
            continue
        keys[option_key(p)] = p
        keys[str(p.name)] = p
    out: dict[str, Any] = {}
    name = ".".join(command_path)
    for key, value in table.items():
        p = keys.get(key) or keys.get(key.replace("_", "-"))
        if p is None:
            shown = sorted({option_key(q) for q in keys.values()})
            raise UsageError(
                f"--config {file}: [{name}] has no option {key!r}; `bench "
                f"{name.replace('.', ' ')}` takes {', '.join(shown)}"
            )
        out[str(p.name)] = value
    return out


def load_config(ctx: typer.Context, param: Any, value: Path | None) -> Path | None:
    """The eager callback of ``--config``: the file's table for this command becomes the
    defaults of its other options (``ctx.default_map``), before they are read."""
    if value is None:
        return None
    path = ctx.command_path.split()[1:]  # "bench data inspect" -> ["data", "inspect"]
    try:
        defaults = read_section(Path(value), path, ctx.command.params)
    except UsageError as e:
        raise typer.BadParameter(str(e).removeprefix("--config "), ctx, param) from None
    ctx.default_map = {**(ctx.default_map or {}), **defaults}
    return value


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return (
            ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
            if not math.isfinite(v)
            else repr(v)
        )
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return json.dumps(str(v), ensure_ascii=False)  # a TOML basic string


def to_toml(ctx: typer.Context) -> str:
    """The options this command was called with (defaults, a config file and the command
    line merged) as the TOML table :func:`load_config` reads: ``bench run --print-config >
    run.toml`` then ``bench run --config run.toml`` runs the same. Options without a value
    are left out."""
    name = ".".join(ctx.command_path.split()[1:])
    lines = [f"[{name}]"]
    for p in ctx.command.params:
        if p.name in NOT_SAVED or getattr(p, "hidden", False):
            continue
        v = ctx.params.get(str(p.name))
        if v is None or (isinstance(v, (list, tuple)) and not v and p.multiple):
            continue
        if isinstance(v, Path) or (
            isinstance(v, (list, tuple)) and any(isinstance(x, Path) for x in v)
        ):
            v = [str(x) for x in v] if isinstance(v, (list, tuple)) else str(v)
        lines.append(f"{option_key(p)} = {_toml_value(v)}")
    return "\n".join(lines) + "\n"
