"""How behaviours reach the robot: blackboard keys, registered per behaviour.

Keys (namespace ``/executive``):

* ``robot``: the :class:`executive.execution.simulated.SimulatedRobot` (or any object with
  the same methods) the host steps; read-only for behaviours.
* ``holding``: ``dict[str, str]`` side -> name of the object that hand holds;
  written by grasp/release behaviours, read by the others.
"""

from __future__ import annotations

from typing import Any

import py_trees

__all__ = ["NAMESPACE", "RobotBehaviour", "install"]

NAMESPACE = "/executive"


def install(robot: Any) -> None:
    """Put the robot on the blackboard (and an empty ``holding`` map) before ticking a tree."""
    client = py_trees.blackboard.Client(name="executive.host", namespace=NAMESPACE)
    client.register_key("robot", access=py_trees.common.Access.WRITE)
    client.register_key("holding", access=py_trees.common.Access.WRITE)
    client.robot = robot
    client.holding = {}


class RobotBehaviour(py_trees.behaviour.Behaviour):
    """Base of the task-level behaviours: registered access to the robot and the holding map.

    A behaviour that fails sets ``verdict`` to what went wrong, a verdict of the failure-mode
    table (executive.schema.failure_modes: ``drop``, ``tracking``, ``task``, ...), and says
    how in ``feedback_message``; :meth:`fail` does both.
    """

    def __init__(self, name: str, writes_holding: bool = False) -> None:
        super().__init__(name=name)
        self.verdict = ""
        self.bb = self.attach_blackboard_client(name=name, namespace=NAMESPACE)
        self.bb.register_key("robot", access=py_trees.common.Access.READ)
        access = py_trees.common.Access.WRITE if writes_holding else py_trees.common.Access.READ
        self.bb.register_key("holding", access=access)

    @property
    def robot(self) -> Any:
        return self.bb.robot

    def failed_by_detector(self, robot: Any = None) -> bool:
        """True (with the feedback message set) when the physics detectors flagged a failure.

        ``robot``: the robot if the caller holds it already (saves a blackboard read)."""
        failure = (self.robot if robot is None else robot).failure
        if failure is None:
            return False
        self.feedback_message = failure.detail  # already "<mode>: ..."
        self.verdict = failure.mode
        return True

    def fail(self, verdict: str, message: str) -> py_trees.common.Status:
        """Fail with ``verdict`` (a verdict of the failure-mode table) and ``message``; returns FAILURE."""
        self.verdict, self.feedback_message = verdict, message
        return py_trees.common.Status.FAILURE
