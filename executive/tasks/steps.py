"""Planning a task's alternative step after step.

:func:`plan_alternative` asks the task's kind for the alternative's steps
(:class:`executive.planning.plan.Step`), checks their grasps, and plans them one
after another with the whole-body planner into an
:class:`executive.planning.plan.AlternativePlan`; the kind's
:meth:`executive.tasks.base.TaskKind.subtree` turns that into behaviours
(by default :func:`executive.tasks.subtree.build_subtree`, also importable from here).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.planning.plan import AlternativePlan, CompositionConfig, Step
from executive.planning.planner import Planner, Trajectory
from executive.planning.stepping import StepPlan, StepPlanner, plan_steps
from executive.planning.timing import concatenate
from executive.tasks.base import Task
from executive.tasks.grasp_geometry import check_grasp
from executive.tasks.registry import get as task_kind
from executive.tasks.subtree import build_subtree
from executive.world.model import World

__all__ = ["build_subtree", "check_grasps", "plan_alternative", "plan_walk"]

FloatArray = NDArray[np.float64]
#: A hand whose approach axis is within this (1 - cos) of straight down grasps from above.
_ROUNDING = 1e-6


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
    steps = task_kind(task.kind).steps(task, world, alternative, cfg)
    check_grasps(world, steps, planner.config.table_distance, cfg.grip_depth)
    q = np.array(world.home_qpos() if q_start is None else q_start, dtype=float)
    trajectories: dict[str, Trajectory] = {}
    walks: dict[str, tuple[StepPlan, ...]] = {}
    for step in steps:
        if step.kind == "step":
            walk = walks[step.name] = plan_walk(planner, world, step, q)
            if walk:  # none: the feet stand at the goal already
                trajectories[step.name] = concatenate(
                    [p.trajectory for s in walk for p in s.phases], step.name
                )
                q = walk[-1].final_qpos
            continue
        if not step.targets:
            continue
        traj = planner.move(
            q,
            list(step.targets),
            name=step.name,
            carried=step.carried,
            allow_contact=step.allow_contact,
            rest=step.kind == "home",
            straight=step.straight,
        )
        trajectories[step.name] = traj
        q = traj.qpos[-1]
    return AlternativePlan(alternative, task, tuple(steps), trajectories, walks)


def plan_walk(planner: Planner, world: World, step: Step, q: FloatArray) -> tuple[StepPlan, ...]:
    """The footsteps of a ``step`` step from ``q``: to its ``stance``, ``step.side`` first, holding
    ``step.carried`` (if any) where its hand has it.

    Raises:
        StepPlanningError: a step the legs cannot make, or a goal not reached (naming what binds).
    """
    if step.stance is None:
        raise ValueError(f"step '{step.name}' has no stance to walk to")
    stepper = StepPlanner(world, planner_config=planner.config, problem=planner.problem, carried=step.carried)
    x, y, yaw = step.stance
    goal = (x, y, stepper.pelvis(q)[2] if yaw is None else yaw)
    return tuple(plan_steps(stepper, q, goal, first=step.side or None))


def check_grasps(world: World, steps: list[Step], table_clearance: float, grip_depth: float) -> None:
    """The grasp geometry of every grasp of an alternative.

    Each is checked with :func:`executive.tasks.grasp_geometry.check_grasp`.

    The first grasp takes the object off the table: its site height above the table top is the
    approach's target, the width the object's across the target's closing axis; a grasp that does
    not come straight down (:mod:`executive.tasks.grasp_candidates` laid it out clear of the table)
    is checked for width only. Later grasps (a handover) are in the air, checked for width only,
    across the object's y.

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
        closing, straight_down = (0.0, 1.0, 0.0), True
        if on_table:  # the object as it rests (in the air a handover has turned it: across its y)
            hand, obj = np.zeros(9), np.zeros(9)
            mujoco.mju_quat2Mat(hand, np.asarray(site.quat, dtype=float))
            mujoco.mju_quat2Mat(obj, world.object_pose(step.obj)[1])
            axis = obj.reshape(3, 3).T @ hand.reshape(3, 3)[:, 1]
            closing = (float(axis[0]), float(axis[1]), float(axis[2]))
            straight_down = float(hand[8]) < -1.0 + _ROUNDING
        check_grasp(
            world,
            step.side,
            step.obj,
            motion=approach.name,
            site_above_table=float(site.position[2]) - table if on_table and straight_down else None,
            table_clearance=table_clearance,
            grip_depth=grip_depth,
            closing_axis_object=closing,
        )
        on_table = False
