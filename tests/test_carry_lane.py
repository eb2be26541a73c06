"""The one-arm carry's lane comes only from the obstacles the carry passes (phases.carry_lane_front).

The bundled book transfer inside an enclosure: two tall box walls at the table's sides,
beside the work area. The lane is the x of the ``transfer`` step's hand target. Its
closed form: the nearest front face among the obstacles in the band the carried book's
footprint sweeps in y (plus ``obstacle_clearance``), minus ``obstacle_clearance`` and half
the book's length (capped by the grasp's and the place's x). The walls leave it where it is
without them, down to 5 mm outside the band; 5 mm inside, or across the carry's path, a wall
moves it. Feasibility is the real planner's.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
import yaml

from executive.planning.plan import CompositionConfig
from executive.planning.planner import Planner
from executive.scenario import from_dict
from executive.schema.catalog import scenario_path
from executive.schema.types import Body, Scenario
from executive.tasks.phases import footprint_half_y
from executive.tasks.steps import plan_alternative
from executive.tasks.transfer import transfer_steps
from executive.world.model import build

CLEARANCE = CompositionConfig().obstacle_clearance
BOOK_HALF_LENGTH = 0.11  # the bundled book is 0.22 m long (x)
BOOK_HALF_WIDTH = 0.055  # and 0.11 m wide (y); it keeps its yaw, 0
BAND = 0.26 + BOOK_HALF_WIDTH + CLEARANCE  # the carry from y 0.26 to -0.26: the band's half width
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


@pytest.mark.parametrize(("side", "y"), [("left", 0.60), ("right", 0.60), ("left", 0.46), ("right", 0.46)])
def test_side_walls_leave_the_lane_and_the_plan(side: str, y: float) -> None:
    walled = _scenario(_walls(y))  # 0.46: the inner faces 0.44 m from the middle, as tests/data's enclosure
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


def test_a_wall_moves_the_lane_from_where_it_enters_the_band() -> None:
    wall_front = 0.62 - 0.28  # the walls are 0.56 m deep, centred at x 0.62
    inside = _scenario(_walls(BAND - 0.005 + 0.02))  # a 4 cm wall whose inner face is 5 mm inside
    outside = _scenario(_walls(BAND + 0.005 + 0.02))
    assert _lane_x(inside, "left") == pytest.approx(wall_front - CLEARANCE - BOOK_HALF_LENGTH, abs=1e-9)
    assert _lane_x(outside, "left") == pytest.approx(STACK_FRONT - CLEARANCE - BOOK_HALF_LENGTH, abs=1e-9)


@pytest.mark.parametrize("yaws", [(0.0, 0.0), (0.0, math.pi / 2), (-0.5, 1.0), (0.3, 3.0), (-4.0, 4.0)])
def test_the_footprint_half_width_is_the_most_over_the_turn(yaws: tuple[float, float]) -> None:
    book = Body("book", "box", (0.22, 0.11, 0.05), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    turn = np.linspace(min(yaws), max(yaws), 200_001)  # the reference: a dense sweep of the yaw
    corners = np.array([[sx * 0.11, sy * 0.055] for sx in (-1, 1) for sy in (-1, 1)])
    reference = max(float(np.max(np.abs(corners @ np.array([np.sin(a), np.cos(a)])))) for a in turn[::1000])
    dense = float(np.max(0.11 * np.abs(np.sin(turn)) + 0.055 * np.abs(np.cos(turn))))
    assert footprint_half_y(book, yaws) == pytest.approx(dense, abs=1e-9)
    assert footprint_half_y(book, yaws) >= reference - 1e-12  # the corners' y never exceed it
