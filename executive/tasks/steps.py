"""Planning a task's alternative step after step, and building its behaviour subtree.

:func:`plan_alternative` asks the task's kind for the alternative's steps
(:class:`executive.planning.plan.Step`), checks their grasps, and plans them one
after another with the whole-body planner into an
:class:`executive.planning.plan.AlternativePlan`; :func:`build_subtree` turns that
into a py_trees Sequence (a handover is its own subtree; every motion may be
wrapped in a live risk guard).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import py_trees
from numpy.typing import NDArray

from executive.planning.plan import AlternativePlan, CompositionConfig, Step
from executive.planning.planner import Planner, Trajectory
from executive.tasks.base import Task
from executive.tasks.grasp_geometry import check_grasp
from executive.world.model import World

__all__ = ["build_subtree", "check_grasps", "plan_alternative"]

FloatArray = NDArray[np.float64]


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


def build_subtree(
    plan: AlternativePlan,
    *,
    guard: bool = False,
    make: Mapping[str, Callable[[Step], py_trees.behaviour.Behaviour]] | None = None,
) -> py_trees.composites.Sequence:
    """The alternative as a py_trees Sequence of task-level behaviours (a handover is its own subtree).

    ``guard``: wrap every motion in a :class:`behaviours.guard.RiskGuard` (live risk checks,
    active when a monitor is on the blackboard). ``make``: a task kind's own behaviour for
    steps of a kind of its own (a press), by step kind.
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
        if make is not None and step.kind in make:
            children.append(make[step.kind](step))
            i += 1
            continue
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
