"""The ``pick`` and ``place`` task kinds: their YAML blocks, their alternatives, and a pick
followed by a place in physics (the Executive, exact truth) ending with the object at its target."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from executive.errors import ScenarioError
from executive.scenario import load, loads
from executive.schema.catalog import scenario_path
from executive.tasks.pick_place import PickKind, PickTask, PlaceKind, PlaceTask
from executive.world.model import build

SCRIPT = Path(sys.executable).parent / "executive"
CMD = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main"]
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def _doc() -> dict[str, Any]:
    return yaml.safe_load(scenario_path("pick_place_push").read_text())


def _loads(doc: dict[str, Any]) -> Any:
    return loads(yaml.safe_dump(doc, sort_keys=False), "pp.yaml")


def test_pick_and_place_blocks_are_read() -> None:
    doc = _doc()
    doc["mission"][1]["place"]["to_yaw"] = 90
    mission = _loads(doc).mission
    assert mission[0] == PickTask(object="book", alternatives=("left", "right"))
    place = mission[1]
    assert isinstance(place, PlaceTask)
    assert place.to == (0.45, 0.50, None) and place.alternatives == ("left", "right")
    assert place.to_yaw_rad == pytest.approx(math.pi / 2)
    assert place.label() == "place book at (0.45, 0.50)"


@pytest.mark.parametrize(
    ("index", "block", "where", "says"),
    [
        (0, {"pick": {"alternatives": ["left"]}}, "mission[0].pick", "object"),
        (0, {"pick": {"object": "book", "to": [0.4, 0.4]}}, "mission[0].pick.to", "unknown key"),
        (0, {"pick": {"object": "book_stack"}}, "mission[0].pick.object", "obstacle"),
        (
            0,
            {"pick": {"object": "book", "alternatives": ["left_to_right"]}},
            "mission[0].pick.alternatives[0]",
            "left",
        ),
        (1, {"place": {"object": "book"}}, "mission[1].place", "to"),
        (1, {"place": {"object": "book", "to": [2.0, 0.4]}}, "mission[1].place.to", "not over the table"),
        (1, {"place": {"object": "book", "to": [0.62, 0.0]}}, "mission[1].place.to", "book_stack"),
        (
            1,
            {"place": {"object": "book", "to": [0.4, 0.44], "to_yaw": 400}},
            "mission[1].place.to_yaw",
            "360",
        ),
        (
            1,
            {"place": {"object": "book", "to": [0.4, 0.44], "alternatives": ["left", "left"]}},
            "alternatives[1]",
            "duplicate",
        ),
    ],
)
def test_bad_blocks_name_the_key(index: int, block: dict[str, Any], where: str, says: str) -> None:
    doc = _doc()
    doc["mission"][index] = block
    with pytest.raises(ScenarioError) as err:
        _loads(doc)
    assert "pp.yaml" in str(err.value) and where in str(err.value) and says in str(err.value)


def test_a_target_is_free_only_once_an_earlier_task_took_its_object_away() -> None:
    doc = _doc()
    pick, place, transfer = doc["mission"][:3]  # the transfer: the box to where the book lies at first
    doc["mission"] = [transfer]
    with pytest.raises(ScenarioError) as err:
        _loads(doc)
    assert "mission[0].transfer.to" in str(err.value) and "book" in str(err.value)
    doc["mission"] = [pick, place, transfer]
    assert len(_loads(doc).mission) == 3
    place["place"]["to"] = [0.52, 0.26]  # the book put back where it was: the box's target again
    with pytest.raises(ScenarioError) as err:
        _loads(doc)
    assert "mission[2].transfer.to" in str(err.value) and "book" in str(err.value)


@pytest.mark.parametrize("between", [3, 0])  # the push; a second pick (of the book again)
def test_only_the_place_may_follow_a_pick(between: int) -> None:
    doc = _doc()
    pick, place = doc["mission"][0], doc["mission"][1]
    doc["mission"] = [pick, doc["mission"][between], place]
    kind = next(iter(doc["mission"][1]))
    with pytest.raises(ScenarioError) as err:
        _loads(doc)
    assert f"mission[1].{kind}: 'book' is still in hand (picked by mission[0].pick)" in str(err.value)


def test_place_supports_only_the_hand_that_holds_the_object() -> None:
    scenario = load("pick_place_push")
    world = build(scenario)
    place, kind = scenario.mission[1], PlaceKind()
    nobody = {a.name: a.unsupported for a in kind.alternatives(place, world)}
    assert nobody == {s: "'book' is held by no hand (pick it first)" for s in ("left", "right")}
    world.held["book"] = "right"
    alts = {a.name: a.unsupported for a in kind.alternatives(place, world)}
    assert alts == {"left": "'book' is held by the right hand", "right": ""}
    picks = {a.name: a.unsupported for a in PickKind().alternatives(scenario.mission[0], world)}
    assert picks["left"] == "'book' is held by the right hand already"


def test_a_pick_with_nothing_in_hand_is_reported_as_a_drop() -> None:
    from executive.monitoring.detectors import FailureDetector

    world = build(load("pick_place_push"))  # the book on the table, no hand near it
    verdict = PickKind().verify(load("pick_place_push").mission[0], world, FailureDetector(world))
    assert verdict is not None and not verdict.ok
    assert verdict.fields["mode"] == "drop" and "no hand holds book" in verdict.fields["detail"]
    assert verdict.failure is not None and verdict.failure.mode == "drop"


def test_a_places_misplacement_risk_matches_monte_carlo_of_the_measured_grip() -> None:
    """The grip measured from 2 looks of 1 cm per axis lands its error on the target: P(|e| > 2 cm)."""
    from executive.decision.drop_model import _placed_from_hand
    from executive.planning.plan import AlternativePlan, Step
    from executive.world.model import Grip

    doc = _doc()
    doc["uncertainty"]["object_position"] = 0.01
    scenario = _loads(doc)
    world = build(scenario)
    world.held["book"] = "left"
    world.grips["book"] = Grip("left", np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), looks=2)
    steps = (
        Step("place", "left.place", "left", carried=("left", "book")),
        Step("release", "left.release", "left"),
    )
    plan = AlternativePlan("left", scenario.mission[1], steps)
    drop = _placed_from_hand(world, plan)
    rng = np.random.default_rng(7)
    error = rng.normal(0.0, 0.01 / math.sqrt(2), (400_000, 2))
    expected = float(np.mean(np.hypot(error[:, 0], error[:, 1]) > 0.02))
    assert drop.probability == pytest.approx(expected, abs=0.001)  # 0.0183


def test_bundled_scenario_validates() -> None:
    out = subprocess.run(
        [*CMD, "validate", "pick_place_push"], capture_output=True, text=True, env=ENV, timeout=120
    )
    assert out.returncode == 0, out.stderr
    kinds = {line.split()[2] for line in out.stdout.splitlines() if line.startswith("task ")}
    assert kinds == {"pick", "place", "transfer", "push"}


def _pick_then_place(tmp_path: Path) -> Path:
    """The bundled mission cut to its pick and place, without rollouts (the dry runs still run)."""
    doc = _doc()
    doc["mission"] = doc["mission"][:2]
    doc["risk"]["rollouts"] = {"count": 0}
    path = tmp_path / "pick_place.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_pick_then_place_in_physics_puts_the_book_at_its_target(tmp_path: Path) -> None:
    """Exact truth: the book ends resting within the detector's 2 cm of the place's target; while
    the place is planned the hand keeps it (gripper closed, hand at the hold pose)."""
    from executive.runtime.mission import Executive

    drift: list[float] = []
    with Executive(_pick_then_place(tmp_path), approval="deny", truth="exact", pace_waiting=True) as ex:
        truth = ex.truth
        assert truth is not None
        book = truth.ids.object_bodies["book"]

        def watch(e: Executive) -> None:
            task = e.current_task
            if task is not None and task.name == "task1" and task.phase == "planning":
                drift.append(float(np.linalg.norm(truth.data.xpos[book] - held_at)))

        ex.tick()
        while not ex.done and ex.current_task is not None and ex.current_task.name == "task0":
            ex.tick()
        held_at = truth.data.xpos[book].copy()
        summary = ex.run(time_limit_s=120.0, on_tick=watch)
        held = ex.log.of_kind("held")
    assert summary["outcome"] == "success", summary
    assert [h["side"] for h in held] == [summary["tasks"][0]["chosen"]]
    assert held[0]["contacts"] >= 2 and held[0]["force_n"] >= 10.0
    assert [t["outcome"] for t in summary["tasks"]] == ["success", "success"]
    assert summary["tasks"][1]["chosen"] == summary["tasks"][0]["chosen"]
    assert held_at[2] > 0.8 + 0.05  # held above the table top after the pick
    assert drift and max(drift) < 0.005  # held still while the place was planned
    pos = truth.data.xpos[book]
    assert math.hypot(pos[0] - 0.45, pos[1] - 0.50) < 0.02
    assert pos[2] == pytest.approx(0.80 + 0.025, abs=0.003)  # resting on the table top
