"""Malformed scenarios: each is a small mutation of the bundled one and must fail with a ScenarioError
naming the key path and what was expected."""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from scenario_docs import walk  # tests/ is on sys.path (pytest's default prepend import mode)

from executive import scenario
from executive.errors import ScenarioError
from executive.schema import catalog as registry

Doc = dict[str, Any]


def put(path: str, value: object) -> Callable[[Doc], Doc]:
    def mutate(data: Doc) -> Doc:
        node, key = walk(data, path)
        node[key] = value
        return data

    return mutate


def drop(path: str) -> Callable[[Doc], Doc]:
    def mutate(data: Doc) -> Doc:
        node, key = walk(data, path)
        del node[key]
        return data

    return mutate


def rename(path: str, new: str) -> Callable[[Doc], Doc]:
    def mutate(data: Doc) -> Doc:
        node, key = walk(data, path)
        node[new] = node.pop(key)
        return data

    return mutate


def text(replace: str, by: str) -> Callable[[str], str]:
    """A mutation of the bundled file's text (keeps YAML spellings such as ``.nan``)."""

    def mutate(source: str) -> str:
        if replace not in source:
            raise LookupError(f"{replace!r} is not in the bundled scenario")
        return source.replace(replace, by, 1)

    return mutate


def whole(document: str) -> Callable[[str], str]:
    return lambda _source: document


BOMB = "\n".join(
    ['a: &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    + [f"{c}: &{c} [{', '.join([f'*{p}'] * 9)}]" for p, c in zip("abcdefgh", "bcdefghi", strict=True)]
)


@dataclass(frozen=True)
class Case:
    id: str
    mutate: Callable[[Doc], Doc] | Callable[[str], str]
    key_path: str  # substring of ScenarioError.key_path
    message: str  # substring of the message
    on_text: bool = False


CASES = [
    # wrong types
    Case("name-not-a-string", put("name", 42), "name", "expected a string, got int 42"),
    Case(
        "number-is-a-string", put("risk.d_safety", "abc"), "risk.d_safety", "expected a number, got str 'abc'"
    ),
    Case(
        "number-is-a-bool", put("risk.threshold", True), "risk.threshold", "expected a number, got bool True"
    ),
    Case("scene-is-a-list", put("scene", [1, 2]), "scene", "expected a mapping, got a list of 2 items"),
    Case(
        "size-is-a-number", put("scene.objects[0].size", 0.1), "scene.objects[0].size", "expected a list of 3"
    ),
    Case(
        "objects-is-a-mapping",
        put("scene.objects", {"book": 1}),
        "scene.objects",
        "expected a non-empty list",
    ),
    # missing required keys
    Case("missing-scene", drop("scene"), "scene", "missing required key 'scene'"),
    Case("missing-mission", drop("mission"), "mission", "missing required key 'mission'"),
    Case(
        "missing-object-mass", drop("scene.objects[0].mass"), "scene.objects[0].mass", "missing required key"
    ),
    Case("missing-table-height", drop("scene.table.height"), "scene.table.height", "missing required key"),
    # negative and zero sizes, ranges
    Case(
        "negative-table-size",
        put("scene.table.size", [0.6, -1.3, 0.04]),
        "scene.table.size[1]",
        "expected a number > 0 and <= 10, got float -1.3",
    ),
    Case(
        "zero-object-size",
        put("scene.objects[0].size", [0.16, 0.0, 0.045]),
        "scene.objects[0].size[1]",
        "expected a number >= 0.001 and <= 2, got float 0.0",
    ),
    Case(
        "zero-mass",
        put("scene.objects[0].mass", 0),
        "scene.objects[0].mass",
        "expected a number >= 0.001 and <= 50, got int 0",
    ),
    Case("negative-uncertainty", put("uncertainty.com", -0.01), "uncertainty.com", ">= 0"),
    Case("zero-timeout", put("approval.timeout_s", 0), "approval.timeout_s", "> 0"),
    Case(
        "rgba-out-of-range",
        put("scene.objects[0].rgba", [1, 0.5, 0, 1.5]),
        "scene.objects[0].rgba[3]",
        "<= 1",
    ),
    Case(
        "grasp-scale-above-max",
        put("risk.grasp", {"position_scale": 0.06}),
        "risk.grasp.position_scale",
        "position_scale < position_max",
    ),
    Case("negative-seed", put("trials.seed", -1), "trials.seed", "expected an integer >= 0"),
    Case("zero-trials", put("trials.count", 0), "trials.count", "expected an integer >= 1"),
    Case(
        "negative-scene-variation",
        put("trials.scene_variation", {"object_position": -0.02}),
        "trials.scene_variation.object_position",
        ">= 0",
    ),
    Case(
        "reversed-perception-scale",
        put("trials.scene_variation", {"perception_scale": [2.0, 0.5]}),
        "trials.scene_variation.perception_scale",
        "reversed",
    ),
    Case(
        "zero-perception-scale",
        put("trials.scene_variation", {"perception_scale": [0.0, 2.0]}),
        "trials.scene_variation.perception_scale",
        "> 0",
    ),
    # NaN and inf as YAML spells them
    Case(
        "nan-height",
        text("height: 0.80", "height: .nan"),
        "scene.table.height",
        "expected a finite number, got float nan",
        on_text=True,
    ),
    Case("inf-uncertainty", text("com: 0.01", "com: .inf"), "uncertainty.com", "finite", on_text=True),
    Case(
        "minus-inf-position",
        text("position: [0.52, 0.26]", "position: [-.inf, 0.26]"),
        "scene.objects[0].position[0]",
        "finite",
        on_text=True,
    ),
    # unknown keys, with the nearest valid name
    Case(
        "unknown-top-level-key",
        rename("uncertainty", "uncertainity"),
        "uncertainity",
        "unknown key 'uncertainity'; did you mean 'uncertainty'? valid keys: name, robot",
    ),
    Case(
        "unknown-object-key",
        rename("scene.objects[0].friction", "frction"),
        "scene.objects[0].frction",
        "did you mean 'friction'?",
    ),
    Case(
        "yaw-symmetry-not-whole",
        put("scene.objects[0].yaw_symmetry", 2.5),
        "scene.objects[0].yaw_symmetry",
        "a whole number >= 1",
    ),
    Case(
        "yaw-symmetry-of-oblong-box",
        put("scene.objects[0].yaw_symmetry", 4),
        "scene.objects[0].yaw_symmetry",
        "footprint has yaw symmetry 1 or 2, not 4",
    ),
    Case(
        "yaw-symmetry-on-obstacle",
        put("scene.obstacles[0].yaw_symmetry", 2),
        "scene.obstacles[0].yaw_symmetry",
        "unknown key 'yaw_symmetry'",
    ),
    Case(
        "unknown-risk-key",
        rename("risk.collision.exponent", "exponet"),
        "risk.collision.exponet",
        "did you mean 'exponent'?",
    ),
    Case("unknown-weight", put("risk.weights", {"dorp": 1.0}), "risk.weights.dorp", "did you mean 'drop'?"),
    Case(
        "unknown-key-no-suggestion",
        put("trials.zzz", 1),
        "trials.zzz",
        "unknown key 'zzz'; valid keys: count",
    ),
    # robot
    Case(
        "unknown-robot",
        put("robot", "humanoyd"),
        "robot",
        "unknown robot 'humanoyd'; did you mean 'humanoid'?",
    ),
    Case(
        "unknown-robot-lists-bundled",
        put("robot", "atlas"),
        "robot",
        "unknown robot 'atlas'; bundled robots: humanoid, unitree_g1",
    ),
    Case(
        "missing-mjcf-file",
        put("robot", {"mjcf": "no/such/robot.xml", "profile": "humanoid"}),
        "robot.mjcf",
        "MJCF file not found: 'no/such/robot.xml'",
    ),
    Case("robot-without-mjcf", put("robot", "unitree_g1"), "robot", "ships no MJCF model"),
    Case(
        "robot-is-a-number",
        put("robot", 7),
        "robot",
        "expected a bundled robot's name (humanoid, unitree_g1)",
    ),
    # geometry
    Case(
        "object-inside-table",
        put("scene.objects[0].position", [0.48, 0.26, 0.79]),
        "scene.objects[0].position",
        "inside the table",
    ),
    Case(
        "obstacle-below-floor",
        put("scene.obstacles[0].position", [2.0, 0.0, 0.1]),
        "scene.obstacles[0].position",
        "below the floor",
    ),
    Case(
        "duplicate-name",
        put("scene.obstacles[0].name", "book"),
        "scene.obstacles[0].name",
        "duplicate name 'book' (already used at scene.objects[0].name)",
    ),
    Case(
        "obstacle-with-mass",
        put("scene.obstacles[0].mass", 1.0),
        "scene.obstacles[0].mass",
        "obstacles are static",
    ),
    Case(
        "bad-shape",
        put("scene.objects[0].shape", "cube"),
        "scene.objects[0].shape",
        "expected one of 'box', 'cylinder', 'sphere', got str 'cube'",
    ),
    # wrong list lengths
    Case(
        "table-position-length",
        put("scene.table.position", [0.62]),
        "scene.table.position",
        "expected a list of 2 numbers, got a list of 1 item",
    ),
    Case(
        "sphere-with-box-size",
        put("scene.objects[0].shape", "sphere"),
        "scene.objects[0].size",
        "expected a list of 1 number, got a list of 3 items",
    ),
    Case(
        "orientation-length",
        put("scene.objects[0].orientation", [0, 0]),
        "scene.objects[0].orientation",
        "expected a list of 3 numbers",
    ),
    # enums
    Case(
        "bad-approval-mode",
        put("approval.mode", "ask"),
        "approval.mode",
        "expected one of 'prompt', 'auto', 'deny', got str 'ask'",
    ),
    Case("bad-ordering", put("risk.ordering", "sum"), "risk.ordering", "'weighted_sum'"),
    # mission
    Case("empty-mission", put("mission", []), "mission", "expected a list of at least 1 item"),
    Case(
        "unknown-task-kind",
        rename("mission[0].transfer", "transfre"),
        "mission[0].transfre",
        "unknown task kind 'transfre'; did you mean 'transfer'? kinds: ",
    ),
    Case(
        "unknown-task-object",
        put("mission[0].transfer.object", "bok"),
        "mission[0].transfer.object",
        "unknown object 'bok'; the scene's objects are: book",
    ),
    Case(
        "task-object-is-an-obstacle",
        put("mission[0].transfer.object", "book_stack"),
        "mission[0].transfer.object",
        "an obstacle",
    ),
    Case(
        "unknown-alternative",
        put("mission[0].transfer.alternatives", ["left", "both"]),
        "mission[0].transfer.alternatives[1]",
        "expected one of 'left', 'right', 'left_to_right', 'right_to_left'",
    ),
    Case(
        "duplicate-alternative",
        put("mission[0].transfer.alternatives", ["left", "left"]),
        "mission[0].transfer.alternatives[1]",
        "duplicate alternative 'left'",
    ),
    Case(
        "target-off-the-table",
        put("mission[0].transfer.to", [3.0, 0.0]),
        "mission[0].transfer.to",
        "not over the table",
    ),
    Case("task-with-two-kinds", put("mission[0].place", {}), "mission[0]", "exactly one key"),
    # bool where an int is expected
    Case("bool-trial-count", put("trials.count", True), "trials.count", "expected an integer, got bool True"),
    Case("float-trial-count", put("trials.count", 2.5), "trials.count", "expected an integer, got float 2.5"),
    # documents that are not a scenario at all
    Case("alias-bomb", whole(BOMB), "", "refusing an alias bomb", on_text=True),
    Case("recursive-alias", whole("name: &a [*a]\n"), "", "recursive alias", on_text=True),
    Case(
        "python-object-tag",
        whole("name: !!python/object/apply:os.system ['echo pwned']\n"),
        "",
        "could not determine a constructor for the tag",
        on_text=True,
    ),
    Case(
        "non-mapping-document",
        whole("- name\n- robot\n"),
        "",
        "expected a mapping at the top level, got a list",
        on_text=True,
    ),
    Case("scalar-document", whole("just text\n"), "", "got str 'just text'", on_text=True),
    Case("empty-file", whole(""), "", "the document is empty", on_text=True),
    Case("comment-only-file", whole("# nothing here\n"), "", "the document is empty", on_text=True),
    Case(
        "syntax-error",
        text("size: [0.60, 1.30, 0.04]", "size: [0.60, 1.30, 0.04"),
        "",
        "invalid YAML at line",
        on_text=True,
    ),
    Case("two-documents", whole("name: a\n---\nname: b\n"), "", "expected a single document", on_text=True),
    Case("non-string-key", whole("1: a\n"), "", "expected string keys, got key int 1", on_text=True),
]


def _load(case: Case, tmp_path: Path) -> scenario.Scenario:
    source = registry.scenario_path("book_transfer").read_text()
    if case.on_text:
        document = case.mutate(source)  # type: ignore[arg-type]
    else:
        data = case.mutate(copy.deepcopy(yaml.safe_load(source)))  # type: ignore[arg-type]
        document = yaml.safe_dump(data, sort_keys=False)
    path = tmp_path / "case.yaml"
    path.write_text(document)
    return scenario.load(path)


def test_there_are_at_least_25_distinct_cases() -> None:
    assert len({case.id for case in CASES}) == len(CASES) >= 25


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_malformed_scenario_is_rejected_with_key_path_and_reason(case: Case, tmp_path: Path) -> None:
    with pytest.raises(ScenarioError) as info:
        _load(case, tmp_path)
    error = info.value
    assert case.key_path in error.key_path, str(error)
    assert case.message in error.problem, str(error)
    assert str(error).startswith(f"{tmp_path / 'case.yaml'}: "), str(error)
    if case.key_path:
        assert f": {error.key_path}: " in str(error)


def test_alias_bomb_is_rejected_quickly() -> None:
    start = time.process_time()  # this process's CPU time: another process's load does not count
    with pytest.raises(ScenarioError, match="alias bomb"):
        scenario.loads(BOMB)
    assert time.process_time() - start < 1.0


def test_alias_within_limits_is_accepted() -> None:
    data = yaml.safe_load(registry.scenario_path("book_transfer").read_text())
    document = yaml.safe_dump(data, sort_keys=False).replace(
        "size:\n    - 0.6\n    - 1.3\n    - 0.04", "size: &table_size [0.6, 1.3, 0.04]"
    )
    document += "\n" + "x_unused: *table_size\n"
    with pytest.raises(ScenarioError, match="unknown key 'x_unused'"):
        scenario.loads(document)


def test_oversized_file_is_rejected(tmp_path: Path) -> None:
    path = tmp_path / "big.yaml"
    path.write_text("# " + "x" * (1 << 20) + "\nname: big\n")
    with pytest.raises(ScenarioError, match="too large"):
        scenario.load(path)
    with pytest.raises(ScenarioError, match="too large"):
        scenario.loads(path.read_text())


def test_unknown_bundled_scenario_lists_the_bundled_ones() -> None:
    with pytest.raises(ScenarioError, match="book_transfer"):
        scenario.load("no_such_scenario")


def test_error_message_format() -> None:
    data = yaml.safe_load(registry.scenario_path("book_transfer").read_text())
    data["scene"]["objects"][0]["size"][2] = "thick"
    with pytest.raises(ScenarioError) as info:
        scenario.from_dict(data, source="mine.yaml")
    assert str(info.value) == "mine.yaml: scene.objects[0].size[2]: expected a number, got str 'thick'"
