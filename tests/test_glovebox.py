"""The bundled glovebox scenario: it loads, its breach obstacles frame the documented ports, and
the press through the right port plans on the estimate and runs in MuJoCo (issue 17)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from executive.execution.runner import run_alternative
from executive.planning.route import Footprint, via_points
from executive.scenario.loader import load
from executive.world.model import World, build

#: The openings the scenario's header documents (m): across (y) and high (z), and their centres.
PORT_WIDTH, PORT_HEIGHT, PORT_Y, PORT_Z = 0.40, 0.36, 0.25, 1.09
RIMS = ("top", "bottom", "inner", "outer")


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("glovebox"))


def _box(world: World, name: str) -> tuple[np.ndarray, np.ndarray]:
    """World-aligned (lo, hi) of an obstacle's box geom, from the compiled MuJoCo model."""
    geom = world.ids.obstacle_geoms[name]
    assert world.model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_BOX
    data = mujoco.MjData(world.model)
    mujoco.mj_kinematics(world.model, data)
    rot = data.geom_xmat[geom].reshape(3, 3)
    half = np.abs(rot) @ world.model.geom_size[geom]
    return data.geom_xpos[geom] - half, data.geom_xpos[geom] + half


def test_scenario_validates_with_a_three_task_mission() -> None:
    scenario = load("glovebox")
    assert [t.kind for t in scenario.mission] == ["pick", "place", "press"]
    assert len(scenario.scene.objects) == 1 and scenario.scene.objects[0].shape == "cylinder"


@pytest.mark.parametrize("side", ["left", "right"])
def test_port_opening_measured_from_the_rims(world: World, side: str) -> None:
    """The opening between the rims' inner faces is at least the documented size, where documented."""
    box = {rim: _box(world, f"{side}_port_rim_{rim}") for rim in RIMS}
    sign = 1.0 if side == "left" else -1.0
    inner, outer = box["inner"], box["outer"]
    near, far = (inner[1][1], outer[0][1]) if side == "left" else (outer[1][1], inner[0][1])
    width = far - near
    height = box["top"][0][2] - box["bottom"][1][2]
    assert width >= PORT_WIDTH - 1e-9 and height >= PORT_HEIGHT - 1e-9
    assert (near + far) / 2 == pytest.approx(sign * PORT_Y, abs=1e-9)
    assert (box["top"][0][2] + box["bottom"][1][2]) / 2 == pytest.approx(PORT_Z, abs=1e-9)
    # All four rims stand in the front wall's plane, one thickness, the window right above.
    xs = {(round(lo[0], 9), round(hi[0], 9)) for lo, hi in box.values()}
    assert len(xs) == 1
    window = _box(world, "window")
    assert window[0][2] == pytest.approx(box["top"][1][2], abs=1e-9)
    assert (round(window[0][0], 9), round(window[1][0], 9)) in xs


def test_severity_tiers(world: World) -> None:
    """Window and rims are breaches with the highest severity; walls lower; a drop lower still."""
    scenario = world.scenario
    by_name = {o.name: o for o in scenario.scene.obstacles}
    breach = {n for n, o in by_name.items() if o.category == "breach"}
    assert breach == {"window"} | {f"{s}_port_rim_{r}" for s in ("left", "right") for r in RIMS}
    default = scenario.risk.severity.collision
    walls = [o.severity or default for n, o in by_name.items() if n not in breach]
    lowest_breach = min(by_name[n].severity or default for n in breach)
    assert lowest_breach > max(walls) > scenario.risk.severity.drop


def test_route_passes_under_an_obstacle_above_the_hand() -> None:
    """A hand's straight way under a lintel needs no via; a wall across it needs two, over its top."""
    extent = Footprint(np.array([-0.05, -0.1, -0.05]), np.array([0.05, 0.1, 0.1]))
    start, target = np.array([0.3, 0.0, 1.0]), np.array([0.7, 0.0, 1.0])
    lintel = (np.array([0.49, -0.5, 1.2]), np.array([0.51, 0.5, 1.5]))
    assert via_points(start, target, extent, [lintel], clearance=0.04) == []
    wall = (np.array([0.49, -0.5, 0.8]), np.array([0.51, 0.5, 1.1]))
    vias = via_points(start, target, extent, [lintel, wall], clearance=0.04)
    assert len(vias) == 2
    # Closed form: the footprint's bottom (-0.05) clears the wall's top (1.1) by the clearance.
    assert vias[0][2] == pytest.approx(1.1 + 0.04 + 0.05) and vias[1][2] == pytest.approx(1.19)


def test_press_through_the_right_port_runs_in_physics() -> None:
    """Task 2, exact truth: planned on the estimate, executed in MuJoCo without a collision."""
    result = run_alternative(load("glovebox"), "right", task_index=2, exact=True)
    assert result.outcome == "success", result.message or result.failure
    assert result.sim_time_s > 1.0  # the hold alone is 1 s of simulated time


def test_the_sample_stays_inside_the_box(world: World) -> None:
    """The front wall is reached through, not skirted: the pick holds the can behind it and the
    place carries it there (a lane in front of the wall would take it out through the port)."""
    from executive.planning.plan import CompositionConfig
    from executive.tasks.phases import carry_lane_front
    from executive.tasks.registry import get

    scenario = world.scenario
    wall = next(o for o in scenario.scene.obstacles if o.name == "front_wall_lower")
    inside = wall.position[0] + wall.size[0] / 2  # the wall's inner face
    pick = scenario.mission[0]
    steps = get(pick.kind).steps(pick, world, "left", CompositionConfig())
    carried = [t.position for s in steps if s.carried for t in s.targets]
    assert carried and min(p[0] for p in carried) > inside + 0.02  # the can's radius and more
    # the same scene without the rule: the wall (and the roof above) set a lane outside the box
    can, _ = world.object_pose("can")
    band = (float(can[1]), 0.25)
    outside = carry_lane_front(scenario.scene, band, 0.1, 0.0, float(can[0]))
    assert outside < inside
    behind = carry_lane_front(scenario.scene, band, 0.1, 0.0, float(can[0]), float(can[0]) - 0.025, 1.13)
    assert behind > inside
