"""What a planned alternative is: its steps (hand targets, gripper actions) and their trajectories.

A task kind lays an alternative out as :class:`Step` values; the planner turns each
motion step into a trajectory; the result is an :class:`AlternativePlan`, which the
risk models assess and the behaviours execute.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from executive.planning.planner import HandTarget, Trajectory
from executive.planning.stepping import StepPlan
from executive.schema.types import Task

__all__ = [
    "MOVE_TOLERANCE",
    "AlternativePlan",
    "CompositionConfig",
    "Step",
    "StepKind",
    "held_at_end",
    "held_at_start",
]

FloatArray = NDArray[np.float64]

#: m: how far a hand may end a move from its planned end before the move fails with ``tracking``
#: (the tolerance of :class:`behaviours.move_hand.MoveHand`, which the tracking model predicts against).
MOVE_TOLERANCE = 0.03
StepKind = Literal[
    "move", "lift", "carry", "place", "retreat", "home", "grasp", "release", "push", "press", "step"
]


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
    ``stance``: a ``step`` (a walk, ``side`` the foot that leads): the pelvis's goal (x, y, yaw rad;
    yaw None: as it stands). ``straight``: the hand keeps to the straight line to its target, with
    no via points over what lies beside it (a contact motion: a push's legs stay on the object's
    face; :meth:`executive.planning.planner.Planner.move`).
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
    stance: tuple[float, float, float | None] | None = None
    straight: bool = False


@dataclass(frozen=True)
class AlternativePlan:
    """An alternative planned on the estimate: its steps and one trajectory per motion step.

    ``walks``: per ``step`` step, the planned footsteps (its trajectory is theirs end to end).
    """

    name: str
    task: Task
    steps: tuple[Step, ...]
    trajectories: dict[str, Trajectory] = field(default_factory=dict)
    walks: dict[str, tuple[StepPlan, ...]] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        """Seconds as planned: the motions' and the holds of steps that keep a force (a press)."""
        return sum(t.duration for t in self.trajectories.values()) + sum(s.hold_s for s in self.steps)

    def ordered_trajectories(self) -> list[Trajectory]:
        return [self.trajectories[s.name] for s in self.steps if s.name in self.trajectories]


def held_at_end(steps: tuple[Step, ...] | list[Step]) -> dict[str, str]:
    """The objects the hands hold when an alternative ends: side -> object.

    What they hold at its start (:func:`held_at_start`), then each ``grasp`` takes its object into
    its hand and each ``release`` opens it; a push moves its object without holding it.
    """
    held = dict(held_at_start(steps))
    for step in steps:
        if step.kind == "grasp" and step.obj:
            held[step.side] = step.obj
        elif step.kind == "release":
            held.pop(step.side, None)
    return held


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
