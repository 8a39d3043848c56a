"""``bench predictors``: every available predictor, where it comes from, and its options."""

from __future__ import annotations

import inspect
import json
from pathlib import Path
from typing import Annotated, Any

import typer

from posbench.cli.options import ConfigOpt, QuietOpt, VerboseOpt, import_from_cwd
from posbench.cli.terminal import console
from posbench.errors import UsageError


def _jsonable(value: Any) -> Any:
    """A default value as JSON: itself if JSON can hold it, else its repr."""
    try:
        json.dumps(value, allow_nan=False)
        return value
    except (TypeError, ValueError):
        return repr(value)


def predictor_info(name: str, options: bool = False, tuning: Path | None = None) -> dict[str, Any]:
    """What ``name`` is (any form ``bench run --predictors`` takes): ``name``, ``source``
    (built-in, registered, entry point, import path), ``distribution`` (for an entry
    point), ``target`` (``module:Class``), ``description`` and ``error`` (why it cannot be
    loaded, else None). With ``options``: its constructor options (``name``, ``default``,
    ``required``, ``takes``: the values it takes, in words), ``any_option`` (it takes
    ``**kwargs``) and ``by_condition``: per GPS
    condition the values a run uses where they differ from the defaults (the ``tuning``
    file's, else the package's tuning), with ``tuning`` (the file they come from). A
    built-in's class is imported only for its options; an entry point's or import path's to
    read its docstring."""
    from posbench.config import GPS_CONDITIONS
    from posbench.predictors.option_types import declared_meanings, declared_types, takes_text
    from posbench.predictors.registry import (
        PredictorError,
        base_name,
        constructor_options,
        description,
        predictor_class,
        resolve,
        tuning_entry,
    )

    entry = resolve(name)
    info: dict[str, Any] = {
        "name": name,
        "source": entry.source,
        "distribution": entry.distribution,
        "target": entry.target,
        "description": entry.description,
        "error": None,
    }
    try:
        info["description"] = description(name)
        if options:
            cls = predictor_class(name)
            accepted, any_option = constructor_options(cls)
            types = declared_types(cls)
            meanings = declared_meanings(cls)
            info["options"] = [
                {
                    "name": k,
                    "default": None if v is inspect.Parameter.empty else _jsonable(v),
                    "required": v is inspect.Parameter.empty,
                    "takes": takes_text(types.get(k, Any)),
                    "meaning": meanings.get(k),
                }
                for k, v in accepted.items()
            ]
            info["any_option"] = any_option
            info["by_condition"] = {}
            for cond in GPS_CONDITIONS:
                found = tuning_entry(base_name(name), cond, tuning)
                if found:
                    info["by_condition"][cond] = {
                        "params": found[1].get("params", {}),
                        "tuning": str(found[0]),
                    }
    except PredictorError as e:
        info["error"] = str(e)
    return info


def listing(names: list[str] | None = None, tuning: Path | None = None) -> dict[str, Any]:
    """Every available predictor (or those ``names``, with their options), and notes on
    entry points that are left out or cannot be loaded."""
    from posbench.predictors.registry import PredictorError, available, entry_point_notes

    details = bool(names)
    if details:
        import_from_cwd()
        try:
            infos = [predictor_info(n, options=True, tuning=tuning) for n in names or []]
        except PredictorError as e:
            raise UsageError(str(e)) from None
        bad = next((i for i in infos if i["error"]), None)
        if bad:
            raise UsageError(bad["error"])
    else:
        infos = [predictor_info(n) for n in available()]
    notes = list(entry_point_notes()) + [i["error"] for i in infos if i["error"]]
    return {"predictors": infos, "notes": notes}


def list_predictors(
    names: Annotated[
        list[str] | None,
        typer.Argument(
            metavar="NAME",
            help="Show these predictors with their options (--set NAME.OPTION=VALUE): registered "
            "names, entry points or module:Class. Default: list every available one.",
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    tuning: Annotated[
        Path | None,
        typer.Option(
            "--tuning",
            metavar="FILE",
            help="Show the values a run with `bench run --tuning FILE` would use.",
        ),
    ] = None,
    config: ConfigOpt = None,
    quiet: QuietOpt = False,
    verbose: VerboseOpt = False,
) -> None:
    """List the predictors `bench run --predictors` takes: built-in ones, those installed
    packages declare in the entry-point group posbench.predictors, and any module:Class of a
    Predictor subclass importable from PYTHONPATH or the current folder.

    Example: bench predictors; bench predictors kf mypkg.mymodule:MyPredictor
    """
    from rich.markup import escape

    from posbench.cli.terminal import print_table, say
    from posbench.predictors.option_types import shown

    if tuning is not None and not tuning.is_file():
        raise UsageError(f"--tuning {tuning}: no such file")
    res = listing(names, tuning)
    if as_json:
        print(json.dumps(res, indent=2))
        return
    rows = [
        [
            i["name"],
            i["source"] + (f" ({i['distribution']})" if i["distribution"] else ""),
            i["description"] if not i["error"] else "(cannot be loaded: see the note below)",
        ]
        for i in res["predictors"]
    ]
    print_table(console, ["name", "from", "description"], rows, left_columns=3)
    for i in res["predictors"]:
        if "options" in i:
            more = " and any other (**kwargs)" if i["any_option"] else ""
            how = f"--set {escape(i['name'])}.OPTION=VALUE"
            console.print(
                f"{escape(i['name'])} ({escape(i['target'])}) options"
                f"{':' if i['options'] else ': none'}{more} ({how})",
                highlight=False,
                soft_wrap=True,
            )
            option_rows = [
                [o["name"], "(required)" if o["required"] else shown(o["default"]), o["takes"]]
                for o in i["options"]
            ]
            header = ["option", "default", "takes"]
            if any(o["meaning"] for o in i["options"]):
                header.append("meaning")
                for row, o in zip(option_rows, i["options"], strict=True):
                    row.append(o["meaning"] or "")
            if option_rows:
                print_table(console, header, option_rows, left_columns=len(header))
            for cond, tuned in i.get("by_condition", {}).items():
                values = ", ".join(f"{k}={v!r}" for k, v in tuned["params"].items())
                console.print(
                    f"  under GPS condition {cond}: {escape(values or 'the defaults')} "
                    f"(tuning {escape(tuned['tuning'])})",
                    highlight=False,
                    soft_wrap=True,
                )
    for note in res["notes"]:
        say(f"note: {note}")
