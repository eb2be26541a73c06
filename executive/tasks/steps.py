"""Steps, planned alternatives and their subtrees: what every task kind builds on.

A task kind lays an alternative out as a list of :class:`Step` values (hand targets
computed from the *estimate* of the scene); :func:`plan_alternative` plans them one
after another with the whole-body planner into an :class:`AlternativePlan`, and
:func:`build_subtree` turns that into a py_trees Sequence (a handover is its own
subtree; every motion may be wrapped in a live risk guard).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import py_trees
from numpy.typing import NDArray

from executive.planning.planner import HandTarget, Planner, Trajectory
from executive.tasks.base import Task
from executive.tasks.grasp_geometry import check_grasp
from executive.world.model import World

__all__ = [
    "AlternativePlan",
    "CompositionConfig",
    "Step",
    "StepKind",
    "build_subtree",
    "check_grasps",
    "held_at_start",
    "plan_alternative",
]

FloatArray = NDArray[np.float64]
StepKind = Literal["move", "lift", "carry", "place", "retreat", "home", "grasp", "release", "push", "press"]


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
    """One step of an alternative: a motion of one hand (with the others' targets held) or a gripper action.

    ``carried``: (side, object) moved with that hand during the motion; ``allow_contact``: bodies the
    hand may touch; ``obj``: the object a grasp/release acts on (a home step: the one it keeps clear of);
    ``force``: the force (N, world frame) the hand exerts on the environment during a push or a press
    (the robot feels its reaction); ``hold_s``: how long a press keeps that force.
    """

    kind: StepKind
    name: str
    side: str
    targets: tuple[HandTarget, ...] = ()
    carried: tuple[str, str] | None = None
    allow_contact: tuple[str, ...] = ()
    obj: str = ""
    force: tuple[float, float, float] | None = None
    hold_s: float = 0.0


@dataclass(frozen=True)
class AlternativePlan:
    """An alternative planned on the estimate: its steps and one trajectory per motion step."""

    name: str
    task: Task
    steps: tuple[Step, ...]
    trajectories: dict[str, Trajectory] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Seconds as planned: the motions' and the holds of steps that keep a force (a press)."""
        return sum(t.duration for t in self.trajectories.values()) + sum(s.hold_s for s in self.steps)

    def ordered_trajectories(self) -> list[Trajectory]:
        return [self.trajectories[s.name] for s in self.steps if s.name in self.trajectories]


def plan_alternative(
    planner: Planner,
    world: World,
    task: Task,
    alternative: str,
    q_start: FloatArray | None = None,
    config: CompositionConfig | None = None,
) -> AlternativePlan:
    """Plan every motion step of an alternative in order, each from where the previous ended.

    Raises :class:`executive.planning.planner.PlanningError` naming the step that cannot be reached,
    or (:class:`executive.tasks.grasp_geometry.GraspGeometryError`, before any planning) the grasp
    the hand cannot make: an object wider than the jaw opening, or too thin for the fingers
    to get round it above the table.
    """
    cfg = config or CompositionConfig()
    from executive.tasks.registry import get

    steps = get(task.kind).steps(task, world, alternative, cfg)
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


def held_at_start(steps: tuple[Step, ...] | list[Step]) -> dict[str, str]:
    """The objects the hands hold when an alternative starts: side -> object.

    A hand holds an object from the start when it carries it in a motion before any grasp of
    that hand (a ``place`` after a ``pick``); a push moves its object without holding it.
    """
    held: dict[str, str] = {}
    grasped: set[str] = set()
    for step in steps:
        if step.kind == "grasp":
            grasped.add(step.side)
        elif step.carried is not None and step.kind != "push" and step.carried[0] not in grasped:
            held.setdefault(step.carried[0], step.carried[1])
    return held


def check_grasps(world: World, steps: list[Step], table_clearance: float, grip_depth: float) -> None:
    """The grasp geometry of every grasp of an alternative.

    Each is checked with :func:`executive.tasks.grasp_geometry.check_grasp`.

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
    from behaviours.push import Push

    movers = {
        "move": MoveHand,
        "lift": Lift,
        "carry": Carry,
        "place": Place,
        "retreat": Retreat,
        "home": Home,
        "push": Push,
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
            touching = (step.side, let_go) if step.kind in ("retreat", "home", "push") and let_go else None
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
