"""Grasp geometry as named reasons (executive/tasks/grasp_geometry.py).

References: the gripper's slide positions (``grasp_tolerance``'s jaw opening) against rays cast
at the model's open hand; the humanoid MJCF's finger numbers; the whole-body IK itself, which
stops short of the approach to an object the check calls too thin, by the missing thickness.
"""

from __future__ import annotations

from pathlib import Path

import pytest

import executive.tasks.steps as composition
from executive.planning.plan import CompositionConfig
from executive.planning.planner import Planner, PlanningError
from executive.risk.grasp import grasp_tolerance
from executive.risk.hand_span import hand_span
from executive.scenario import load, loads
from executive.tasks.grasp_geometry import GraspGeometryError, hand_geometry, min_thickness
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"
BOOK_SIZE = "size: [0.22, 0.11, 0.05]"


def _book(size: str) -> World:
    text = (SCENARIOS / "book_transfer.yaml").read_text()
    assert BOOK_SIZE in text
    return build(loads(text.replace(BOOK_SIZE, f"size: {size}"), source="book.yaml", base_dir=SCENARIOS))


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("book_transfer"))


def test_measured_hand_matches_the_gripper_and_the_mjcf(world: World) -> None:
    for side in ("left", "right"):
        geometry = hand_geometry(world, side)
        # The slide jaws' open and closed positions (grasp_tolerance's opening): closing = (o - w) / 2.
        tol = grasp_tolerance(world, side, "book")
        assert geometry.jaw_opening == pytest.approx(2.0 * tol.closing + 0.11, abs=1e-9)
        # humanoid.xml: pads end 0.025 + 0.065 + 0.03 = 0.12 m from the palm, the site 0.10 m.
        assert geometry.finger_depth == pytest.approx(0.02, abs=1e-9)


def test_min_thickness_closed_form() -> None:
    # Site 1 cm under the top, fingers 2 cm past it, 1 cm off the table: 2 + 1 + 1 = 4 cm.
    assert min_thickness(0.02, 0.01, 0.01) == pytest.approx(0.04)
    # Short fingers: the site stops at the centre of a thin object, t / 2 = 0.5 + 0.5 cm.
    assert min_thickness(0.005, 0.005, 0.02) == pytest.approx(0.02)


def test_too_wide_object_is_refused_by_name() -> None:
    wide = _book("[0.22, 0.18, 0.05]")
    for alternative in ("left", "right", "left_to_right"):
        with pytest.raises(GraspGeometryError) as info:
            plan_alternative(Planner(wide), wide, wide.scenario.mission[0], alternative)
        message = str(info.value)
        assert "the 18 cm 'book' is wider than the 17 cm jaw opening" in message, message
    assert isinstance(info.value, PlanningError)


def test_too_thin_object_is_refused_by_name_and_the_ik_agrees(monkeypatch: pytest.MonkeyPatch) -> None:
    thin = _book("[0.22, 0.11, 0.03]")
    task = thin.scenario.mission[0]
    with pytest.raises(GraspGeometryError) as info:
        plan_alternative(Planner(thin), thin, task, "left")
    message = str(info.value)
    print(message)
    assert "the 3 cm 'book' is thinner than the 4 cm the fingers need above the table" in message
    # Without the check, the IK stops short of the approach by the missing centimetre (within its
    # position tolerance): the table clearance holds the fingertips up.
    monkeypatch.setattr(composition, "check_grasps", lambda *args, **kwargs: None)
    planner = Planner(thin)
    with pytest.raises(PlanningError) as ik:
        plan_alternative(planner, thin, task, "left")
    print(ik.value)
    assert ik.value.name == "left.approach"
    missing = 0.04 - 0.03
    assert ik.value.position_error == pytest.approx(missing, abs=planner.config.position_tolerance + 1e-3)


def test_object_at_the_limit_plans(world: World) -> None:
    exact = _book("[0.22, 0.11, 0.04]")
    plan = plan_alternative(Planner(exact), exact, exact.scenario.mission[0], "left")
    assert "left.approach" in plan.trajectories


def test_g1_dex3_opening_is_measured_on_its_open_hand(g1_scenario_yaml: str) -> None:
    """The Dex3 has no slide jaws: its opening is the rays' span between thumb and fingers,
    and the grasp tolerance uses that span (the 9 cm book leaves (opening - 9 cm) / 2)."""
    g1 = build(loads(g1_scenario_yaml, source="g1_book_transfer.yaml"))
    for side in ("left", "right"):
        geometry = hand_geometry(g1, side)
        tolerance = grasp_tolerance(g1, side, "book")
        assert tolerance.closing == pytest.approx((geometry.jaw_opening - 0.09) / 2.0, abs=1e-9)
        # The profile's site sits between the open thumb and fingers, the 9 cm book fits with
        # room for the approach, and the fingertips keep clear of the table under a 5 cm book.
        assert 0.09 < geometry.jaw_opening < 0.20
        assert 0.0 < geometry.finger_depth < 0.04 - 0.01
    wide = build(
        loads(g1_scenario_yaml.replace("0.14, 0.09, 0.05", "0.14, 0.16, 0.05"), source="g1_wide.yaml")
    )
    with pytest.raises(GraspGeometryError, match="the 16 cm 'book' is wider than the 15 cm jaw opening"):
        plan_alternative(Planner(wide), wide, wide.scenario.mission[0], "left")


def test_g1_dex3_fingers_reach_deeper_closed(g1_scenario_yaml: str) -> None:
    """The Dex3's fingers curl below the grasp point as they close (2.5 cm, against 1.8 cm open):
    the finger depth is the closed one, and a 4 cm book is refused before planning with the
    thickness the closed hand needs: depth + 1 cm table clearance + 1 cm grip depth (closed form,
    :func:`min_thickness`), where in physics the guard stopped the lift 7.7 mm off the table."""
    g1 = build(loads(g1_scenario_yaml, source="g1_book_transfer.yaml"))
    geometry = hand_geometry(g1, "left")
    open_depth = hand_span(g1, "left").finger_depth
    closed_depth = hand_span(g1, "left", closed=True).finger_depth
    assert closed_depth > open_depth + 0.005
    assert geometry.finger_depth == closed_depth
    need = min_thickness(closed_depth, 0.01, CompositionConfig().grip_depth)
    assert need == pytest.approx(closed_depth + 0.02, abs=1e-12) and 0.04 < need < 0.05
    thin = build(
        loads(g1_scenario_yaml.replace("0.14, 0.09, 0.05", "0.14, 0.09, 0.04"), source="g1_thin.yaml")
    )
    with pytest.raises(GraspGeometryError, match=r"the 4 cm 'book' is thinner than the 4\.5 cm"):
        plan_alternative(Planner(thin), thin, thin.scenario.mission[0], "left")
