"""The scenario format as a JSON Schema (draft 2020-12), made from the declarations the loader reads with.

``scenario_schema()`` describes every key with its unit, range, default and words: the top level
and its blocks (:mod:`executive.scenario.keys`), the scene (:mod:`executive.schema.scene_keys`) and
each task kind's block (:meth:`executive.tasks.base.TaskKind.schema`, so an installed plug-in's
kind is in it too). ``executive schema`` prints it; the built-in kinds' schema ships as
``scenario.schema.json`` beside the bundled scenarios (package ``executive.bundled``), whose first
line names it for editors (``# yaml-language-server: $schema=scenario.schema.json``), and
``docs/scenarios.md`` is written from it (:mod:`executive.scenario.schema_docs`).

A document the loader accepts validates against the schema. The converse does not hold: the
loader also checks what a JSON Schema cannot say (:data:`LOADER_ONLY`); ``executive validate``
is the whole check. An optional key given as null counts as absent (its default), as in the loader.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Sequence
from typing import Any

from executive.errors import ExecutiveError
from executive.scenario.keys import SCENARIO
from executive.tasks.base import TaskKind
from executive.tasks.registry import BUILT_IN, available, get

__all__ = [
    "DIALECT",
    "LOADER_ONLY",
    "SCHEMA_FILE",
    "available_kinds",
    "built_in_kinds",
    "scenario_schema",
    "schema_text",
]

DIALECT = "https://json-schema.org/draft/2020-12/schema"
#: The shipped schema's file name, beside the bundled scenarios.
SCHEMA_FILE = "scenario.schema.json"
#: A task's ``kind:`` given as a dotted path to a TaskKind class.
DOTTED_KIND = r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*:[A-Za-z_][A-Za-z0-9_]*$"

#: What the loader checks and a JSON Schema cannot express: (name, what and why).
LOADER_ONLY: tuple[tuple[str, str], ...] = (
    (
        "duplicate keys",
        "a key given twice is refused; a YAML parser keeps the last one before any schema sees the document",
    ),
    (
        "whole numbers",
        "an integer (a count, a seed) written with a decimal point, `3.0`, is refused; JSON Schema "
        "counts 3.0 as an integer",
    ),
    (
        "finite numbers",
        "NaN (a validator's comparisons with it are all false) and infinity where a key has no upper "
        "bound (`risk.threshold`) are refused",
    ),
    (
        "scene geometry",
        "no object overlaps an obstacle or another object, every object rests on the table or on "
        "something on it (not floating, not inside the table, not on the floor), a target is over the "
        "table and clear (exact signed distances with coal)",
    ),
    (
        "reach",
        "the table, every object and every target within the robot's reach, measured in its MJCF model",
    ),
    (
        "names",
        "a task's `object` is one of the scene's objects, a press's `target` one of its obstacles, "
        "names are unique, a `risk.severity.body_parts` name is a label or a body of the robot's model",
    ),
    (
        "objects in hand",
        "what a task leaves in a hand and the next task needs there (a place follows the pick of its "
        "object; nothing else comes between)",
    ),
    (
        "ranges across keys",
        "`risk.threshold` below the largest value the ordering can take (it depends on the severities, "
        "weights and obstacles), `position_scale < position_max` and `angle_scale < angle_max`, "
        "`position_weight` and `angle_weight` not both 0, `rollouts.min_count <= count`, "
        "`perception_scale` low <= high, a press's `tolerance` <= its `force` and its `point` on the "
        "target's surface, a `yaw_symmetry` the object's footprint has",
    ),
    ("files", "a robot's MJCF and profile files exist and are an MJCF model and a profile"),
    (
        "allowed modules",
        "whether a `kind: package.module:Class` may import its module is the run's permission "
        "(`--allow-module`), not the file's",
    ),
)


def built_in_kinds() -> list[TaskKind]:
    """The kinds that ship with the package, by name."""
    return [get(name) for name in sorted(BUILT_IN)]


def available_kinds() -> tuple[list[TaskKind], list[str]]:
    """Every kind this installation finds (built in, registered, installed plug-ins), and the
    problems of those that fail to load (one line each)."""
    kinds, problems = [], []
    for name in available():
        try:
            kinds.append(get(name))
        except ExecutiveError as error:
            problems.append(str(error))
    return kinds, problems


def _kind_form(kinds: Sequence[TaskKind]) -> dict[str, Any]:
    """``{kind: NAME-OR-package.module:Class, ...the kind's keys}``: a known name's keys are its kind's."""
    names = [kind.name for kind in kinds]
    conditions = []
    for kind in kinds:
        block = copy.deepcopy(kind.schema())
        block.pop("title", None)
        block.pop("description", None)
        block["properties"] = {"kind": {"const": kind.name}, **block.get("properties", {})}
        conditions.append({"if": {"properties": {"kind": {"const": kind.name}}}, "then": block})
    kind_key: dict[str, Any] = {
        "title": "The task's kind",
        "description": "The task's kind: a kind's name, or package.module:Class of a plug-in kind "
        "(imported only when the run allows its module).",
        "type": "string",
        "anyOf": [{"enum": names}, {"pattern": DOTTED_KIND}],
    }
    form: dict[str, Any] = {"type": "object", "required": ["kind"], "properties": {"kind": kind_key}}
    if conditions:
        form["allOf"] = conditions
    return form


def _task(kinds: Sequence[TaskKind]) -> dict[str, Any]:
    """One task of the mission: ``{KIND: {...}}`` (one key, a kind's name) or the ``kind:`` form."""
    by_key = {
        "type": "object",
        "properties": {kind.name: kind.schema() for kind in kinds},
        "additionalProperties": False,
        "minProperties": 1,
        "maxProperties": 1,
    }
    return {"oneOf": [by_key, _kind_form(kinds)]}


def scenario_schema(kinds: Sequence[TaskKind] | None = None) -> dict[str, Any]:
    """The JSON Schema of a scenario whose tasks are of ``kinds`` (None: the built-in kinds).

    Args:
        kinds: the task kinds a mission may name (:func:`available_kinds` for every one found).

    Returns:
        The schema as a JSON-able dict (``$schema`` the 2020-12 dialect).
    """
    document = SCENARIO.json_schema()
    mission = document["properties"]["mission"]
    mission["items"] = _task(built_in_kinds() if kinds is None else kinds)
    return {
        "$schema": DIALECT,
        "$comment": "Generated by `executive schema` from the declarations the loader reads with; "
        "do not edit (docs/scenarios.md says how it is made and what only the loader checks).",
        **document,
    }


def schema_text(schema: dict[str, Any]) -> str:
    """The schema as the shipped file holds it: JSON, indented 2, a newline at the end."""
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"
