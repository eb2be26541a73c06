"""Grasp and release: close or open one hand's gripper and verify the result in physics."""

from __future__ import annotations

import py_trees

from behaviours.robot_access import RobotBehaviour
from executive.world.touch import hand_contacts

__all__ = ["Grasp", "Release", "object_contacts"]

Status = py_trees.common.Status


def object_contacts(robot: object, side: str, obj: str) -> tuple[int, float]:
    """How many distinct hand geoms of ``side`` touch ``obj``, and their total normal force (N)
    (:func:`executive.world.touch.hand_contacts` of the robot's world)."""
    return hand_contacts(robot.world, side, obj)  # type: ignore[attr-defined]


class Grasp(RobotBehaviour):
    """Close a hand on an object; succeed when at least two hand geoms hold it firmly.

    The detectors are told the hand may touch the object from the start. The
    grasp is verified by contacts in physics (``min_contacts`` distinct hand
    geoms, ``min_force`` N in total), not by the gripper's joint positions.
    """

    def __init__(
        self,
        name: str,
        side: str,
        obj: str,
        settle_s: float = 0.5,
        timeout_s: float = 1.5,
        min_contacts: int = 2,
        min_force: float = 10.0,
    ) -> None:
        super().__init__(name, writes_holding=True)
        self.side, self.obj = side, obj
        self.settle_s, self.timeout_s = settle_s, timeout_s
        self.min_contacts, self.min_force = min_contacts, min_force
        self._t0 = 0.0

    def initialise(self) -> None:
        self._t0 = self.robot.time
        holding: dict[str, str] = self.bb.holding
        carried = next(((s, o) for s, o in holding.items() if o == self.obj and s != self.side), None)
        self.robot.detector.set_phase(carried=carried, grasping=(self.side, self.obj))
        self.robot.set_gripper(self.side, closed=True)
        self.feedback_message = f"closing {self.side} hand on {self.obj}"

    def update(self) -> Status:
        if self.failed_by_detector():
            return Status.FAILURE
        t = self.robot.time - self._t0
        if t < self.settle_s:
            return Status.RUNNING
        # A robot with its own touch sensing answers itself (robot_interface.HostRobot);
        # otherwise the contacts of its MuJoCo state are read.
        sense = getattr(self.robot, "hand_contacts", None)
        n, force = (
            sense(self.side, self.obj)
            if callable(sense)
            else object_contacts(self.robot, self.side, self.obj)
        )
        if n >= self.min_contacts and force >= self.min_force:
            holding = dict(self.bb.holding)
            holding[self.side] = self.obj
            self.bb.holding = holding
            self.feedback_message = f"{self.side} hand holds {self.obj} ({n} contacts, {force:.0f} N)"
            return Status.SUCCESS
        if t < self.timeout_s:
            return Status.RUNNING
        return self.fail(
            "drop",
            f"drop: {self.side} hand closed but does not hold {self.obj} "
            f"({n} hand geoms touching, {force:.1f} N; need {self.min_contacts} and {self.min_force:.0f} N)",
        )

    def terminate(self, new_status: Status) -> None:
        if new_status in (Status.FAILURE, Status.INVALID):
            self.robot.hold()


class Release(RobotBehaviour):
    """Open a hand; succeed once it has opened for ``open_s`` seconds."""

    def __init__(self, name: str, side: str, obj: str, open_s: float = 0.5) -> None:
        super().__init__(name, writes_holding=True)
        self.side, self.obj, self.open_s = side, obj, open_s
        self._t0 = 0.0

    def initialise(self) -> None:
        self._t0 = self.robot.time
        holding = dict(self.bb.holding)
        holding.pop(self.side, None)
        self.bb.holding = holding
        other = next(((s, o) for s, o in holding.items() if o == self.obj), None)
        # Still touching while the jaws open: the hand may touch, another hand may carry.
        self.robot.detector.set_phase(
            carried=other, grasping=(self.side, self.obj), placing=None if other else self.obj
        )
        self.robot.set_gripper(self.side, closed=False)
        self.feedback_message = f"opening {self.side} hand"

    def update(self) -> Status:
        if self.failed_by_detector():
            return Status.FAILURE
        if self.robot.time - self._t0 < self.open_s:
            return Status.RUNNING
        self.feedback_message = f"{self.side} hand released {self.obj}"
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        if new_status in (Status.FAILURE, Status.INVALID):
            self.robot.hold()
