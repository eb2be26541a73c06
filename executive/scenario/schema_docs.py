"""``docs/scenarios.md``, the scenario reference, written from the JSON Schema (``schema --markdown``).

One section per block (``scene.table``, ``risk.guard``, ``mission[].transfer``, ...), one table
row per key: its type, unit, range, default and words, all read from the schema that
:func:`executive.scenario.json_schema.scenario_schema` makes, so the page says what the loader
checks. Then what only the loader checks (:data:`executive.scenario.json_schema.LOADER_ONLY`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from executive.scenario.json_schema import LOADER_ONLY, SCHEMA_FILE

__all__ = ["schema_markdown"]

_INTRO = f"""\
# Scenario reference

<!-- Written by `executive schema --markdown` from the declarations the loader reads with
(executive/scenario/keys.py, executive/schema/scene_keys.py, each task kind's `keys`). Do not
edit: change a declaration, then `executive schema --markdown > docs/scenarios.md` and
`executive schema > scenarios/{SCHEMA_FILE}` (tests/test_scenario_schema.py checks both). -->

A scenario is a YAML file (read with `yaml.safe_load` rules only). Units are metres, kilograms,
seconds and degrees; sizes are full edge lengths. The robot's base stands at the origin facing
+x, +y is its left, +z up. Paths resolve relative to the scenario's folder.

Every key below is checked by `executive validate` (and `load()`): an unknown key is refused
with the nearest valid name, a key given twice with both lines, a number outside its range with
the key path, the value and the range. An optional key that is absent or null takes its
default. A range `[a, b]` includes both ends, `(a, b]` excludes `a`.

## The JSON Schema

`executive schema` prints the same as a JSON Schema (draft 2020-12), with the task kinds this
installation has (installed plug-ins too; `--kind package.module:Class` adds another).
The built-in kinds' schema ships beside the bundled scenarios as `{SCHEMA_FILE}`
(`scenarios/{SCHEMA_FILE}` in a checkout, package `executive.bundled` installed), and each
bundled scenario names it on its first line, so an editor with a YAML language server
(VS Code's YAML extension, for one) checks a scenario and explains each key as it is written:

```yaml
# yaml-language-server: $schema=scenario.schema.json
```

A scenario elsewhere names the file by its path, or a copy made with
`executive schema > scenario.schema.json` (with a plug-in's kinds in it).

## What only the loader checks

A document the loader accepts validates against the schema. The converse does not hold: a
JSON Schema cannot say these, which `executive validate` checks (each with the key path at
fault):
"""


def _kinds(schema: dict[str, Any]) -> list[str]:
    types = schema.get("type", [])
    return [t for t in (types if isinstance(types, list) else [types]) if t != "null"]


def _type(schema: dict[str, Any]) -> str:
    """The value's type in a few words."""
    if "enum" in schema:
        return " | ".join(f"`{v}`" for v in schema["enum"] if v is not None)
    kinds = _kinds(schema)
    if kinds == ["object"]:
        return "mapping"
    if "oneOf" in schema:
        return " or ".join(_type(option) for option in schema["oneOf"] if option.get("type") != "null")
    if kinds == ["array"]:
        items = schema.get("items")
        if isinstance(items, dict) and (_kinds(items) == ["object"] or "oneOf" in items):
            return "list of mappings"
        if isinstance(items, dict) and "enum" in items:
            return "list of " + _type(items)
        low, high = schema.get("minItems"), schema.get("maxItems")
        count = f"{low}" if low == high else f"{low} to {high}" if high is not None else ""
        return f"list of {count} numbers".replace("  ", " ")
    return " or ".join(kinds)


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _default(schema: dict[str, Any]) -> str:
    if "default" not in schema:
        return ""
    value = schema["default"]
    text = json.dumps(value, ensure_ascii=False).replace('"', "")
    return f"`{text}`"


def _row(key: str, schema: dict[str, Any], required: bool) -> str:
    words = schema.get("title") or schema.get("description", "")
    if schema.get("deprecated"):
        words = f"(deprecated) {words}"
    cells = [
        f"`{key}`" + (" (required)" if required else ""),
        _type(schema),
        schema.get("x-unit", ""),
        schema.get("x-range", ""),
        _default(schema),
        words,
    ]
    return "| " + " | ".join(_cell(c) for c in cells) + " |"


def _children(schema: dict[str, Any]) -> Iterator[tuple[str, dict[str, Any]]]:
    """The sub-blocks of a block's keys: (suffix, block) for a mapping of keys or a list of them."""
    for key, sub in schema.get("properties", {}).items():
        for option in [sub, *sub.get("oneOf", [])]:
            if _kinds(option) == ["object"] and "properties" in option:
                yield f".{key}", option
        items = sub.get("items")
        if isinstance(items, dict) and _kinds(items) == ["object"] and "properties" in items:
            yield f".{key}[]", items
        if key == "mission" and isinstance(items, dict) and "oneOf" in items:
            for kind, block in items["oneOf"][0]["properties"].items():
                yield f".{key}[].{kind}", block


def _sections(path: str, schema: dict[str, Any]) -> Iterator[str]:
    """The section of the block at ``path``, then those of its sub-blocks, depth first."""
    title = f"`{path}`" if path else "The top level"
    lines = [f"## {title}", ""]
    words = schema.get("title") or schema.get("description", "")
    if words and path:
        lines += [words.rstrip(".") + ".", ""]
    required = set(schema.get("required", []))
    properties = schema.get("properties", {})
    if properties:
        lines += ["| key | type | unit | range | default | what it is |", "|---|---|---|---|---|---|"]
        lines += [_row(key, sub, key in required) for key, sub in properties.items()]
    if schema.get("additionalProperties") is not False:
        lines += ["", "Other keys are the kind's own (its schema does not declare them)."]
    yield "\n".join(lines) + "\n"
    for suffix, sub in _children(schema):
        yield from _sections(f"{path}{suffix}".lstrip("."), sub)


def schema_markdown(schema: dict[str, Any]) -> str:
    """The scenario reference page (``docs/scenarios.md``) of ``schema``."""
    loader_only = "\n".join(f"- **{name}**: {what}." for name, what in LOADER_ONLY)
    sections = "\n".join(_sections("", schema))
    return f"{_INTRO}\n{loader_only}\n\n{sections}"
