"""The bundled glovebox scenario: it loads, its breach obstacles frame the documented ports, the
press through the right port and the regrasp between the ports plan on the estimate and run in
MuJoCo, and the can never leaves the box (issue 17)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from executive.execution.runner import run_alternative
from executive.planning.route import Footprint, via_points
from executive.scenario.loader import load
from executive.world.model import World, build

#: The openings the scenario's header documents (m): across (y) and high (z), and their centres.
PORT_WIDTH, PORT_HEIGHT, PORT_Y, PORT_Z = 0.40, 0.40, 0.22, 1.11
BREACH = {
    "window",
    "port_rim_top",
    "port_rim_bottom",
    "port_mullion",
    "left_port_rim_outer",
    "right_port_rim_outer",
}


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
    assert [t.kind for t in scenario.mission] == ["press", "transfer", "press"]
    assert scenario.mission[1].alternatives[0] == "right_regrasp_left"
    assert len(scenario.scene.objects) == 1 and scenario.scene.objects[0].shape == "cylinder"


@pytest.mark.parametrize("side", ["left", "right"])
def test_port_opening_measured_from_the_rims(world: World, side: str) -> None:
    """The opening between the rims' inner faces is the documented size, where documented."""
    sign = 1.0 if side == "left" else -1.0
    top, bottom = _box(world, "port_rim_top"), _box(world, "port_rim_bottom")
    mullion, outer = _box(world, "port_mullion"), _box(world, f"{side}_port_rim_outer")
    near, far = (mullion[1][1], outer[0][1]) if side == "left" else (outer[1][1], mullion[0][1])
    assert far - near == pytest.approx(PORT_WIDTH, abs=1e-9)
    assert top[0][2] - bottom[1][2] == pytest.approx(PORT_HEIGHT, abs=1e-9)
    assert (near + far) / 2 == pytest.approx(sign * PORT_Y, abs=1e-9)
    assert (top[0][2] + bottom[1][2]) / 2 == pytest.approx(PORT_Z, abs=1e-9)
    # The rims stand in the front wall's plane, one thickness, the window right above.
    xs = {(round(lo[0], 9), round(hi[0], 9)) for lo, hi in (top, bottom, mullion, outer)}
    window = _box(world, "window")
    assert len(xs) == 1 and (round(window[0][0], 9), round(window[1][0], 9)) in xs
    assert window[0][2] == pytest.approx(top[1][2], abs=1e-9)


def test_severity_and_clearance_tiers(world: World) -> None:
    """Window and rims are breaches with the highest severity; walls lower; a drop lower still.
    The rims may be passed at 2 cm, the window at no less than 5 cm."""
    scenario = world.scenario
    by_name = {o.name: o for o in scenario.scene.obstacles}
    breach = {n for n, o in by_name.items() if o.category == "breach"}
    assert breach == BREACH
    default = scenario.risk.severity.collision
    walls = [o.severity or default for n, o in by_name.items() if n not in breach]
    lowest_breach = min(by_name[n].severity or default for n in breach)
    assert lowest_breach > max(walls) > scenario.risk.severity.drop
    assert by_name["window"].clearance == 0.05
    assert {by_name[n].clearance for n in breach - {"window"}} == {0.02}


def test_route_passes_under_an_obstacle_above_the_hand() -> None:
    """A hand's straight way under a lintel needs no via; a wall across it needs two, over its top."""
    extent = Footprint(np.array([-0.05, -0.1, -0.05]), np.array([0.05, 0.1, 0.1]))
    start, target = np.array([0.3, 0.0, 1.0]), np.array([0.7, 0.0, 1.0])
    lintel = (np.array([0.49, -0.5, 1.4]), np.array([0.51, 0.5, 1.5]))
    assert via_points(start, target, extent, [lintel], clearance=0.04) == []
    wall = (np.array([0.49, -0.5, 0.8]), np.array([0.51, 0.5, 1.1]))
    vias = via_points(start, target, extent, [lintel, wall], clearance=0.04)
    assert len(vias) == 2
    # Closed form: the footprint's bottom (-0.05) clears the wall's top (1.1) by the clearance.
    assert vias[0][2] == pytest.approx(1.1 + 0.04 + 0.05) and vias[1][2] == pytest.approx(1.19)


def test_no_way_over_a_port_side_with_the_wall_above() -> None:
    """A hand passing close beside a port's side rim would be lifted over it, into the rim
    above the port: no via points then (the hand goes straight, along the opening), where the
    side rim alone gets two."""
    extent = Footprint(np.array([-0.05, -0.1, -0.05]), np.array([0.05, 0.1, 0.1]))
    start, target = np.array([0.3, 0.0, 0.93]), np.array([0.7, 0.0, 1.03])
    side = (np.array([0.43, 0.12, 0.91]), np.array([0.45, 0.16, 1.27]))  # within 4 cm of the hand
    vias = via_points(start, target, extent, [side], clearance=0.04)
    # Closed form: the footprint's bottom (-0.05) clears the side rim's top (1.27) by 0.04.
    assert len(vias) == 2 and vias[0][2] == pytest.approx(1.27 + 0.04 + 0.05)
    top = (np.array([0.43, -0.5, 1.27]), np.array([0.45, 0.5, 1.31]))  # above the straight way
    assert via_points(start, target, extent, [top], clearance=0.04) == []
    assert via_points(start, target, extent, [side, top], clearance=0.04) == []


def test_press_through_the_right_port_runs_in_physics() -> None:
    """Task 2, exact truth: planned on the estimate, executed in MuJoCo without a collision."""
    result = run_alternative(load("glovebox"), "right", task_index=2, exact=True)
    assert result.outcome == "success", result.message or result.failure
    assert result.sim_time_s > 1.0  # the hold alone is 1 s of simulated time


def test_regrasp_between_the_ports_runs_in_physics() -> None:
    """Task 1, exact truth: the right hand sets the can down between the ports, the left takes it
    to the bag-out; it ends within the placement tolerance of its target."""
    scenario = load("glovebox")
    result = run_alternative(scenario, "right_regrasp_left", task_index=1, exact=True)
    assert result.outcome == "success", result.message or result.failure
    assert result.placement_error_m is not None and result.placement_error_m < 0.02


def test_the_sample_stays_inside_the_box(world: World) -> None:
    """The front wall is reached through, not skirted: every carry of the regrasp keeps the can
    behind it, and each hand goes in and out along its own line, straight ahead of its home pose
    through its own port (a lane in front of the wall would take the can out through a port)."""
    from executive.planning.plan import CompositionConfig
    from executive.tasks.hands import HandFrames
    from executive.tasks.phases import carry_lane_front
    from executive.tasks.registry import get

    scenario = world.scenario
    wall = next(o for o in scenario.scene.obstacles if o.name == "front_wall_lower")
    inside = wall.position[0] + wall.size[0] / 2  # the wall's inner face
    transfer = scenario.mission[1]
    steps = get(transfer.kind).steps(transfer, world, "right_regrasp_left", CompositionConfig())
    carried = [t.position for s in steps if s.carried for t in s.targets]
    assert carried and min(p[0] for p in carried) > inside + 0.025  # the can's radius and more
    home = HandFrames(world).home
    for name in ("right.reach_in", "right.back", "left.reach_in", "left.back"):
        (target,) = next(s for s in steps if s.name == name).targets
        side = name.split(".")[0]
        assert target.position[1] == pytest.approx(home[side].position[1], abs=1e-12)
        assert target.position[0] > inside
    # the same scene without the rule: the wall (and the roof above) set a lane outside the box
    can, _ = world.object_pose("can")
    band = (float(can[1]), 0.28)
    outside = carry_lane_front(scenario.scene, band, 0.1, 0.0, float(can[0]))
    assert outside < inside
    behind = carry_lane_front(scenario.scene, band, 0.1, 0.0, float(can[0]), float(can[0]) - 0.025, 1.13)
    assert behind > inside


def test_campaign_counts_breach_touches_apart() -> None:
    """The campaign's prediction carries P(breach) (a part of the collision mode), and its
    summary counts the trials whose failure touched a breach obstacle, with the interval."""
    from executive.validation.campaign import predict, summarise, table_text

    scenario = load("glovebox")
    prediction = predict(scenario, 2, "right")
    assert prediction.risk is not None
    assert 0.0 <= prediction.risk["breach"] <= prediction.risk["collision"]
    predicted = {**prediction.risk, "value": prediction.value}

    def record(i: int, bodies: tuple[str, ...]) -> dict[str, object]:
        failure = {"mode": "collision", "bodies": list(bodies), "detail": "-"} if bodies else None
        outcome = "collision" if bodies else "success"
        return {
            "trial": i,
            "alternative": "right",
            "outcome": outcome,
            "failure": failure,
            "predicted": predicted,
        }

    records = [record(0, ("right_hand", "window")), record(1, ("right_hand", "right_wall")), record(2, ())]
    summary = summarise(scenario, records, ["right", "left"], {"right": prediction})
    touches = summary["alternatives"][0]["breach"]
    assert (touches["touches"], touches["trials"]) == (1, 3)
    assert touches["rate"]["ci95"][0] > 0.0 and touches["predicted"] == pytest.approx(
        prediction.risk["breach"]
    )
    assert "right: 1 of 3" in table_text(summary)
