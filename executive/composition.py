"""Expanding a task into alternative behaviour sequences, planning them, building their subtrees.

A ``transfer`` task for a two-armed robot can be done four ways (seed study,
section "Total risk"): ``left`` (pick and place with the left hand), ``right``,
``left_to_right`` (pick left, hand over, place right) and ``right_to_left``.
Each alternative is a list of :class:`Step` values (hand targets computed from
the *estimate* of the scene), planned step after step with the whole-body
planner into an :class:`AlternativePlan`, and turned into a py_trees Sequence.

Grasp geometry: top-down, the jaws closing across the object's local y
extent; a one-hand grasp at the object's centre, a handover grasp at the two
ends of the object's local x axis (``handover_offset`` either side), so both
hands fit side by side. Of the two ways to close across the object, a hand
takes the one nearer its profile's ``closing_yaw`` (a hand with a thumb on one
side, such as the G1's Dex3), else the one nearer its home pose's.

After placing, a hand goes home keeping clear of the object it placed; on a
robot whose profile sets ``return_along_lane``, a hand that placed across the
body first goes back along the lane to its own side.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import mujoco
import numpy as np
import py_trees
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.grasp_geometry import check_grasp
from executive.planning import HandTarget, Planner, PlanningError, Trajectory
from executive.planning_types import site_quat
from executive.scenario_types import ALTERNATIVES, TransferTask
from executive.world import World

__all__ = [
    "AlternativePlan",
    "CompositionConfig",
    "Step",
    "build_subtree",
    "check_grasps",
    "plan_alternative",
    "transfer_steps",
    "yaw_of",
]

FloatArray = NDArray[np.float64]
StepKind = Literal["move", "lift", "carry", "place", "retreat", "home", "grasp", "release"]


@dataclass(frozen=True)
class CompositionConfig:
    """Geometry of the waypoints (metres)."""

    approach_height: float = 0.10  # pre-grasp / pre-place above the grasp pose
    lift_height: float = 0.12  # lift above the grasp pose
    grip_depth: float = 0.01  # hand site below the object's top face
    handover_offset: float = 0.06  # grasp points either side of the object's centre
    handover_point: tuple[float, float] = (0.30, 0.0)  # object centre x y at the handover
    handover_height: float = 0.20  # object centre above the table top at the handover
    giver_end: int = -1  # the end of the object's x axis the giver grasps (+1 or -1)
    turn_point: tuple[float, float] | None = None  # object centre x y after the receiver's turn
    receiver_turn_steps: int = 1  # the receiver's turn to the place yaw, in this many moves
    giver_turn_steps: int = 1  # the giver's quarter turn to the handover, in this many moves
    handover_side: float = 0.10  # the receiver rises this far out on its side of the handover
    obstacle_clearance: float = 0.07  # how close a one-arm carry skirts the obstacles' front


@dataclass(frozen=True)
class Step:
    kind: StepKind
    name: str
    side: str
    targets: tuple[HandTarget, ...] = ()
    carried: tuple[str, str] | None = None
    allow_contact: tuple[str, ...] = ()
    obj: str = ""


@dataclass(frozen=True)
class AlternativePlan:
    """An alternative planned on the estimate: its steps and one trajectory per motion step."""

    name: str
    task: TransferTask
    steps: tuple[Step, ...]
    trajectories: dict[str, Trajectory] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return sum(t.duration for t in self.trajectories.values())

    def ordered_trajectories(self) -> list[Trajectory]:
        return [self.trajectories[s.name] for s in self.steps if s.name in self.trajectories]


def _top_down_quat(yaw: float) -> FloatArray:
    """Hand site frame with +z down and +y (closing) along the horizontal direction at ``yaw``."""
    y_axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    z_axis = np.array([0.0, 0.0, -1.0])
    x_axis = np.cross(y_axis, z_axis)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).ravel())
    return quat


def yaw_of(quat: FloatArray) -> float:
    """The z-y-x Euler yaw of a unit quaternion (w x y z)."""
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _home_targets(world: World) -> dict[str, HandTarget]:
    """Hand site poses at the robot's home keyframe."""
    data = mujoco.MjData(world.model)
    mujoco.mj_resetDataKeyframe(world.model, data, world.ids.keyframe)
    mujoco.mj_kinematics(world.model, data)
    out = {}
    for side, site in world.ids.hand_sites.items():
        out[side] = HandTarget(side, data.site_xpos[site].copy(), site_quat(data, site))
    return out


def _home_base(world: World) -> tuple[FloatArray, float]:
    """Position of the robot's base and yaw of its forward direction (base x) at the home keyframe."""
    data = mujoco.MjData(world.model)
    mujoco.mj_resetDataKeyframe(world.model, data, world.ids.keyframe)
    mujoco.mj_kinematics(world.model, data)
    mat = data.xmat[world.ids.base_body]
    return data.xpos[world.ids.base_body].copy(), float(np.arctan2(mat[3], mat[0]))


def transfer_steps(
    world: World, task: TransferTask, alternative: str, config: CompositionConfig | None = None
) -> list[Step]:
    """The steps of one alternative of a transfer task, with targets from the estimate world."""
    cfg = config or CompositionConfig()
    sides = world.profile.sides
    if alternative not in ALTERNATIVES:
        raise ExecutiveError(f"unknown alternative '{alternative}'; valid: {', '.join(ALTERNATIVES)}")
    if "left" not in sides or "right" not in sides:
        raise ExecutiveError(f"robot '{world.profile.name}' needs a left and a right arm for '{alternative}'")
    scene = world.scenario.scene
    body = next(b for b in scene.objects if b.name == task.object)
    obj = body.name
    pos, quat = world.object_pose(obj)
    yaw = yaw_of(quat)
    top = pos[2] + body.half_height()
    grasp_z = max(pos[2], top - cfg.grip_depth)
    site_above_centre = grasp_z - pos[2]
    target_z = task.to[2] if task.to[2] is not None else scene.table.height + body.half_height()
    place_yaw = task.to_yaw_rad if task.to_yaw_rad is not None else yaw
    axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    up = np.array([0.0, 0.0, 1.0])
    home = _home_targets(world)
    base, heading = _home_base(world)
    left_of_base = np.array([-np.sin(heading), np.cos(heading), 0.0])

    def side_of_body(point: FloatArray) -> float:
        """+1 left of the robot's midline, -1 right of it."""
        return 1.0 if float(np.dot(np.asarray(point) - base, left_of_base)) >= 0.0 else -1.0

    def closing_near_home(side: str, hand_yaw: float) -> float:
        # Of the two closing directions across an object at hand_yaw, take the one nearer the
        # preferred: the profile's closing_yaw (a hand with a thumb on one side), else the home
        # pose's (symmetric jaws).
        preferred = world.profile.arms[side].hand.closing_yaw_deg
        if preferred is None:
            mat = np.zeros(9)
            mujoco.mju_quat2Mat(mat, home[side].quat)
            want = float(np.arctan2(mat[4], mat[1]))  # yaw of the home frame's y (closing) axis
        else:
            want = heading + float(np.radians(preferred))
        closing = hand_yaw + np.pi / 2
        return closing + np.pi if np.cos(closing - want) < 0 else closing

    def target(side: str, point: FloatArray, hand_yaw: float, grasp_yaw: float | None = None) -> HandTarget:
        """Top-down hand target whose jaws close across an object at ``hand_yaw``.

        ``grasp_yaw``: the object's yaw when this hand grasped it. A hand that holds (or has just
        released) an object turns it with itself, so its closing direction is the grasp's
        turned by the object's change of yaw, not whichever of the two is nearer home.
        """
        if grasp_yaw is None:
            closing = closing_near_home(side, hand_yaw)
        else:
            closing = closing_near_home(side, grasp_yaw) + (hand_yaw - grasp_yaw)
        return HandTarget(side, np.asarray(point, dtype=float), _top_down_quat(closing))

    # Obstacle front: the carry skirts the nearest obstacle face at obstacle_clearance.
    front_x = min(
        (o.position[0] - (o.size[0] / 2 if o.shape == "box" else o.size[0]) for o in scene.obstacles),
        default=pos[0],
    )
    length = body.size[0] if body.shape == "box" else 2 * body.size[0]

    if alternative in ("left", "right"):
        # Straight, simple hand paths: up, back to the lane in front of the obstacles, across the
        # body in that lane (the carried object skirting the obstacles' front at
        # obstacle_clearance: the one-arm alternatives' risk), forward over the place, down.
        s = alternative
        grasp = np.array([pos[0], pos[1], grasp_z])
        place = np.array([task.to[0], task.to[1], target_z + site_above_centre])
        lift_z = grasp[2] + cfg.lift_height
        carry_z = max(lift_z, place[2] + cfg.approach_height)
        lane_x = min(front_x - cfg.obstacle_clearance - length / 2, grasp[0], place[0])
        carry_yaw = (yaw + place_yaw) / 2
        lane_in = np.array([lane_x, grasp[1], carry_z])
        lane_out = np.array([lane_x, place[1], carry_z])
        carried = (s, obj)
        # A hand that placed the object across the body first goes back along the lane to its own
        # side, as it is (the retreat's orientation), and only then turns home: the straight way
        # home from across the body swings the arm across the body's front while the hand turns,
        # and the IK may bring it home in another arm configuration, with the waist still bent.
        go_back: list[Step] = []
        if world.profile.return_along_lane and side_of_body(place) != side_of_body(home[s].position):
            back_point = np.array([lane_x, home[s].position[1], carry_z])
            go_back.append(Step("move", f"{s}.back", s, (target(s, back_point, place_yaw, yaw),)))
        return [
            Step("move", f"{s}.pre_grasp", s, (target(s, grasp + cfg.approach_height * up, yaw),)),
            Step("move", f"{s}.approach", s, (target(s, grasp, yaw),), allow_contact=(obj,)),
            Step("grasp", f"{s}.grasp", s, obj=obj),
            Step(
                "lift", f"{s}.lift", s, (target(s, grasp + cfg.lift_height * up, yaw, yaw),), carried=carried
            ),
            Step("carry", f"{s}.to_lane", s, (target(s, lane_in, carry_yaw, yaw),), carried=carried),
            Step("carry", f"{s}.transfer", s, (target(s, lane_out, carry_yaw, yaw),), carried=carried),
            Step(
                "carry",
                f"{s}.pre_place",
                s,
                (target(s, place + cfg.approach_height * up, place_yaw, yaw),),
                carried=carried,
            ),
            Step(
                "place",
                f"{s}.place",
                s,
                (target(s, place, place_yaw, yaw),),
                carried=carried,
                allow_contact=("table_top",),
            ),
            Step("release", f"{s}.release", s, obj=obj),
            Step(
                "retreat",
                f"{s}.retreat",
                s,
                (target(s, place + cfg.approach_height * up, place_yaw, yaw),),
                allow_contact=(obj,),
            ),
            *go_back,
            # The way home keeps clear of the object just placed (a hand that rotates back to its
            # home pose can sweep its fingers into it); brushing it is tolerated (obj).
            Step("home", f"{s}.home", s, (home[s],), obj=obj),
        ]

    giver, receiver = alternative.split("_to_")
    if body.yaw_symmetry % 2:
        # Each top-down hand's forearm lies along the object's long axis (its jaws close across
        # the width). Both hands take and leave the object forearm-forward, and at the handover
        # the two forearms point at each other from its two ends, so the object turns a half turn
        # in all: only an object unchanged by a half turn about the vertical can be handed over.
        raise PlanningError(
            alternative,
            None,
            0.0,
            float(np.pi),
            0,
            reason=(
                f"a top-down handover turns '{obj}' a half turn about the vertical, and its yaw "
                f"matters (yaw_symmetry {body.yaw_symmetry}); declare yaw_symmetry: 2 for an object "
                "a half turn leaves unchanged"
            ),
        )
    d = cfg.handover_offset
    # The giver holds the object's +x end (giver_end = 1) or its -x end (-1), the receiver the other.
    e = 1.0 if cfg.giver_end > 0 else -1.0
    grasp_g = np.array([*(pos[:2] + e * d * axis[:2]), grasp_z])
    hx, hy = cfg.handover_point
    h_centre = np.array([hx, hy, scene.table.height + cfg.handover_height + body.half_height()])
    # At the handover the object lies across the body, the giver's end on the giver's side, so
    # the hands meet side by side, each forearm coming from its own shoulder. The giver turns it
    # by the shortest way that puts its end on its own side (a quarter turn for an object lying
    # along x; for the left giver holding the -x end, clockwise: its forearm swings out to its side).
    side_dir = np.array([0.0, 1.0 if giver == "left" else -1.0, 0.0])
    h_yaw = float(np.arctan2(e * side_dir[1], 0.0))
    hand_g = h_centre + d * side_dir + site_above_centre * up
    hand_r = h_centre - d * side_dir + site_above_centre * up
    # While one hand holds the object at the handover and the other moves, the holding hand is
    # kept where it is (an idle arm would move with the torso and carry the object away).
    hold_g = target(giver, hand_g, h_yaw, yaw)
    hold_r = target(receiver, hand_r, h_yaw)
    # The giver turns the object in giver_turn_steps equal parts on the way (shortest turn).
    lift_g = grasp_g + cfg.lift_height * up
    back_g = np.array([hx + e * d * axis[0], lift_g[1], max(lift_g[2], hand_g[2])])
    turn_g = float(np.remainder(h_yaw - yaw + np.pi, 2 * np.pi) - np.pi)
    n_turn = max(1, cfg.giver_turn_steps)
    # The receiver's wrist turns back the natural way (its closing direction ends nearer its home
    # pose's). With both wrists turning naturally the object ends a half turn from place_yaw: the
    # same pose for an object with an even yaw_symmetry (checked above).
    back = float(
        np.remainder(
            closing_near_home(receiver, place_yaw) - closing_near_home(receiver, h_yaw) + np.pi, 2 * np.pi
        )
        - np.pi
    )
    final_yaw = h_yaw + back
    final_axis = np.array([np.cos(final_yaw), np.sin(final_yaw), 0.0])
    n_back = max(1, cfg.receiver_turn_steps)
    place_r = np.array([*(np.array(task.to[:2]) - e * d * final_axis[:2]), target_z + site_above_centre])
    # After the handover the receiver turns the object to its place yaw in front of the body,
    # already over the place's y (far from the obstacles), then carries it straight out over the
    # place and sets it down.
    tx, ty = cfg.turn_point if cfg.turn_point is not None else (h_centre[0], float(task.to[1]))
    turn_r = np.array(
        [tx - e * d * final_axis[0], ty - e * d * final_axis[1], h_centre[2] + site_above_centre]
    )
    return [
        Step("move", f"{giver}.pre_grasp", giver, (target(giver, grasp_g + cfg.approach_height * up, yaw),)),
        Step("move", f"{giver}.approach", giver, (target(giver, grasp_g, yaw),), allow_contact=(obj,)),
        Step("grasp", f"{giver}.grasp", giver, obj=obj),
        Step(
            "lift",
            f"{giver}.lift",
            giver,
            (target(giver, grasp_g + cfg.lift_height * up, yaw, yaw),),
            carried=(giver, obj),
        ),
        # Back out of the table first (the object keeps its yaw), then across and turning: the
        # object's far end then sweeps well clear of the obstacles' front corner.
        Step(
            "carry",
            f"{giver}.back",
            giver,
            (target(giver, back_g, yaw, yaw),),
            carried=(giver, obj),
        ),
        *(
            Step(
                "carry",
                f"{giver}.turn{k}",
                giver,
                (target(giver, back_g + (hand_g - back_g) * k / n_turn, yaw + turn_g * k / n_turn, yaw),),
                carried=(giver, obj),
            )
            for k in range(1, n_turn)
        ),
        Step(
            "carry", f"{giver}.to_handover", giver, (target(giver, hand_g, h_yaw, yaw),), carried=(giver, obj)
        ),
        # The receiver rises on its own side first and comes over its end of the object from
        # above (a straight reach from its side would sweep low past the object's end).
        Step(
            "move",
            f"{receiver}.rise",
            receiver,
            (
                target(receiver, hand_r - cfg.handover_side * side_dir + cfg.approach_height * up, h_yaw),
                hold_g,
            ),
            carried=(giver, obj),
        ),
        Step(
            "move",
            f"{receiver}.pre_handover",
            receiver,
            (target(receiver, hand_r + cfg.approach_height * up, h_yaw), hold_g),
            carried=(giver, obj),
        ),
        Step(
            "move",
            f"{receiver}.handover_approach",
            receiver,
            (target(receiver, hand_r, h_yaw), hold_g),
            carried=(giver, obj),
            allow_contact=(obj,),
        ),
        Step("grasp", f"{receiver}.grasp", receiver, obj=obj),
        Step("release", f"{giver}.release", giver, obj=obj),
        # The giver's open jaws leave straight up (a palm moving down and sideways would push
        # the object's end down and turn it in the receiver's grip), out to its side, then home.
        Step(
            "retreat",
            f"{giver}.retreat",
            giver,
            (target(giver, hand_g + cfg.approach_height * up, h_yaw, yaw), hold_r),
            carried=(receiver, obj),
            allow_contact=(obj,),
        ),
        Step(
            "move",
            f"{giver}.clear",
            giver,
            (
                target(giver, hand_g + cfg.handover_side * side_dir + cfg.approach_height * up, h_yaw, yaw),
                hold_r,
            ),
            carried=(receiver, obj),
        ),
        Step(
            "home",
            f"{giver}.home",
            giver,
            (home[giver], hold_r),
            carried=(receiver, obj),
            allow_contact=(obj,),
        ),
        *(
            Step(
                "carry",
                f"{receiver}.turn{k}",
                receiver,
                (
                    target(
                        receiver, hand_r + (turn_r - hand_r) * k / n_back, h_yaw + back * k / n_back, h_yaw
                    ),
                ),
                carried=(receiver, obj),
            )
            for k in range(1, n_back)
        ),
        Step(
            "carry",
            f"{receiver}.turn",
            receiver,
            (target(receiver, turn_r, final_yaw, h_yaw),),
            carried=(receiver, obj),
        ),
        Step(
            "carry",
            f"{receiver}.pre_place",
            receiver,
            (target(receiver, place_r + cfg.approach_height * up, final_yaw, h_yaw),),
            carried=(receiver, obj),
        ),
        Step(
            "place",
            f"{receiver}.place",
            receiver,
            (target(receiver, place_r, final_yaw, h_yaw),),
            carried=(receiver, obj),
            allow_contact=("table_top",),
        ),
        Step("release", f"{receiver}.release", receiver, obj=obj),
        Step(
            "retreat",
            f"{receiver}.retreat",
            receiver,
            (target(receiver, place_r + cfg.approach_height * up, final_yaw, h_yaw),),
            allow_contact=(obj,),
        ),
        Step("home", f"{receiver}.home", receiver, (home[receiver],), obj=obj),
    ]


def plan_alternative(
    planner: Planner,
    world: World,
    task: TransferTask,
    alternative: str,
    q_start: FloatArray | None = None,
    config: CompositionConfig | None = None,
) -> AlternativePlan:
    """Plan every motion step of an alternative in order, each from where the previous ended.

    Raises :class:`executive.planning.PlanningError` naming the step that cannot be reached,
    or (:class:`executive.grasp_geometry.GraspGeometryError`, before any planning) the grasp
    the hand cannot make: an object wider than the jaw opening, or too thin for the fingers
    to get round it above the table.
    """
    cfg = config or CompositionConfig()
    steps = transfer_steps(world, task, alternative, cfg)
    check_grasps(world, steps, planner.config.table_distance, cfg.grip_depth)
    q = np.array(world.home_qpos() if q_start is None else q_start, dtype=float)
    trajectories: dict[str, Trajectory] = {}
    for step in steps:
        if not step.targets:
            continue
        traj = planner.move(
            q,
            list(step.targets),
            name=step.name,
            carried=step.carried,
            allow_contact=step.allow_contact,
            rest=step.kind == "home",
        )
        trajectories[step.name] = traj
        q = traj.qpos[-1]
    return AlternativePlan(alternative, task, tuple(steps), trajectories)


def check_grasps(world: World, steps: list[Step], table_clearance: float, grip_depth: float) -> None:
    """The grasp geometry of every grasp of an alternative (:func:`executive.grasp_geometry.check_grasp`).

    The first grasp takes the object off the table: its site height above the table top is the
    approach's target; later grasps (a handover) are in the air, checked for width only.

    Raises:
        GraspGeometryError: the first grasp the hand cannot make, with the reason.
    """
    table = world.scenario.scene.table.height
    on_table = True
    for i, step in enumerate(steps):
        if step.kind != "grasp":
            continue
        approach = next(s for s in reversed(steps[:i]) if s.side == step.side and s.targets)
        site = next(t for t in approach.targets if t.side == step.side)
        check_grasp(
            world,
            step.side,
            step.obj,
            motion=approach.name,
            site_above_table=float(site.position[2]) - table if on_table else None,
            table_clearance=table_clearance,
            grip_depth=grip_depth,
        )
        on_table = False


def build_subtree(plan: AlternativePlan, *, guard: bool = False) -> py_trees.composites.Sequence:
    """The alternative as a py_trees Sequence of task-level behaviours (a handover is its own subtree).

    ``guard``: wrap every motion in a :class:`behaviours.guard.RiskGuard` (live risk checks,
    active when a monitor is on the blackboard).
    """
    from behaviours.gripper import Grasp, Release
    from behaviours.guard import RiskGuard
    from behaviours.handover import handover_subtree
    from behaviours.move_hand import Carry, Home, Lift, MoveHand, Place, Retreat

    movers = {
        "move": MoveHand,
        "lift": Lift,
        "carry": Carry,
        "place": Place,
        "retreat": Retreat,
        "home": Home,
    }
    children: list[py_trees.behaviour.Behaviour] = []
    steps = list(plan.steps)
    i = 0
    while i < len(steps):
        step = steps[i]
        if step.kind == "grasp" and i + 2 < len(steps) and steps[i + 1].kind == "release":
            # receiver grasps, giver releases, giver retreats: the handover
            release, retreat = steps[i + 1], steps[i + 2]
            children.append(
                handover_subtree(
                    f"{release.side}_to_{step.side}.handover",
                    giver=release.side,
                    receiver=step.side,
                    obj=step.obj,
                    retreat=plan.trajectories[retreat.name],
                )
            )
            i += 3
            continue
        if step.kind == "grasp":
            children.append(Grasp(step.name, step.side, step.obj))
        elif step.kind == "release":
            children.append(Release(step.name, step.side, step.obj))
        else:
            # After a release the open jaws may still brush the object they let go of.
            let_go = step.obj or (step.allow_contact[0] if step.allow_contact else "")
            touching = (step.side, let_go) if step.kind in ("retreat", "home") and let_go else None
            # The move onto a grasp: the open jaws must straddle the object, not land on it.
            after = steps[i + 1] if i + 1 < len(steps) else None
            onto_grasp = after is not None and after.kind == "grasp" and after.side == step.side
            approaching = (step.side, after.obj) if after is not None and onto_grasp else None
            mover = movers[step.kind](
                step.name, plan.trajectories[step.name], touching=touching or None, approaching=approaching
            )
            children.append(
                RiskGuard(
                    mover,
                    side=step.side,
                    kind=step.kind,
                    obj=plan.task.object,
                    allow_contact=step.allow_contact,
                )
                if guard
                else mover
            )
        i += 1
    return py_trees.composites.Sequence(name=plan.name, memory=True, children=children)
