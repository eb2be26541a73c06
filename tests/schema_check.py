"""Checking scenario documents against the scenario schema (``executive schema``), for the tests.

``watch_loader`` makes every scenario a test loads successfully also validate against the schema
(conftest.py applies it to every test): a document the loader accepts that the schema refuses is a
schema that says less than the loader reads. jsonschema is a test dependency only.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jsonschema
import pytest
import yaml

from executive.risk.orderings import ordering_names
from executive.scenario import loader
from executive.scenario.json_schema import built_in_kinds, scenario_schema
from executive.schema import yaml_nodes
from executive.schema.failure_modes import failure_modes
from executive.tasks import registry
from executive.tasks.base import TaskKind


class EditorLoader(yaml.SafeLoader):
    """YAML as an editor's language server reads it (YAML 1.2: ``5e-2`` is a number, as the loader
    reads it), keeping a duplicate key's last value as any YAML parser does before a schema looks."""


EditorLoader.add_implicit_resolver("tag:yaml.org,2002:float", yaml_nodes._FLOAT_12, list("-+0123456789."))


def parse(text: str) -> Any:
    """The document ``text`` as an editor validates it (raises yaml.YAMLError when it cannot)."""
    return yaml.load(text, Loader=EditorLoader)  # a SafeLoader: safe


_validators: dict[tuple[object, ...], jsonschema.Draft202012Validator] = {}


def validator(kinds: list[TaskKind] | None = None) -> jsonschema.Draft202012Validator:
    """A validator of the schema with ``kinds`` (None: the built-in kinds), made once per set of kinds
    and of the registries the schema names (orderings, failure modes: a test may add one)."""
    kinds = built_in_kinds() if kinds is None else kinds
    registries = (ordering_names(), tuple((m.name, m.aliases) for m in failure_modes()))
    key = (tuple(sorted((kind.name, id(type(kind))) for kind in kinds)), registries)
    if key not in _validators:
        schema = scenario_schema(sorted(kinds, key=lambda kind: kind.name))
        jsonschema.Draft202012Validator.check_schema(schema)
        _validators[key] = jsonschema.Draft202012Validator(schema)
    return _validators[key]


def problems(document: Any, kinds: list[TaskKind] | None = None) -> list[str]:
    """Why the schema refuses ``document`` (key path: message), empty if it validates."""
    found = validator(kinds).iter_errors(document)
    return [
        f"{'.'.join(str(p) for p in error.absolute_path) or '<root>'}: {error.message}" for error in found
    ]


def watch_loader(
    monkeypatch: pytest.MonkeyPatch, check: Callable[[Any, list[TaskKind]], list[str]] | None = None
) -> list[str]:
    """From now on, check every document the loader accepts against the schema; return the refusals.

    The schema has the kinds the loader has met so far (those it registered), so a plug-in kind a
    test loads is in it, and checking imports nothing a test did not. ``check``: what refuses a
    document (default :func:`problems`).
    """
    check = problems if check is None else check
    refused: list[str] = []
    read = loader._scenario

    def read_and_check(root: Any, *args: Any, **kwargs: Any) -> Any:
        scenario = read(root, *args, **kwargs)
        kinds = list(registry._registered.values())
        refused.extend(f"{root.source}: {p}" for p in check(root.value, kinds))
        return scenario

    monkeypatch.setattr(loader, "_scenario", read_and_check)
    return refused
