"""The one-arm carry's lane comes only from the obstacles the carry passes (phases.carry_lane_front).

The bundled book transfer inside an enclosure: two tall box walls at the table's sides,
far beside the work area. The lane is the x of the ``transfer`` step's hand target. Its
closed form: the nearest front face among the obstacles in the band the carried book
sweeps, minus ``obstacle_clearance`` and half the book's length (capped by the grasp's and
the place's x). The walls leave it where it is without them; a wall across the carry's
path moves it. Feasibility is the real planner's.
"""

from __future__ import annotations

from typing import Any

import pytest
import yaml

from executive.planning.plan import CompositionConfig
from executive.planning.planner import Planner
from executive.scenario import from_dict
from executive.schema.catalog import scenario_path
from executive.schema.types import Scenario
from executive.tasks.steps import plan_alternative
from executive.tasks.transfer import transfer_steps
from executive.world.model import build

CLEARANCE = CompositionConfig().obstacle_clearance
BOOK_HALF_LENGTH = 0.11  # the bundled book is 0.22 m long (x)
STACK_FRONT = 0.62 - 0.11  # the stack's centre x minus half its 0.22 m depth


def _walls(y: float) -> list[dict[str, Any]]:
    """Two tall walls 4 cm thick along the table's depth, at +-y, standing on the table."""
    return [
        {"name": f"wall_{side}", "shape": "box", "size": [0.56, 0.04, 0.60], "position": [0.62, sign * y]}
        for side, sign in (("left", 1.0), ("right", -1.0))
    ]


def _scenario(extra: list[dict[str, Any]]) -> Scenario:
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["scene"]["obstacles"] = [*doc["scene"]["obstacles"], *extra]
    return from_dict(doc)


def _lane_x(scenario: Scenario, side: str) -> float:
    steps = transfer_steps(build(scenario), scenario.mission[0], side)
    step = next(s for s in steps if s.name == f"{side}.transfer")
    return float(step.targets[0].position[0])


@pytest.mark.parametrize("side", ["left", "right"])
def test_side_walls_leave_the_lane_and_the_plan(side: str) -> None:
    walled = _scenario(_walls(0.60))
    expected = STACK_FRONT - CLEARANCE - BOOK_HALF_LENGTH
    assert _lane_x(_scenario([]), side) == pytest.approx(expected, abs=1e-9)
    assert _lane_x(walled, side) == pytest.approx(expected, abs=1e-9)
    world = build(walled)
    plan = plan_alternative(Planner(world), world, walled.mission[0], side)
    assert f"{side}.transfer" in plan.trajectories  # feasible between the walls


def test_a_wall_across_the_path_moves_the_lane() -> None:
    # A low wall 4 cm deep in front of the stack, across the carry's right half (y -0.16..0).
    across = {"name": "low_wall", "shape": "box", "size": [0.04, 0.16, 0.06], "position": [0.46, -0.08]}
    scenario = _scenario([*_walls(0.60), across])
    front = 0.46 - 0.02
    for side in ("left", "right"):
        assert _lane_x(scenario, side) == pytest.approx(front - CLEARANCE - BOOK_HALF_LENGTH, abs=1e-9)
