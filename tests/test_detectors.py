"""Failure detectors on the real physics of the bundled book world.

Every failure here is made by MuJoCo: arms driven into the stack, the table and the
book through their position servos, the robot pushed over with an external force,
the book dropped, a real grasp held, a real MuJoCo warning raised. The closest
clearance is checked against an exhaustive ``mj_geomDistance`` over every forbidden
geom pair (no broad phase), not against the detector's own numbers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence

import mujoco
import numpy as np
import pytest

from executive.monitoring.detectors import (
    DetectorError,
    DetectorThresholds,
    Failure,
    FailureDetector,
)
from executive.scenario import load
from executive.world.model import World, build

Waypoints = Sequence[tuple[float, dict[str, float]]]


@pytest.fixture(scope="module")
def shared_world() -> World:
    return build(load("book_transfer"))


@pytest.fixture
def world(shared_world: World) -> Iterator[World]:
    shared_world.reset()
    shared_world.data.xfrc_applied[:] = 0.0
    yield shared_world
    shared_world.data.xfrc_applied[:] = 0.0
    shared_world.reset()


def _actuator(world: World, name: str) -> int:
    return int(world.model.actuator(name).id)


def _drive(
    world: World,
    detector: FailureDetector,
    waypoints: Waypoints,
    *,
    each_step: Callable[[], None] | None = None,
) -> Failure | None:
    """Ramp the home ctrl linearly through ``waypoints`` ((end time, {actuator: target})).

    Stops at the first failure; returns it (or None at the end of the last waypoint).
    """
    m, d = world.model, world.data
    prev = world.home_ctrl()
    start = float(d.time)
    for end, targets in waypoints:
        goal = prev.copy()
        for name, value in targets.items():
            goal[_actuator(world, name)] = value
        while d.time < end - 1e-9:
            a = min(1.0, (float(d.time) - start) / (end - start))
            d.ctrl[:] = prev + a * (goal - prev)
            if each_step is not None:
                each_step()
            mujoco.mj_step(m, d)
            found = detector.check()
            if found is not None:
                return found
        prev, start = goal, end
    return None


def _hold(world: World, detector: FailureDetector, seconds: float, ctrl: np.ndarray | None = None) -> None:
    m, d = world.model, world.data
    c = world.home_ctrl() if ctrl is None else ctrl
    for _ in range(round(seconds / m.opt.timestep)):
        d.ctrl[:] = c
        mujoco.mj_step(m, d)
        detector.check()


def _move_book(
    world: World, xyz: Sequence[float] | np.ndarray, quat: Sequence[float] | np.ndarray | None = None
) -> None:
    adr = world.ids.object_qpos["book"]
    world.data.qpos[adr : adr + 3] = xyz
    if quat is not None:
        world.data.qpos[adr + 3 : adr + 7] = quat
    world.data.qvel[world.model.jnt_dofadr[world.model.joint("book_free").id] :][:6] = 0.0
    mujoco.mj_forward(world.model, world.data)


def _grasp_book_in_left_hand(world: World) -> np.ndarray:
    """Put the book between the open left jaws (aligned with the hand site) and return a closing ctrl."""
    m, d = world.model, world.data
    site = world.ids.hand_sites["left"]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, d.site_xmat[site])
    _move_book(world, d.site_xpos[site].copy(), quat)
    for joint in ("left_finger_a_slide", "left_finger_b_slide"):
        d.qpos[m.jnt_qposadr[m.joint(joint).id]] = 0.056  # half gap just over the book's 5.5 cm
    mujoco.mj_forward(m, d)
    ctrl = world.home_ctrl()
    for name in ("left_grip_a", "left_grip_b"):
        ctrl[_actuator(world, name)] = 0.0
    return ctrl


# Hand motions found by forward kinematics of the embedded humanoid in the book scene.
LEFT_INTO_STACK: Waypoints = [
    (1.5, {"left_shoulder_pitch": -0.6, "left_elbow": -0.8, "left_shoulder_yaw": -0.6}),
    (2.5, {}),
]
RIGHT_ONTO_TABLE: Waypoints = [
    (1.0, {"waist_pitch": 0.4, "right_shoulder_pitch": -0.6, "right_elbow": -0.3, "right_wrist_pitch": -0.6}),
    (2.0, {}),
]


def _down_onto_book(side: str) -> Waypoints:
    """Close the jaws, reach forward above the book, then lean the waist: fingertips land on it."""
    arm = {
        f"{side}_shoulder_pitch": -0.8,
        f"{side}_elbow": -0.3,
        f"{side}_wrist_pitch": -0.3,
        f"{side}_grip_a": 0.0,
        f"{side}_grip_b": 0.0,
    }
    return [(0.8, arm), (2.0, {"waist_pitch": 0.4}), (2.5, {})]


# --- 1. standing still ----------------------------------------------------------------------


def _forbidden_min_distance(world: World) -> float:
    """Exhaustive reference, no phase: every robot geom vs. table, obstacles and objects, and
    every object vs. the obstacles (the pairs the rules forbid; the floor is left out)."""
    m, d = world.model, world.data
    objects = list(world.ids.object_geoms.values())
    obstacles = list(world.ids.obstacle_geoms.values())
    pairs = [(r, g) for r in world.ids.robot_geoms for g in [*world.ids.table_geoms, *obstacles, *objects]]
    pairs += [(o, g) for o in objects for g in obstacles]
    return min(float(mujoco.mj_geomDistance(m, d, g1, g2, 1.0, None)) for g1, g2 in pairs)


def test_standing_still_3_s_is_no_failure_and_reports_the_closest_call(world: World) -> None:
    m, d = world.model, world.data
    detector = FailureDetector(world)
    ctrl = world.home_ctrl()
    reference = math.inf
    for step in range(1, round(3.0 / m.opt.timestep) + 1):
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d)
        assert detector.check() is None
        if step % 10 == 0:  # the detector's clearance stride
            reference = min(reference, _forbidden_min_distance(world))
    call = detector.closest_call
    print("standing:", call.describe())
    assert detector.failure is None
    assert call.distance == pytest.approx(reference, abs=1e-9)
    assert 0.05 < call.distance < detector.thresholds.clearance_horizon  # hands ~10 cm above the table
    assert call.distance_bodies[0].startswith(("left_", "right_")) and call.distance_bodies[1] == "table"
    assert call.self_contacts == 0 and call.ignored_force == 0.0
    assert "mm" in call.describe()


# --- 2. collisions --------------------------------------------------------------------------


def test_left_hand_driven_into_the_book_stack_is_a_collision(world: World) -> None:
    detector = FailureDetector(world)
    failure = _drive(world, detector, LEFT_INTO_STACK)
    print(failure)
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies[0].startswith("left_") and failure.bodies[1] == "book_stack"
    assert failure.force >= 1.0 and 0.0 < failure.time < 2.5
    assert "book_stack" in failure.detail and f"{failure.force:.1f} N" in failure.detail
    assert f"t={failure.time:.3f} s" in failure.detail
    # The clearance came down to the contact just before (it is sampled every 10 steps).
    assert detector.closest_call.distance < 0.01
    assert detector.closest_call.distance_bodies[1] == "book_stack"


def test_right_hand_driven_onto_the_table_is_a_collision(world: World) -> None:
    failure = _drive(world, FailureDetector(world), RIGHT_ONTO_TABLE)
    print(failure)
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies[0].startswith("right_") and failure.bodies[1] == "table"
    assert failure.force >= 1.0 and failure.time > 0.0


def test_right_hand_into_a_book_nobody_holds_is_a_collision_naming_the_book(world: World) -> None:
    book = world.data.xpos[world.ids.object_bodies["book"]]
    _move_book(world, (book[0], -book[1], book[2]))  # mirror it in front of the right hand
    detector = FailureDetector(world)
    _hold(world, detector, 0.1)  # let it settle on the table: resting is allowed
    assert detector.failure is None
    failure = _drive(world, detector, [(float(world.data.time), {}), *_down_onto_book("right")])
    print(failure)
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies[0].startswith("right_") and failure.bodies[1] == "book"
    assert failure.force >= 1.0


# --- 3. fall --------------------------------------------------------------------------------


def _push(world: World, force: tuple[float, float, float], until: float) -> Callable[[], None]:
    def apply() -> None:
        on = world.data.time < until
        world.data.xfrc_applied[world.ids.torso_body, :3] = force if on else (0.0, 0.0, 0.0)

    return apply


def test_a_hard_push_is_a_fall_and_the_failure_stays_latched(world: World) -> None:
    detector = FailureDetector(world)
    # Backwards, away from the table, 1000 N on the torso for 0.3 s.
    failure = _drive(world, detector, [(2.0, {})], each_step=_push(world, (-1000.0, 0.0, 0.0), 0.3))
    print(failure)
    assert failure is not None and failure.mode == "fall"
    assert 0.1 < failure.time < 1.0
    assert "tilted" in failure.detail and "deg" in failure.detail and " m " in failure.detail
    tilt = math.degrees(math.acos(world.data.xmat[world.ids.torso_body][8]))
    assert tilt > 30.0  # independent of the detector: the torso really is past the limit
    _hold(world, detector, 0.5)  # it keeps falling; the first failure is what is reported
    assert detector.check() is failure and detector.failure is failure


def test_a_fall_is_also_seen_by_the_pelvis_height_and_by_a_body_on_the_floor(world: World) -> None:
    # Only the height criterion: tilt limit out of reach.
    by_height = FailureDetector(world, DetectorThresholds(trunk_tilt_deg=179.0))
    failure = _drive(world, by_height, [(3.0, {})], each_step=_push(world, (-1000.0, 0.0, 0.0), 0.3))
    assert failure is not None and failure.mode == "fall" and "below standing" in failure.detail
    # The limit is the safe posture's (executive.robot.posture), measured from the standing keyframe.
    posture = world.profile.safe_posture
    assert by_height.pelvis_drop == posture.max_pelvis_drop + posture.pelvis_tolerance
    assert world.data.xpos[world.ids.base_body][2] < by_height.standing_height - by_height.pelvis_drop
    # Only the floor contact: height and tilt limits out of reach.
    world.reset()
    by_floor = FailureDetector(world, DetectorThresholds(trunk_tilt_deg=179.0, pelvis_drop=5.0))
    failure = _drive(world, by_floor, [(4.0, {})], each_step=_push(world, (-1000.0, 0.0, 0.0), 0.3))
    print(failure)
    assert failure is not None and failure.mode == "fall"
    assert failure.bodies[1] == "floor" and "sole" not in failure.bodies[0]
    assert failure.force >= 1.0 and "touched the floor" in failure.detail


# --- 4. drop --------------------------------------------------------------------------------


def test_a_carried_book_teleported_away_from_the_hand_is_a_drop(world: World) -> None:
    ctrl = _grasp_book_in_left_hand(world)
    detector = FailureDetector(world)
    detector.set_phase(carried=("left", "book"))
    _hold(world, detector, 0.5, ctrl)  # a real grasp: held, no failure
    assert detector.failure is None
    site = world.data.site_xpos[world.ids.hand_sites["left"]].copy()
    _move_book(world, site + np.array([0.0, 0.3, 0.0]))
    failure = detector.check()
    print(failure)
    assert failure is not None and failure.mode == "drop"
    # 0.3 m from the site to the centre, minus the book's half width (5.5 cm) to its surface.
    assert "0.245 m" in failure.detail and "left hand" in failure.detail


def test_a_book_falling_to_the_floor_is_a_drop(world: World) -> None:
    _move_book(world, (0.6, 0.9, 0.9))  # beside the table (its top spans y = +-0.65)
    detector = FailureDetector(world)
    failure = _drive(world, detector, [(1.0, {})])
    assert failure is not None and failure.mode == "drop"
    assert failure.bodies == ("book", "floor") and failure.force >= 1.0
    # Free fall of 0.9 m minus the half thickness: about sqrt(2 * 0.875 / 9.81) = 0.42 s.
    assert failure.time == pytest.approx(math.sqrt(2 * 0.875 / 9.81), abs=0.02)


def test_check_placed_measures_the_distance_and_yaw_to_the_target(world: World) -> None:
    detector = FailureDetector(world)
    _hold(world, detector, 0.3)  # the book settles on the table
    x, y = (float(v) for v in world.data.xpos[world.ids.object_bodies["book"]][:2])
    assert detector.check_placed("book", (x, y)) is None
    assert detector.check_placed("book", (x, y), target_yaw=0.0) is None
    off = detector.check_placed("book", (x, y - 0.05))
    print(off)
    assert off is not None and off.mode == "drop" and "0.050 m from its target" in off.detail
    assert detector.failure is off  # latched as the outcome
    yawed = detector.check_placed("book", (x, y), target_yaw=math.radians(20.0))
    assert yawed is not None and "yaw off by 20.0 deg" in yawed.detail
    assert detector.check_placed("book", (x, y)) is None  # the latched failure does not leak in
    # A half turn: wrong for an object whose yaw matters, the same pose for a half-turn-symmetric one.
    turned = detector.check_placed("book", (x, y), target_yaw=math.radians(178.0))
    assert turned is not None and "yaw off by 178.0 deg" in turned.detail
    assert detector.check_placed("book", (x, y), target_yaw=math.radians(178.0), yaw_symmetry=2) is None
    assert "yaw off by 20.0 deg" in str(
        detector.check_placed("book", (x, y), target_yaw=math.radians(200.0), yaw_symmetry=2)
    )
    with pytest.raises(DetectorError, match="objects: book"):
        detector.check_placed("cup", (x, y))


def test_check_placed_fails_while_the_book_is_in_the_air(world: World) -> None:
    _move_book(world, (0.6, 0.9, 0.9))
    detector = FailureDetector(world)
    _hold(world, detector, 0.1)
    failure = detector.check_placed("book", (0.6, 0.9))
    assert failure is not None and "not on the table" in failure.detail and "still moving" in failure.detail


# --- 5. unstable ----------------------------------------------------------------------------


@pytest.mark.parametrize("value", [math.nan, 1e6])
def test_a_bad_velocity_is_unstable(world: World, value: float) -> None:
    detector = FailureDetector(world)
    _hold(world, detector, 0.1)
    world.data.qvel[20] = value
    failure = detector.check()
    print(failure)
    assert failure is not None and failure.mode == "unstable"
    assert (
        "qvel[20]" in failure.detail and world.model.joint(world.model.dof_jntid[20]).name in failure.detail
    )


def test_real_mujoco_warnings_are_unstable(world: World) -> None:
    m, d = world.model, world.data
    # NaN velocity, then a real step: MuJoCo warns (BADQVEL) and auto-resets the data, so the
    # state is finite again and only the warning counter still shows it.
    detector = FailureDetector(world)
    d.qvel[20] = math.nan
    mujoco.mj_step(m, d)
    assert np.isfinite(d.qvel).all()
    failure = detector.check()
    assert failure is not None and failure.mode == "unstable" and "mjWARN_BADQVEL" in failure.detail
    # NaN control: MuJoCo warns (BADCTRL) and zeroes the controls; physics goes on, finite.
    world.reset()
    detector = FailureDetector(world)
    d.ctrl[:] = world.home_ctrl()
    d.ctrl[3] = math.nan
    mujoco.mj_step(m, d)
    assert np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()
    failure = detector.check()
    assert failure is not None and "mjWARN_BADCTRL" in failure.detail


# --- 6. allowed contacts --------------------------------------------------------------------


def test_a_real_grasp_is_allowed_while_carrying_but_a_collision_without_a_phase(world: World) -> None:
    ctrl = _grasp_book_in_left_hand(world)
    carrying = FailureDetector(world)
    carrying.set_phase(carried=("left", "book"))
    _hold(world, carrying, 1.0, ctrl)
    assert carrying.failure is None
    pads = {world.model.body(world.model.geom_bodyid[g]).name for g in _touching(world, "book")}
    assert pads == {"left_finger_a", "left_finger_b"}  # the book really is squeezed by the jaws
    nobody = FailureDetector(world)
    _hold(world, nobody, 0.01, ctrl)
    failure = nobody.failure
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies[0] in pads and failure.bodies[1] == "book"


def _touching(world: World, geom_name: str) -> set[int]:
    d = world.data
    g = world.model.geom(geom_name).id
    return {int(c.geom1 if c.geom2 == g else c.geom2) for c in d.contact[: d.ncon] if g in (c.geom1, c.geom2)}


def test_fingers_on_the_book_are_allowed_while_grasping_it(world: World) -> None:
    grasping = FailureDetector(world)
    grasping.set_phase(grasping=("left", "book"))
    assert _drive(world, grasping, _down_onto_book("left")) is None
    touched = {world.model.body(world.model.geom_bodyid[g]).name for g in _touching(world, "book")}
    assert touched & {"left_finger_a", "left_finger_b"}  # the contact did happen
    world.reset()
    other_hand = FailureDetector(world)
    other_hand.set_phase(grasping=("right", "book"))  # the wrong side
    failure = _drive(world, other_hand, _down_onto_book("left"))
    assert failure is not None and failure.mode == "collision" and failure.bodies[1] == "book"
    world.reset()
    no_phase = FailureDetector(world)
    failure = _drive(world, no_phase, _down_onto_book("left"))
    print(failure)
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies[0].startswith("left_") and failure.bodies[1] == "book"


def test_jaws_landing_on_the_book_they_approach_are_a_misaligned_grasp(world: World) -> None:
    """Closed jaws driven down onto the book while approaching to grasp it: a drop (the grasp
    missed), not a collision; the same motion approaching with the other hand is a collision."""
    approaching = FailureDetector(world)
    approaching.set_phase(approaching=("left", "book"))
    failure = _drive(world, approaching, _down_onto_book("left"))
    print(failure)
    assert failure is not None and failure.mode == "drop" and "misaligned grasp" in failure.detail
    assert failure.bodies[0].startswith("left_") and failure.bodies[1] == "book"
    assert failure.force >= 1.0
    world.reset()
    other = FailureDetector(world)
    other.set_phase(approaching=("right", "book"))
    failure = _drive(world, other, _down_onto_book("left"))
    assert failure is not None and failure.mode == "collision" and failure.bodies[1] == "book"


def test_set_phase_names_the_valid_choices(world: World) -> None:
    detector = FailureDetector(world)
    with pytest.raises(DetectorError, match="left, right"):
        detector.set_phase(carried=("middle", "book"))
    with pytest.raises(DetectorError, match="objects: book"):
        detector.set_phase(grasping=("left", "cup"))


# --- 7. cost --------------------------------------------------------------------------------


def test_check_costs_less_than_a_physics_step(world: World) -> None:
    m, d = world.model, world.data
    detector = FailureDetector(world)
    ctrl = world.home_ctrl()
    n = 1500
    step_time = check_time = 0.0
    for _ in range(n):
        d.ctrl[:] = ctrl
        t0 = time.perf_counter()
        mujoco.mj_step(m, d)
        t1 = time.perf_counter()
        detector.check()
        check_time += time.perf_counter() - t1
        step_time += t1 - t0
    print(f"mj_step {step_time / n * 1e6:.1f} us, check() {check_time / n * 1e6:.1f} us per call")
    assert check_time < step_time


def test_a_carried_object_may_touch_the_table_only_while_being_placed(world: World) -> None:
    # The book rests on the table with its weight (0.6 kg: 5.9 N). Declared carried (the hold
    # distance relaxed: no hand is near it), that contact is a collision; declared being
    # placed, it is not.
    relaxed = DetectorThresholds(hold_distance=1.0)
    carried = FailureDetector(world, relaxed)
    _hold(world, carried, 0.3)  # resting on the table, carried by nobody: allowed
    assert carried.failure is None
    carried.set_phase(carried=("left", "book"))
    _hold(world, carried, 0.01)
    failure = carried.failure
    assert failure is not None and failure.mode == "collision"
    assert failure.bodies == ("book", "table")
    assert failure.force == pytest.approx(0.6 * 9.81, rel=0.05)
    world.reset()
    placing = FailureDetector(world, relaxed)
    placing.set_phase(carried=("left", "book"), placing="book")
    _hold(world, placing, 0.5)
    assert placing.failure is None
    assert placing.phase == {
        "carried": ("left", "book"),
        "grasping": None,
        "placing": "book",
        "approaching": None,
        "pushing": None,
        "support": None,
    }


def test_a_new_phase_reclassifies_contacts_that_did_not_change(world: World) -> None:
    """The same jaws on the same book, step after step: allowed while carrying, a collision at the
    very next step once the phase no longer allows it (nothing about the contacts changed)."""
    ctrl = _grasp_book_in_left_hand(world)
    detector = FailureDetector(world)
    detector.set_phase(carried=("left", "book"))
    _hold(world, detector, 0.5, ctrl)
    assert detector.failure is None
    before = world.data.contact.geom.copy()
    detector.set_phase()  # nobody holds it now
    _hold(world, detector, world.model.opt.timestep, ctrl)  # one physics step
    assert np.array_equal(world.data.contact.geom, before)  # the very same contact pairs
    failure = detector.failure
    assert failure is not None and failure.mode == "collision" and failure.bodies[1] == "book"
