"""Build-time generators of the reference pages' tables (called from markdown-exec blocks in
``docs/reference/*.md``): every table is read from the code or the schema file it
documents, never copied by hand.

* :func:`results_schema_markdown`: ``results.json``'s JSON schema
  (``posbench/saved_run/schemas/results.schema.json``, as :func:`results_schema` loads it);
* :func:`trace_columns_markdown`: :data:`posbench.scoring.schema.TRACE_COLUMNS`;
* :func:`glossary_markdown`: every term the report's glossary can print
  (:mod:`posbench.report.glossary`);
* :func:`tolerances_markdown`: every field of
  :class:`posbench.scenarios.consistency.Tolerances`, its default and its docstring text.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from collections.abc import Iterator, Mapping
from typing import Any


def cell(text: Any) -> str:
    """``text`` fit for one Markdown table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


# ------------------------------------------------------------------ results.json schema
def _def_link(ref: str) -> str:
    name = ref.rsplit("/", 1)[-1]
    return f"[`{name}`](#def-{name})"


def schema_type(node: Mapping[str, Any]) -> str:
    """A schema node's type in words: ``string``, ``number or null``, ``array of
    integer``, ``one of "a", "b"``, a link to a definition."""
    if "$ref" in node:
        return _def_link(node["$ref"])
    if "enum" in node:
        return "one of " + ", ".join(f"`{v}`" for v in node["enum"])
    if "const" in node:
        return f"`{node['const']}`"
    for key in ("oneOf", "anyOf"):
        if key in node:
            return " or ".join(schema_type(n) for n in node[key])
    kind = node.get("type")
    kinds = kind if isinstance(kind, list) else [kind] if kind else []
    words = []
    for k in kinds:
        if k == "array" and isinstance(node.get("items"), Mapping):
            words.append(f"array of {schema_type(node['items'])}")
        elif (
            k == "object"
            and isinstance(node.get("additionalProperties"), Mapping)
            and not node.get("properties")
        ):
            words.append(f"object of {schema_type(node['additionalProperties'])}")
        else:
            words.append(str(k))
    return " or ".join(words) or "any"


def _limits(node: Mapping[str, Any]) -> str:
    marks = {
        "minimum": ">=",
        "exclusiveMinimum": ">",
        "maximum": "<=",
        "exclusiveMaximum": "<",
        "pattern": "matches",
        "minItems": "items >=",
        "maxItems": "items <=",
    }
    return ", ".join(f"{m} `{node[k]}`" for k, m in marks.items() if k in node)


def schema_rows(
    node: Mapping[str, Any], path: str = "", required: bool = True
) -> Iterator[tuple[str, str, bool, str]]:
    """(key path, type, required, description) of ``node`` and of every key inside it:
    nested objects' keys as ``a.b``, any key of a map as ``a.*``, array items as ``a[]``;
    a ``$ref`` is named, not followed (its definition has its own table)."""
    if path:
        desc = node.get("description", "")
        limits = _limits(node)
        desc = f"{desc} ({limits})" if limits and desc else desc or limits
        yield path, schema_type(node), required, desc
    if "$ref" in node:
        return
    props = node.get("properties") or {}
    needed = set(node.get("required") or ())
    for key, sub in props.items():
        yield from schema_rows(sub, f"{path}.{key}" if path else key, key in needed)
    extra = node.get("additionalProperties")
    if isinstance(extra, Mapping) and props and "$ref" not in extra:
        yield from schema_rows(extra, f"{path}.*" if path else "*", False)
    elif isinstance(extra, Mapping) and not props and _has_keys(extra):
        yield from (
            r
            for r in schema_rows(extra, f"{path}.*" if path else "*", False)
            if r[0] != f"{path}.*"
        )
    items = node.get("items")
    if isinstance(items, Mapping) and _has_keys(items):
        yield from (r for r in schema_rows(items, f"{path}[]", True) if r[0] != f"{path}[]")


def _has_keys(node: Mapping[str, Any]) -> bool:
    """Whether ``node`` (no ``$ref``) has keys of its own to list."""
    if "$ref" in node:
        return False
    extra = node.get("additionalProperties")
    return (
        bool(node.get("properties"))
        or (isinstance(extra, Mapping) and _has_keys(extra))
        or (isinstance(node.get("items"), Mapping) and _has_keys(node["items"]))
    )


def schema_table(node: Mapping[str, Any]) -> str:
    """The Markdown table of :func:`schema_rows`."""
    lines = ["| key | type | required | description |", "|---|---|---|---|"]
    lines += [
        f"| `{p}` | {cell(t)} | {'yes' if r else ''} | {cell(d)} |"
        for p, t, r, d in schema_rows(node)
    ]
    return "\n".join(lines)


def results_schema_markdown(schema: Mapping[str, Any] | None = None) -> str:
    """The page body: the schema's title, id and description, the top-level keys (with
    every key nested inside them), then one table per definition (``$defs``)."""
    if schema is None:
        from posbench.saved_run.run import results_schema

        schema = results_schema()
    out = [
        f"Schema `{schema.get('$id', '')}` (JSON Schema "
        f"`{schema.get('$schema', '').rstrip('#')}`): {schema.get('title', '')}.",
        "",
        cell(schema.get("description", "")),
        "",
        "## Top-level keys",
        "",
        schema_table(schema),
        "",
        "## Definitions",
        "",
        "Shared shapes the keys above refer to (`$defs`).",
        "",
    ]
    for name, node in (schema.get("$defs") or {}).items():
        out += [f"### `{name}` {{#def-{name}}}", ""]
        if node.get("description"):
            out += [cell(node["description"]), ""]
        out += [f"Type: {schema_type(node)}.", ""]
        if _has_keys(node):
            out += [schema_table(node), ""]
    return "\n".join(out)


# ------------------------------------------------------------------------ trace columns
def trace_columns_markdown() -> str:
    """The table of :data:`posbench.scoring.schema.TRACE_COLUMNS` (the README's, too), and
    the query kinds."""
    from posbench.scoring import schema

    kinds = ", ".join(f"`{k}`" for k in schema.KINDS)
    return "\n".join(
        [
            schema.trace_columns_markdown(),
            "",
            f"Query kinds: {kinds}. Reported covariance columns (NaN in traces "
            f"written before they existed): "
            + ", ".join(f"`{c}`" for c in schema.COV_COLUMNS)
            + ".",
        ]
    )


# ----------------------------------------------------------------------------- glossary
#: a results.json with every part the glossary looks at, so every term is listed
_EVERY_PART = {
    "by_speed": {"x": 1},
    "statistics": {"method": "x"},
    "paired": {"baseline": "x"},
    "seeds": {"seeds": [0]},
    "outages": {"x": 1},
    "outage_lengths": {"x": 1},
    "limit": {"x": 1},
}


def glossary_markdown() -> str:
    """Every term :func:`posbench.report.glossary.glossary` can print (a run with every
    part: speed bins, intervals, a paired baseline, seeds, outages, the limit), in its
    reading order, as a definition list."""
    from posbench.report.glossary import glossary

    seen: set[str] = set()
    lines = []
    for term, definition in glossary(_EVERY_PART):
        if term in seen:
            continue
        seen.add(term)
        lines += [f"**{term}**", f":   {' '.join(definition.split())}", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------- data-check thresholds
_ENTRY = re.compile(r"^(?P<names>[a-z_0-9]+(?:,\s*[a-z_0-9]+)*):\s*(?P<text>.*)$")


def docstring_entries(doc: str) -> tuple[dict[str, tuple[str, str]], list[str]]:
    """From a Google-style docstring whose sections (``Grid and reference:``) list
    ``name, name2: text`` entries: field -> (section, text), and the sections in order.
    Entries naming several fields share their text."""
    entries: dict[str, tuple[str, str]] = {}
    sections: list[str] = []
    section, names, text = "", [], []

    def flush() -> None:
        for n in names:
            entries[n] = (section, " ".join(" ".join(text).split()))

    for raw in inspect.cleandoc(doc).splitlines():
        indent = len(raw) - len(raw.lstrip())
        line = raw.strip()
        if indent == 0 and line.endswith(":") and line[:-1].strip():
            flush()
            names, text = [], []
            section = line[:-1]
            sections.append(section)
            continue
        m = _ENTRY.match(line) if indent == 4 else None
        if m and section:
            flush()
            names = [n.strip() for n in m["names"].split(",")]
            text = [m["text"]]
        elif names and line:
            text.append(line)
    flush()
    return entries, sections


def _rst(text: str) -> str:
    """Sphinx roles (``:attr:`x```) and double back-quotes as Markdown code."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"`\1`", text)
    return text.replace("``", "`")


def tolerances_markdown() -> str:
    """One table per docstring section of ``Tolerances``: every field, its default value,
    and the docstring's text for it (text shared by a warn/fail pair is shown once, on
    the pair's first row). A field the docstring misses is still listed (its text: none)."""
    from posbench.scenarios.consistency import Tolerances

    entries, sections = docstring_entries(Tolerances.__doc__ or "")
    defaults = Tolerances()
    by_section: dict[str, list[str]] = {s: [] for s in sections}
    loose: list[str] = []
    for f in dataclasses.fields(Tolerances):
        sec = entries.get(f.name, ("", ""))[0]
        (by_section[sec] if sec in by_section else loose).append(f.name)
    intro = inspect.cleandoc(Tolerances.__doc__ or "").split("\n\n", 1)[0]
    out = [_rst(" ".join(intro.split())), ""]
    for sec, names in [*by_section.items(), ("Other", loose)]:
        if not names:
            continue
        out += [f"## {sec}", "", "| field | default | meaning |", "|---|---|---|"]
        first: dict[str, str] = {}
        for n in names:
            text = entries.get(n, ("", ""))[1]
            meaning = _rst(text) if first.setdefault(text, n) == n else f"see `{first[text]}`"
            out.append(f"| `{n}` | `{getattr(defaults, n)!r}` | {cell(meaning)} |")
        out.append("")
    return "\n".join(out)


# ------------------------------------------------------------------ predictor options
def predictor_options_markdown() -> str:
    """One table per built-in predictor: every option ``--set NAME.OPTION=VALUE`` takes, its
    default and what values it takes, read from the constructor's declared types
    (:mod:`posbench.predictors.option_types`), as ``bench predictors NAME`` prints them."""
    from posbench.predictors.catalogue import BUILT_IN
    from posbench.predictors.option_types import (
        declared_meanings,
        declared_types,
        shown,
        takes_text,
    )
    from posbench.predictors.registry import available, constructor_options, predictor_class

    out = []
    for name, entry in available().items():
        if entry.source != BUILT_IN:
            continue
        cls = predictor_class(name)
        defaults, _ = constructor_options(cls)
        types = declared_types(cls)
        meanings = declared_meanings(cls)
        out += [f"## `{name}`", "", cell(entry.description), ""]
        out += ["| option | default | takes | meaning |", "|---|---|---|---|"]
        for option, default in defaults.items():
            value = "(required)" if default is inspect.Parameter.empty else shown(default)
            if len(value) > 60:  # an input object's repr: its fields are listed as options
                value = type(default).__name__ + "(...)"
            takes = takes_text(types.get(option, Any))
            meaning = cell(meanings.get(option, ""))
            out.append(f"| `{option}` | `{cell(value)}` | {cell(takes)} | {meaning} |")
        out.append("")
    return "\n".join(out)
