"""How far a foot can step (measured by IK), and a walk of steps to a goal stance.

:func:`measure_reach` asks the robot's own legs: from a stance it drives the swing foot along the
floor in each direction (forward, backward, outward, inward, and turning out and in) with the
stance foot fixed and the CoM over it, until the IK stops where the leg's kinematics, a joint
range, the pelvis height, the torso's tilt, the CoM margin or the legs' clearance binds
(:meth:`~executive.planning.stepping_planner.StepPlanner.probe`). :func:`plan_steps` walks to a
goal stance (a pelvis pose on the floor, the feet where they stand now relative to the pelvis),
alternating feet, each step's foothold within ``reach_fraction`` of that reach, each step planned
by :meth:`~executive.planning.stepping_planner.StepPlanner.plan_step`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from executive.planning.stepping_geometry import stance_footholds, stance_offsets
from executive.planning.stepping_ik import StepPlanningError
from executive.planning.stepping_planner import StepPlanner
from executive.planning.stepping_types import Foothold, StepPlan, StepReach

__all__ = ["from_relative", "measure_reach", "plan_steps", "relative"]

FloatArray = NDArray[np.float64]

#: A foot is at its goal within this distance (m) and turn (rad).
GOAL_DISTANCE = 0.005
GOAL_TURN = math.radians(1.0)
#: How often a step that does not plan is tried again half as long.
_RETRIES = 2
#: m of floor that a radian of turn weighs when choosing which foot leads.
_TURN_LENGTH = 0.1


def relative(stance: Foothold, foot: Foothold) -> tuple[float, float, float]:
    """``foot`` in ``stance``'s frame: (x forward, y left (m), yaw (rad))."""
    c, s = math.cos(stance.yaw), math.sin(stance.yaw)
    dx, dy = foot.x - stance.x, foot.y - stance.y
    return c * dx + s * dy, -s * dx + c * dy, math.remainder(foot.yaw - stance.yaw, 2.0 * math.pi)


def from_relative(stance: Foothold, side: str, pose: tuple[float, float, float]) -> Foothold:
    """The foothold of side ``side`` at ``pose`` (:func:`relative`) in ``stance``'s frame."""
    c, s = math.cos(stance.yaw), math.sin(stance.yaw)
    x, y, yaw = pose
    return Foothold(
        side,
        stance.x + c * x - s * y,
        stance.y + s * x + c * y,
        math.remainder(stance.yaw + yaw, 2 * math.pi),
    )


def measure_reach(planner: StepPlanner, q_start: FloatArray, side: str) -> StepReach:
    """How far the ``side`` foot can step from the stance of ``q_start``, measured by IK.

    Args:
        planner: the step planner of the world.
        q_start: the stance (both feet on the floor).
        side: the foot that steps.

    Returns:
        The reach in the six directions and what binds in each.

    Raises:
        StepPlanningError: when the weight shift onto the other foot fails.
    """
    start = planner.footholds(q_start)
    stance = start[next(s for s in planner.sides if s != side)]
    x0, y0, yaw0 = relative(stance, start[side])
    out = 1.0 if y0 >= 0.0 else -1.0  # the sign of "away from the stance foot" across it
    probe = planner.config.reach_probe
    directions = {
        "forward": (probe, 0.0, 0.0),
        "backward": (-probe, 0.0, 0.0),
        "outward": (0.0, out * probe, 0.0),
        "inward": (0.0, -out * probe, 0.0),
        "turn_out": (0.0, 0.0, out * probe),
        "turn_in": (0.0, 0.0, -out * probe),
    }
    amounts: dict[str, float] = {}
    binds: dict[str, str] = {}
    for name, (dx, dy, dyaw) in directions.items():
        goal = from_relative(stance, side, (x0 + dx, y0 + dy, yaw0 + dyaw))
        reached, held = planner.probe(q_start, side, goal)
        rx, ry, ryaw = relative(stance, reached)
        moved = np.array([rx - x0, ry - y0, math.remainder(ryaw - yaw0, 2 * math.pi)])
        unit = np.array([dx, dy, dyaw]) / probe
        amounts[name] = max(0.0, float(moved @ unit))
        binds[name] = "; ".join(held) if held else f"nothing up to the probe's end ({probe:g})"
    return StepReach(side, **amounts, binds=binds)


def _clip_target(
    reach: StepReach, fraction: float, nominal: tuple[float, float, float], wanted: tuple[float, float, float]
) -> tuple[float, float, float]:
    """``wanted`` (relative to the stance foot) clipped to ``fraction`` of ``reach`` about ``nominal``."""
    x0, y0, yaw0 = nominal
    out = 1.0 if y0 >= 0.0 else -1.0
    x = min(max(wanted[0], x0 - fraction * reach.backward), x0 + fraction * reach.forward)
    lateral = min(max(out * (wanted[1] - y0), -fraction * reach.inward), fraction * reach.outward)
    turn = out * math.remainder(wanted[2] - yaw0, 2 * math.pi)
    turn = min(max(turn, -fraction * reach.turn_in), fraction * reach.turn_out)
    return x, y0 + out * lateral, yaw0 + out * turn


def _at(foot: Foothold, goal: Foothold) -> bool:
    distance, turn = foot.distance(goal)
    return distance <= GOAL_DISTANCE and turn <= GOAL_TURN


def _first_foot(planner: StepPlanner, feet: dict[str, Foothold], goals: dict[str, Foothold]) -> str:
    """The foot that leads: the one whose goal lies more outward (away from the other foot, or
    turning its toes away), else the one farther from its goal, else the profile's first."""

    def score(side: str) -> tuple[float, float]:
        other = feet[next(s for s in planner.sides if s != side)]
        _, y0, yaw0 = relative(other, feet[side])
        _, y1, yaw1 = relative(other, goals[side])
        out = 1.0 if y0 >= 0.0 else -1.0
        outward = out * (y1 - y0) + _TURN_LENGTH * out * math.remainder(yaw1 - yaw0, 2 * math.pi)
        distance, turn = feet[side].distance(goals[side])
        return round(outward, 3), distance + _TURN_LENGTH * turn

    return max(planner.sides, key=score)


def plan_steps(
    planner: StepPlanner,
    q_start: FloatArray,
    goal: tuple[float, float, float],
    first: str | None = None,
    max_steps: int = 12,
) -> list[StepPlan]:
    """Steps from ``q_start`` to the stance whose pelvis stands at ``goal`` (x, y, yaw).

    The goal's footholds keep the feet where they stand now relative to the pelvis. The feet
    alternate (a foot already at its goal is skipped); each step's foothold is the foot's goal
    clipped to ``config.reach_fraction`` of the reach measured from ``q_start``
    (:func:`measure_reach`) about where it stood relative to the other foot there.

    Args:
        planner: the step planner of the world.
        q_start: the start stance (both feet on the floor).
        goal: the pelvis's goal on the floor: x, y (m), yaw (rad).
        first: the foot that steps first (None: the one whose goal lies more outward).
        max_steps: the most steps before giving up.

    Returns:
        The steps' plans, in order; each starts where the last ends (``final_qpos``). Empty when
        the feet are at the goal already.

    Raises:
        StepPlanningError: when a step cannot be planned, a foot can make no progress, or the
            goal is not reached in ``max_steps`` steps.
    """
    start = planner.footholds(q_start)
    px, py, pyaw = planner.pelvis(q_start)
    goals = stance_footholds(*goal, stance_offsets(np.array([px, py]), pyaw, start))
    reach = {side: measure_reach(planner, q_start, side) for side in planner.sides}
    nominal = {side: relative(start[_other(planner, side)], start[side]) for side in planner.sides}
    feet, q = dict(start), np.array(q_start, dtype=float)
    swing = first if first is not None else _first_foot(planner, feet, goals)
    plans: list[StepPlan] = []
    while not all(_at(feet[s], goals[s]) for s in planner.sides):
        if len(plans) >= max_steps:
            left = ", ".join(f"{s} foot {feet[s].distance(goals[s])[0] * 1000:.0f} mm" for s in planner.sides)
            raise StepPlanningError(
                "walk", f"the goal stance is not reached in {max_steps} steps ({left} from it)"
            )
        if _at(feet[swing], goals[swing]):
            swing = _other(planner, swing)
        stance = feet[_other(planner, swing)]
        wanted = relative(stance, goals[swing])
        pose = _clip_target(reach[swing], planner.config.reach_fraction, nominal[swing], wanted)
        target = from_relative(stance, swing, pose)
        if _at(target, feet[swing]):
            raise StepPlanningError(
                "walk",
                f"the {swing} foot can make no progress towards {goals[swing].describe()}: its reach "
                f"from the {stance.side} foot ends where it stands ({reach[swing]})",
            )
        plan = _step_within(planner, q, swing, feet[swing], target)
        plans.append(plan)
        feet, q = dict(plan.footholds), plan.final_qpos
        swing = _other(planner, swing)
    return plans


def _step_within(
    planner: StepPlanner, q: FloatArray, swing: str, now: Foothold, target: Foothold
) -> StepPlan:
    """:meth:`StepPlanner.plan_step` to ``target``, or, should that fail (the reach was measured
    from the start stance, and on the floor: a step must also lift and land), to targets half as
    far from ``now`` (:data:`_RETRIES` times); the first failure is raised when none plans."""
    first: StepPlanningError | None = None
    for k in range(_RETRIES + 1):
        f = 0.5**k
        turn = math.remainder(target.yaw - now.yaw, 2 * math.pi)
        aim = Foothold(
            swing, now.x + f * (target.x - now.x), now.y + f * (target.y - now.y), now.yaw + f * turn
        )
        try:
            return planner.plan_step(q, swing, aim)
        except StepPlanningError as exc:
            first = first or exc
    assert first is not None
    raise first


def _other(planner: StepPlanner, side: str) -> str:
    return next(s for s in planner.sides if s != side)
