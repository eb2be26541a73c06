"""Scenarios that used to be accepted although wrong (issue 15), through ``executive validate``.

Each case mutates the bundled ``book_transfer`` document in one way (its YAML text, or the parsed
document written back) and runs ``executive validate`` in process: exit 2, one message naming the
file and the key path, no traceback. The kinds: duplicate keys, absurd and out-of-range numbers
(1e308, 1e300, nan, inf and just past each range), settings that switch a safety check off,
impossible scenes, body-part typos, misleading messages (tiny sizes, non-model MJCF files) and
profile paths that used to crash (a symlink loop, a NUL byte, ``~nosuchuser``), missions whose
tasks the objects in hand do not allow (a place of an object nothing picked), and hostile task
kinds (``kind: this:Zen``, ``os:system``, ``subprocess:Popen``: refused before anything is
imported, unless the run allows the module). The last tests check that what people write and
mean (``5e-2``, extreme but valid numbers) still loads.
"""

from __future__ import annotations

import copy
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
import yaml
from scenario_docs import walk  # tests/ is on sys.path (pytest's default prepend import mode)

from executive import scenario as scenarios
from executive.cli.main import main
from executive.errors import ScenarioError
from executive.schema import catalog as registry
from executive.tasks.registry import ALLOW_ENV

Doc = dict[str, Any]
SOURCE = registry.scenario_path("book_transfer").read_text()
HUMANOID_MJCF = registry.robot_profile_path("humanoid").parent / "humanoid.xml"  # type: ignore[union-attr]


@dataclass(frozen=True)
class Case:
    id: str
    mutate: Callable[[Doc, Path], Doc] | Callable[[str, Path], str]
    key_path: str  # must appear in the message as "<file>: <key_path>: "
    message: str  # a substring of the message
    on_text: bool = False


def put(*pairs: tuple[str, object]) -> Callable[[Doc, Path], Doc]:
    """Set each dotted key path (with [i] indices) to its value."""

    def mutate(data: Doc, _tmp: Path) -> Doc:
        for path, value in pairs:
            node, key = walk(data, path)
            if isinstance(node, list) and key == len(node):
                node.append(value)
            else:
                node[key] = value
        return data

    return mutate


def text(replace: str, by: str) -> Callable[[str, Path], str]:
    """Replace the first occurrence of ``replace`` in the bundled file's text."""

    def mutate(source: str, _tmp: Path) -> str:
        assert replace in source, f"{replace!r} is not in the bundled scenario"
        return source.replace(replace, by, 1)

    return mutate


def robot(make: Callable[[Path], object]) -> Callable[[Doc, Path], Doc]:
    """Replace ``robot`` with what ``make`` builds from the test's tmp folder."""

    def mutate(data: Doc, tmp: Path) -> Doc:
        data["robot"] = make(tmp)
        return data

    return mutate


def _file(tmp: Path, name: str, content: str) -> str:
    path = tmp / name
    path.write_text(content)
    return str(path)


def _loop(tmp: Path) -> str:
    (tmp / "loop_a").symlink_to(tmp / "loop_b")
    (tmp / "loop_b").symlink_to(tmp / "loop_a")
    return str(tmp / "loop_a")


def _with_profile(path: Callable[[Path], str]) -> Callable[[Path], object]:
    return lambda tmp: {"mjcf": str(HUMANOID_MJCF), "profile": path(tmp)}


def _with_mjcf(path: Callable[[Path], str]) -> Callable[[Path], object]:
    return lambda tmp: {"mjcf": path(tmp), "profile": "humanoid"}


# --- duplicate keys: YAML keeps the last one silently
DUPLICATES = [
    Case(
        "dup-threshold",
        text("  threshold: 0.3\n", "  threshold: 0.3\n  threshold: 99\n"),
        "risk.threshold",
        "",
    ),
    Case("dup-name", text("name: book_transfer\n", "name: book_transfer\nname: other\n"), "name", ""),
    Case(
        "dup-table-height",
        text("    height: 0.80", "    height: 0.80\n    height: 0.1"),
        "scene.table.height",
        "",
    ),
    Case("dup-mass", text("      mass: 0.6", "      mass: 0.6\n      mass: 40"), "scene.objects[0].mass", ""),
    Case("dup-com", text("  com: 0.01", "  com: 0.01\n  com: 0.0"), "uncertainty.com", ""),
    Case(
        "dup-com-margin",
        text("    min_com_margin: 0.02", "    min_com_margin: 0.02\n    min_com_margin: 0.2"),
        "risk.guard.min_com_margin",
        "",
    ),
    Case(
        "dup-body-part",
        text("{head: 3.0, hand: 1.5,", "{head: 3.0, head: 0.1, hand: 1.5,"),
        "risk.severity.body_parts.head",
        "",
    ),
    Case(
        "dup-object", text("      object: book", "      object: book\n      object: book"), "mission[0]", ""
    ),
    Case("dup-block", text("approval:\n", "approval: {mode: auto}\napproval:\n"), "approval", ""),
    Case(
        "dup-ordering",
        text("  ordering: expected_loss", "  ordering: probability\n  ordering: x"),
        "risk.ordering",
        "",
    ),
]
DUPLICATES = [Case(c.id, c.mutate, c.key_path, "duplicate key", on_text=True) for c in DUPLICATES]

# --- numbers: absurd magnitudes, nan, inf and values just past the range
NUMBER_KEYS: list[tuple[str, float]] = [
    # key path, a value just outside its range
    ("scene.objects[0].mass", 51.0),
    ("scene.objects[0].friction", 6.0),
    ("scene.objects[0].size[0]", 2.5),
    ("scene.objects[0].size[2]", 0.0005),
    ("scene.objects[0].position[0]", 11.0),
    ("scene.objects[0].position[1]", -11.0),
    ("scene.objects[0].orientation", 400.0),
    ("scene.obstacles[0].size[1]", 6.0),
    ("scene.obstacles[0].position[0]", -12.0),
    ("scene.obstacles[0].severity", 1001.0),
    ("scene.obstacles[0].clearance", 1.5),
    ("scene.table.height", 3.5),
    ("scene.table.size[0]", 10.5),
    ("scene.table.size[2]", 0.6),
    ("scene.table.position[0]", 10.5),
    ("uncertainty.object_position", 0.25),
    ("uncertainty.object_yaw", 190.0),
    ("uncertainty.obstacle_position", 0.3),
    ("uncertainty.com", 0.15),
    ("uncertainty.object_mass", 1.5),
    ("uncertainty.friction", 2.0),
    ("mission[0].transfer.to[0]", 10.5),
    ("mission[0].transfer.to[1]", -10.5),
    ("risk.d_safety", 1.5),
    ("risk.collision.exponent", 11.0),
    ("risk.collision.peak_weight", 101.0),
    ("risk.fall.sigmas", 11.0),
    ("risk.weights.fall", 101.0),
    ("risk.severity.fall", 1001.0),
    ("risk.severity.body_parts.head", 1001.0),
    ("risk.guard.min_distance", 0.6),
    ("risk.guard.lookahead_s", 6.0),
    ("approval.timeout_s", 90000.0),
    ("trials.scene_variation.object_position", 0.3),
]
NUMBERS = []
for i, (key, past) in enumerate(NUMBER_KEYS):
    absurd = 1e308 if i % 2 == 0 else -1e300
    NUMBERS.append(Case(f"absurd:{key}", put((key, absurd)), key, "expected a number"))
    NUMBERS.append(Case(f"past-range:{key}", put((key, past)), key, f"got float {past!r}"))
NUMBERS += [
    Case("nan-mass", put(("scene.objects[0].mass", math.nan)), "scene.objects[0].mass", "finite"),
    Case("inf-friction", put(("scene.objects[0].friction", math.inf)), "scene.objects[0].friction", "finite"),
    Case("nan-yaw-sigma", put(("uncertainty.object_yaw", math.nan)), "uncertainty.object_yaw", "finite"),
    Case(
        "inf-target-z",
        put(("mission[0].transfer.to", [0.52, -0.26, math.inf])),
        "mission[0].transfer.to[2]",
        "finite",
    ),
    Case(
        "huge-target-z",
        put(("mission[0].transfer.to", [0.52, -0.26, 1e300])),
        "mission[0].transfer.to[2]",
        "<= 5",
    ),
    Case("nan-to-yaw", put(("mission[0].transfer.to_yaw", math.nan)), "mission[0].transfer.to_yaw", "finite"),
    Case("huge-to-yaw", put(("mission[0].transfer.to_yaw", 1e308)), "mission[0].transfer.to_yaw", "<= 360"),
    Case("yaml-1e400", text("mass: 0.6", "mass: 1e400"), "scene.objects[0].mass", "finite", on_text=True),
    Case("huge-rollouts", put(("risk.rollouts.count", 10**9)), "risk.rollouts.count", "<= 1000"),
    Case("huge-jobs", put(("risk.rollouts.jobs", 10**6)), "risk.rollouts.jobs", "<= 256"),
    Case("huge-budget", put(("risk.rollouts.budget_s", 1e300)), "risk.rollouts.budget_s", "<= 3600"),
    Case("huge-trials", put(("trials.count", 10**9)), "trials.count", "<= 100000"),
    Case("huge-seed", put(("trials.seed", 2**70)), "trials.seed", "<= 4294967295"),
    Case(
        "huge-perception",
        put(("trials.scene_variation.perception_scale", [0.5, 1e300])),
        "trials.scene_variation.perception_scale[1]",
        "<= 10",
    ),
    Case("huge-fall-radius", put(("risk.fall.circle_radius", 1e300)), "risk.fall.circle_radius", "<= 1"),
    Case("huge-grasp-steepness", put(("risk.grasp.steepness", 1e308)), "risk.grasp.steepness", "<= 100"),
]

# --- settings that would switch a safety check off
SAFETY = [
    Case(
        "negative-com-margin",
        put(("risk.guard.min_com_margin", -0.01)),
        "risk.guard.min_com_margin",
        "switches",
    ),
    Case(
        "very-negative-com-margin",
        put(("risk.guard.min_com_margin", -1.0)),
        "risk.guard.min_com_margin",
        ">= 0",
    ),
    Case(
        "threshold-99",
        put(("risk.threshold", 99)),
        "risk.threshold",
        "largest expected_loss any alternative can have is 22",
    ),
    Case(
        "threshold-at-max",
        put(("risk.threshold", 22)),
        "risk.threshold",
        "is 22 (severity collision 3 x largest body-part factor 3",
    ),
    Case(
        "threshold-probability",
        put(("risk.ordering", "probability"), ("risk.threshold", 1.0)),
        "risk.threshold",
        "largest probability any alternative can have is 1",
    ),
    Case(
        "threshold-weighted-sum",
        put(("risk.ordering", "weighted_sum"), ("risk.threshold", 5.5)),
        "risk.threshold",
        "largest weighted_sum any alternative can have is 5",
    ),
    Case(
        "threshold-severities",
        put(("risk.severity.fall", 100.0), ("risk.threshold", 500)),
        "risk.threshold",
        "is 112 (severity collision 3 x largest body-part factor 3 + fall 100 + drop 2 + tracking 1)",
    ),
    Case(
        "threshold-zero-weights",
        put(
            ("risk.ordering", "weighted_sum"),
            ("risk.weights", {"collision": 0, "fall": 0, "drop": 0, "tracking": 0}),
            ("risk.threshold", 0),
        ),
        "risk.threshold",
        "is 0",
    ),
    Case(
        "grasp-weights-zero",
        put(("risk.grasp", {"position_weight": 0, "angle_weight": 0})),
        "risk.grasp.position_weight",
        "both 0",
    ),
]

# --- impossible scenes
SECOND_BOOK = {"name": "book2", "shape": "box", "size": [0.2, 0.1, 0.05], "position": [0.5, 0.3], "mass": 0.5}
SCENES = [
    Case(
        "object-overlaps-obstacle",
        put(("scene.objects[0].position", [0.62, 0.1])),
        "scene.objects[0].position",
        "overlaps the obstacle 'book_stack'",
    ),
    Case(
        "object-inside-obstacle",
        put(("scene.objects[0].position", [0.62, 0.0, 0.95])),
        "scene.objects[0].position",
        "overlaps the obstacle",
    ),
    Case(
        "object-turned-into-obstacle",
        put(("scene.objects[0].position", [0.62, 0.18]), ("scene.objects[0].orientation", 90)),
        "scene.objects[0].position",
        "overlaps the obstacle",
    ),
    Case(
        "obstacle-onto-object",
        put(("scene.obstacles[0].position", [0.5, 0.25])),
        "scene.objects[0].position",
        "'book_stack' (scene.obstacles[0])",
    ),
    Case(
        "objects-overlap",
        put(("scene.objects[1]", SECOND_BOOK)),
        "scene.objects[1].position",
        "overlaps the object 'book'",
    ),
    Case(
        "object-floats",
        put(("scene.objects[0].position", [0.52, 0.26, 1.2])),
        "scene.objects[0].position",
        "floats in the air",
    ),
    Case(
        "object-hovers",
        put(("scene.objects[0].position", [0.52, 0.26, 0.9])),
        "scene.objects[0].position",
        "0.075 m above the table top",
    ),
    Case(
        "object-in-table",
        put(("scene.objects[0].position", [0.52, 0.26, 0.7])),
        "scene.objects[0].position",
        "inside the table",
    ),
    Case(
        "object-on-floor",
        put(("scene.objects[0].position", [0.1, 0.9])),
        "scene.objects[0].position",
        "off the table (on the floor)",
    ),
    Case(
        "object-off-table-z",
        put(("scene.objects[0].position", [0.1, 0.9, 0.5])),
        "scene.objects[0].position",
        "off the table",
    ),
    Case(
        "object-far",
        put(("scene.objects[0].position", [3.0, 0.0, 0.025])),
        "scene.objects[0].position",
        "reaches at most 1.27 m",
    ),
    Case(
        "target-in-obstacle",
        put(("mission[0].transfer.to", [0.62, 0.0])),
        "mission[0].transfer.to",
        "overlaps the obstacle 'book_stack'",
    ),
    Case(
        "target-touching-deep",
        put(("mission[0].transfer.to", [0.62, -0.1])),
        "mission[0].transfer.to",
        "overlaps the obstacle",
    ),
    Case(
        "target-on-object",
        put(
            ("mission[0].transfer.to", [0.52, 0.26]),
            ("scene.objects[1]", {**SECOND_BOOK, "position": [0.45, -0.3]}),
            ("mission[0].transfer.object", "book2"),
        ),
        "mission[0].transfer.to",
        "overlaps the object 'book'",
    ),
    Case(
        "target-off-table-z",
        put(("mission[0].transfer.to", [0.52, -0.9, 0.3])),
        "mission[0].transfer.to",
        "off the table",
    ),
    Case(
        "target-on-floor",
        put(("mission[0].transfer.to", [0.1, -0.9, 0.025])),
        "mission[0].transfer.to",
        "off the table (on the floor)",
    ),
    Case(
        "target-floats",
        put(("mission[0].transfer.to", [0.52, -0.26, 1.2])),
        "mission[0].transfer.to",
        "floats in the air",
    ),
    Case(
        "target-off-table-xy",
        put(("mission[0].transfer.to", [0.1, -0.9])),
        "mission[0].transfer.to",
        "not over the table",
    ),
    Case(
        "target-far",
        put(("mission[0].transfer.to", [3.0, 0.0, 0.8])),
        "mission[0].transfer.to",
        "reaches at most 1.27 m",
    ),
    Case(
        "target-far-side",
        put(("mission[0].transfer.to", [0.5, -3.0, 0.8])),
        "mission[0].transfer.to",
        "arms 0.74 m long",
    ),
    Case(
        "table-far",
        put(
            ("scene.table.position", [6.0, 0.0]),
            ("scene.objects[0].position", [6.0, 0.26]),
            ("scene.obstacles[0].position", [6.1, 0.0]),
            ("mission[0].transfer.to", [6.0, -0.26]),
        ),
        "scene.table.position",
        "far outside the robot's reach",
    ),
    Case(
        "table-far-to-the-side",
        put(
            ("scene.table.position", [0.6, 5.0]),
            ("scene.objects[0].position", [0.6, 5.2]),
            ("scene.obstacles[0].position", [0.6, 5.0]),
            ("mission[0].transfer.to", [0.6, 4.7]),
        ),
        "scene.table.position",
        "shoulders 1.48 m high",
    ),
]

# --- body-part names
BODY_PARTS = [
    Case(
        f"body-part-{name}",
        put((f"risk.severity.body_parts.{name}", 1.5)),
        f"risk.severity.body_parts.{name}",
        hint,
    )
    for name, hint in (
        ("hnad", "unknown body part 'hnad'; did you mean"),
        ("haed", "did you mean 'head'?"),
        ("foreamr", "did you mean 'forearm'?"),
        ("Head", "valid names: the body-part labels head, hand, forearm"),
        ("tosro", "or a body of the robot's model: pelvis"),
        ("left_hand", "unknown body part 'left_hand'"),
    )
]

# --- misleading messages and paths that crashed
PATHS = [
    Case(
        "tiny-size",
        put(("scene.objects[0].size", [1e-9, 1e-9, 1e-9])),
        "scene.objects[0].size[0]",
        ">= 0.001",
    ),
    Case(
        "tiny-obstacle",
        put(("scene.obstacles[0].size", [1e-6, 0.16, 0.3])),
        "scene.obstacles[0].size[0]",
        ">= 0.001",
    ),
    Case(
        "mjcf-is-yaml",
        robot(_with_mjcf(lambda t: _file(t, "robot.yaml", "name: x\n"))),
        "robot.mjcf",
        "is not an MJCF model file",
    ),
    Case(
        "mjcf-is-text",
        robot(_with_mjcf(lambda t: _file(t, "robot.txt", "hello\n"))),
        "robot.mjcf",
        "it is a .txt file beginning 'hello'",
    ),
    Case(
        "mjcf-is-empty",
        robot(_with_mjcf(lambda t: _file(t, "robot.xml", ""))),
        "robot.mjcf",
        "is not an MJCF model file",
    ),
    Case(
        "mjcf-other-xml",
        robot(_with_mjcf(lambda t: _file(t, "robot.xml", "<html></html>"))),
        "robot.mjcf",
        "<mujoco> root",
    ),
    Case(
        "mjcf-missing", robot(_with_mjcf(lambda t: str(t / "none.xml"))), "robot.mjcf", "MJCF file not found"
    ),
    Case("mjcf-symlink-loop", robot(_with_mjcf(_loop)), "robot.mjcf", "invalid MJCF file path"),
    Case("profile-symlink-loop", robot(_with_profile(_loop)), "robot.profile", "invalid profile path"),
    Case("profile-nul-byte", robot(_with_profile(lambda t: f"{t}/a\0b.yaml")), "robot.profile", "null byte"),
    Case("profile-nul-name", robot(_with_profile(lambda t: "hum\0anoid")), "robot.profile", "null byte"),
    Case(
        "profile-no-such-user",
        robot(_with_profile(lambda t: "~nosuchuser_issue15/p.yaml")),
        "robot.profile",
        "invalid profile path",
    ),
    Case("profile-a-folder", robot(_with_profile(lambda t: str(t))), "robot.profile", "no profile file"),
    Case(
        "profile-missing",
        robot(_with_profile(lambda t: str(t / "none.yaml"))),
        "robot.profile",
        "no profile file",
    ),
]

# --- an obstacle's own severity, clearance and category (issue 17): none may switch a check off
OBSTACLE_LOSS = [
    Case(
        "negative-clearance",
        put(("scene.obstacles[0].clearance", -0.02)),
        "scene.obstacles[0].clearance",
        "> 0",
    ),
    Case("zero-clearance", put(("scene.obstacles[0].clearance", 0.0)), "scene.obstacles[0].clearance", "> 0"),
    Case("zero-severity", put(("scene.obstacles[0].severity", 0)), "scene.obstacles[0].severity", "> 0"),
    Case(
        "negative-severity", put(("scene.obstacles[0].severity", -5.0)), "scene.obstacles[0].severity", "> 0"
    ),
    Case(
        "nan-clearance",
        put(("scene.obstacles[0].clearance", math.nan)),
        "scene.obstacles[0].clearance",
        "finite",
    ),
    Case(
        "text-severity",
        put(("scene.obstacles[0].severity", "high")),
        "scene.obstacles[0].severity",
        "a number",
    ),
    Case(
        "category-typo",
        put(("scene.obstacles[0].category", "breech")),
        "scene.obstacles[0].category",
        "expected one of",
    ),
    Case("object-severity", put(("scene.objects[0].severity", 50.0)), "scene.objects[0]", "severity"),
    Case("object-clearance", put(("scene.objects[0].clearance", 0.05)), "scene.objects[0]", "clearance"),
    Case(
        "threshold-above-obstacle-severity",
        put(("scene.obstacles[0].severity", 50.0), ("risk.threshold", 200.0)),
        "risk.threshold",
        "severity collision 50 x largest body-part factor 3",
    ),
]

# --- missions the objects in hand do not allow (the bundled book: picked, placed, pushed, pressed)
PICK = {"pick": {"object": "book"}}
PLACE = {"place": {"object": "book", "to": [0.52, -0.26]}}
PUSH = {"push": {"object": "book", "to": [0.45, 0.26]}}
PRESS = {"press": {"target": "book_stack", "point": [0.62, 0.0, 1.10], "force": 10, "duration": 1.0}}
TRANSFER = {"transfer": {"object": "book", "to": [0.52, -0.26]}}
MISSIONS = [
    Case(
        "place-unpicked",
        put(("mission", [PLACE])),
        "mission[0].place",
        "'book' is not in hand (nothing picked it)",
    ),
    Case(
        "place-placed",
        put(("mission", [PICK, PLACE, {"place": {"object": "book", "to": [0.45, -0.40]}}])),
        "mission[2].place",
        "'book' is not in hand (it was put down by mission[1].place)",
    ),
    Case(
        "place-after-transfer",
        put(("mission", [TRANSFER, {"place": {"object": "book", "to": [0.45, 0.26]}}])),
        "mission[1].place",
        "nothing picked it",
    ),
    Case(
        "pick-held",
        put(("mission", [PICK, PICK, PLACE])),
        "mission[1].pick",
        "a pick needs its object on the table",
    ),
    Case("transfer-held", put(("mission", [PICK, TRANSFER, PLACE])), "mission[1].transfer", "still in hand"),
    Case("push-held", put(("mission", [PICK, PUSH, PLACE])), "mission[1].push", "still in hand"),
    Case("press-held", put(("mission", [PICK, PRESS, PLACE])), "mission[1].press", "still in hand"),
]

# --- hostile task kinds: a scenario is data; its dotted kinds import nothing unless allowed
HOSTILE = [
    Case(
        f"kind-{path.replace(':', '-')}",
        put(("mission", [{"kind": path, "object": "book"}])),
        "mission[0].kind",
        f"would import the module '{path.split(':')[0]}', which is not allowed",
    )
    for path in ("this:Zen", "os:system", "subprocess:Popen", "os.path:join", "tripwire_never:Kind")
]

CASES = [*DUPLICATES, *NUMBERS, *SAFETY, *SCENES, *BODY_PARTS, *PATHS, *OBSTACLE_LOSS, *MISSIONS, *HOSTILE]


def _write(case: Case, tmp_path: Path) -> Path:
    if case.on_text:
        document = case.mutate(SOURCE, tmp_path)  # type: ignore[arg-type]
    else:
        data = case.mutate(copy.deepcopy(yaml.safe_load(SOURCE)), tmp_path)  # type: ignore[arg-type]
        document = yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
    path = tmp_path / "case.yaml"
    path.write_text(document)
    return path


def test_at_least_100_distinct_cases_of_every_kind() -> None:
    assert len({case.id for case in CASES}) == len(CASES) >= 100
    kinds = (DUPLICATES, NUMBERS, SAFETY, SCENES, BODY_PARTS, PATHS, MISSIONS, HOSTILE)
    assert all(len(kind) >= 5 for kind in kinds)


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_validate_rejects_with_file_and_key_path(
    case: Case, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(case, tmp_path)
    code = main(["validate", str(path)])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert "Traceback" not in out + err
    assert f"{path}: {case.key_path}" in err, err
    assert case.message in err, err
    assert len(err.strip().splitlines()) == 1, err  # one message


def test_a_hostile_kind_is_refused_unimported(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """``kind: this:Zen`` used to print the Zen of Python before the kind was refused."""
    monkeypatch.delenv(ALLOW_ENV, raising=False)
    monkeypatch.delitem(sys.modules, "this", raising=False)
    path = _write(HOSTILE[0], tmp_path)
    assert main(["validate", str(path)]) == 2
    out, err = capsys.readouterr()
    assert "this:Zen" in err and "--allow-module this" in err and f"{ALLOW_ENV}=this" in err, err
    assert "Zen of Python" not in out + err and "this" not in sys.modules


TRIPWIRE = "tripwire_kind"


@pytest.fixture
def tripwire(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A module on ``sys.path`` whose import writes a file (returned; absent until it is imported)."""
    mark = tmp_path / "imported.txt"
    (tmp_path / f"{TRIPWIRE}.py").write_text(f"open({str(mark)!r}, 'w').write('imported')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, TRIPWIRE, raising=False)
    monkeypatch.delenv(ALLOW_ENV, raising=False)
    return mark


def _tripwire_doc() -> Doc:
    data: Doc = yaml.safe_load(SOURCE)
    data["mission"] = [{"kind": f"{TRIPWIRE}:Kind", "object": "book"}]
    return data


@pytest.mark.parametrize("allowed_by", ["flag", "environment", "environment list"])
def test_a_dotted_kind_imports_its_module_only_when_allowed(
    tripwire: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    allowed_by: str,
) -> None:
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(_tripwire_doc(), sort_keys=False))
    monkeypatch.setenv(ALLOW_ENV, "other_module, tripwire")  # neither names the module
    assert main(["validate", str(path), "--allow-module", f"{TRIPWIRE}_other"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: mission[0].kind: task kind '{TRIPWIRE}:Kind' would import" in err, err
    assert not tripwire.exists()
    if allowed_by == "flag":
        argv = ["validate", str(path), "--allow-module", "other", "--allow-module", TRIPWIRE]
    else:
        monkeypatch.setenv(ALLOW_ENV, TRIPWIRE if allowed_by == "environment" else f"x,{TRIPWIRE}")
        argv = ["validate", str(path)]
    assert main(argv) == 2  # imported, then refused: it has no Kind
    err = capsys.readouterr().err
    assert tripwire.exists() and f"module '{TRIPWIRE}' has no 'Kind'" in err, err
    if allowed_by == "flag":  # the flag allowed it for that command only
        assert os.environ[ALLOW_ENV] == "other_module, tripwire"


@pytest.mark.parametrize("api", ["from_dict", "loads", "load"])
def test_the_loading_functions_import_only_what_they_are_allowed(
    tripwire: Path, tmp_path: Path, api: str
) -> None:
    data = _tripwire_doc()
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    calls = {
        "from_dict": lambda **kw: scenarios.from_dict(data, **kw),
        "loads": lambda **kw: scenarios.loads(path.read_text(), **kw),
        "load": lambda **kw: scenarios.load(path, **kw),
    }
    with pytest.raises(ScenarioError, match="would import the module 'tripwire_kind'") as info:
        calls[api]()
    assert info.value.key_path == "mission[0].kind" and not tripwire.exists()
    with pytest.raises(ScenarioError, match="module 'tripwire_kind' has no 'Kind'"):
        calls[api](allow_modules=[TRIPWIRE])
    assert tripwire.exists()


def test_a_name_allows_its_module_and_submodules_only() -> None:
    from executive.tasks.registry import TaskKindError, get

    for allow in (["nosuch"], ["nosuch.sub"]):  # allowed: imported (and not found)
        with pytest.raises(TaskKindError, match=r"cannot import 'nosuch\.sub'"):
            get("nosuch.sub:Kind", allow_modules=allow)
    for allow in (["nosuc"], ["nosuch.sub.deeper"], ["nosuch.subway"], []):
        with pytest.raises(TaskKindError, match=r"would import the module 'nosuch\.sub'"):
            get("nosuch.sub:Kind", allow_modules=allow)


def test_a_duplicate_key_names_both_lines(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(DUPLICATES[0], tmp_path)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    line = SOURCE[: SOURCE.index("  threshold: 0.3\n")].count("\n") + 1
    assert f"first at line {line}, again at line {line + 1}" in err


def test_the_reach_comes_from_the_robot_model() -> None:
    from executive.robot.model import robot_facts
    from executive.robot.profile import load_bundled_profile

    profile = load_bundled_profile("humanoid")
    facts = robot_facts(HUMANOID_MJCF, profile)
    assert facts is not None
    # Shoulders 0.24 m to each side, arms along the joints to the grasp site.
    assert facts.shoulders["left"][1] == pytest.approx(-facts.shoulders["right"][1])
    assert 0.5 < facts.arm_lengths["left"] < facts.max_reach < 2.0


ACCEPTED = [
    ("d_safety 5e-2", text("d_safety: 0.05", "d_safety: 5e-2")),
    ("mass 6E-1", text("mass: 0.6", "mass: 6E-1")),
    ("threshold 3e-1", text("threshold: 0.3", "threshold: 3e-1")),
    ("timeout 6e1", text("timeout_s: 60", "timeout_s: 6e1")),
    ("target -2.6e-1", text("to: [0.52, -0.26]", "to: [5.2e-1, -2.6e-1]")),
    ("sigma 1e-2", text("com: 0.01", "com: 1e-2")),
    ("mass at its limit", text("mass: 0.6", "mass: 50")),
    ("threshold just below the max", text("threshold: 0.3", "threshold: 21.9")),
    ("breach obstacle, threshold above 21", lambda source, _tmp: _breach_obstacle(source)),
]


def _breach_obstacle(source: str) -> str:
    """The bundled file with its stack a breach obstacle of severity 20 and clearance 3 cm, and a
    threshold (40) only an obstacle's own severity makes reachable (20 x 3 + 10 + 2 + 1 = 73)."""
    own = "      severity: 20.0\n      clearance: 3e-2\n      category: breach\n"
    source = source.replace("      # Optional, per obstacle", own + "      # Optional, per obstacle")
    return source.replace("  threshold: 0.3", "  threshold: 40")


@pytest.mark.parametrize(("label", "mutate"), ACCEPTED, ids=[a[0] for a in ACCEPTED])
def test_what_people_write_and_mean_is_accepted(
    label: str, mutate: Callable[[str, Path], str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from executive import scenario

    path = tmp_path / "ok.yaml"
    path.write_text(mutate(SOURCE, tmp_path))
    loaded = scenario.load(path)
    assert loaded.scene.objects[0].name == "book", label
    if "breach" in label:
        stack = loaded.scene.obstacles[0]
        assert (stack.severity, stack.clearance, stack.category) == (20.0, 0.03, "breach")
    if "5e-2" in label:
        assert loaded.risk.d_safety == 0.05
        assert main(["validate", str(path)]) == 0
        assert "Traceback" not in capsys.readouterr().err
