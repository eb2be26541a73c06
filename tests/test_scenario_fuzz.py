"""Fuzzing the loader: whatever the input, it returns a Scenario or raises ScenarioError, nothing else."""

from __future__ import annotations

import copy
from typing import Any

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from executive import scenario
from executive.errors import ScenarioError
from executive.schema import catalog as registry
from executive.schema.types import Scenario


def _valid() -> dict[str, Any]:
    return yaml.safe_load(registry.scenario_path("book_transfer").read_text())


VOCABULARY = [
    "name",
    "robot",
    "scene",
    "table",
    "objects",
    "obstacles",
    "mission",
    "transfer",
    "object",
    "to",
    "alternatives",
    "left",
    "right",
    "left_to_right",
    "size",
    "position",
    "shape",
    "box",
    "cylinder",
    "sphere",
    "mass",
    "humanoid",
    "unitree_g1",
    "book",
    "book_stack",
    "risk",
    "weights",
    "fall",
    "drop",
    "grasp",
    "approval",
    "mode",
    "deny",
    "trials",
    "count",
    "seed",
    "",
    "../x.xml",
    "nan",
]
TOKENS = [
    *(f"{w}: " for w in VOCABULARY if w),
    "\n",
    "\n  ",
    "\n    ",
    "- ",
    "[",
    "]",
    "{",
    "}",
    ", ",
    ": ",
    "&a ",
    "*a",
    "&b ",
    "*b",
    "!!python/object/apply:os.system ",
    "!!binary ",
    "!!str ",
    "!!int ",
    ".nan",
    ".inf",
    "-.inf",
    "~",
    "null",
    "true",
    "no",
    "0",
    "-1",
    "1e3",
    "0.5",
    "1e999",
    "'",
    '"',
    "#",
    "---",
    "...",
    "|",
    ">",
    "<<: ",
    "? ",
    "\t",
    "%YAML 1.1\n",
    "2020-01-01",
]

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(VOCABULARY),
    st.text(max_size=12),
)
values = st.recursive(
    scalars,
    lambda children: st.one_of(
        st.lists(children, max_size=4),
        st.dictionaries(st.one_of(st.sampled_from(VOCABULARY), st.text(max_size=6)), children, max_size=4),
    ),
    max_leaves=12,
)


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Every (container path, key) location in the document."""
    found = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, child in items:
        found.append((*prefix, key))
        found.extend(_paths(child, (*prefix, key)))
    return found


def _container(data: Any, path: tuple[Any, ...]) -> Any:
    for key in path[:-1]:
        data = data[key]
    return data


@st.composite
def mutated_documents(draw: st.DrawFn) -> dict[str, Any]:
    data = _valid()
    for _ in range(draw(st.integers(min_value=1, max_value=3))):
        paths = _paths(data)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = _container(data, path)
        key = path[-1]
        action = draw(st.sampled_from(["replace", "delete", "add-key", "duplicate", "swap-type"]))
        if action == "replace":
            parent[key] = draw(values)
        elif action == "delete":
            del parent[key]
        elif action == "add-key" and isinstance(parent[key], dict):
            parent[key][draw(st.sampled_from(VOCABULARY))] = draw(values)
        elif action == "duplicate" and isinstance(parent, list):
            parent.append(copy.deepcopy(parent[key]))
        else:
            old = parent[key]
            parent[key] = [old] if not isinstance(old, list) else (old[0] if old else {})
    return data


def _check(load: Any, *args: Any, **kwargs: Any) -> None:
    try:
        result = load(*args, **kwargs)
    except ScenarioError as error:
        assert str(error)
    else:
        assert isinstance(result, Scenario)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=40).map("".join) | st.text(max_size=200))
def test_random_yaml_text_never_raises_anything_but_scenario_error(document: str) -> None:
    _check(scenario.loads, document)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated_documents())
def test_mutated_documents_never_raise_anything_but_scenario_error(data: dict[str, Any]) -> None:
    _check(scenario.from_dict, copy.deepcopy(data))
    _check(scenario.loads, yaml.safe_dump(data, sort_keys=False))


@settings(max_examples=100, deadline=None)
@given(values)
def test_arbitrary_values_as_a_document_never_raise_anything_but_scenario_error(data: Any) -> None:
    _check(scenario.from_dict, data)
    _check(scenario.loads, yaml.safe_dump(data))
