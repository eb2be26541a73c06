"""After a walk inside a composition: measure where the base stands, re-plan the rest from there.

``Restance(name, walk=..., rest=..., movers=...)`` follows a walk in an alternative whose plan goes
on after it (a side-step's transfer and place). Its first tick measures the base
(:func:`executive.world.observation.measure_base`) and asks the re-planner on the blackboard
(``/executive/replanner``, a :class:`executive.planning.restance.Replanner`) for the rest of the
composition planned again from the measured stance. It measures once the base has come to rest:
when the walk ends the balance feedback lets go of the pelvis, which sways over the feet for a
second or two (docs/task_kinds.md, "Acting from the measured stance"). The robot holds the walk's
last targets meanwhile. Then:

* re-planned: each following mover gets its new trajectory and the behaviour succeeds;
* refused (the rest does not plan from there, or its risk exceeds what was approved): the robot
  holds where it is and the behaviour fails with ``guard`` and the reason;
* no re-planner on the blackboard: the rest runs as planned (``open_loop`` in its record).

Its :attr:`Restance.record` (:func:`executive.planning.restance.restance_fields`) is the log's
``restance`` line: the planned and measured stances, the outcome, the risk check.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import py_trees

from behaviours.robot_access import NAMESPACE, RobotBehaviour
from executive.planning.plan import AlternativePlan
from executive.planning.restance import (
    RestanceRequest,
    StanceOffset,
    planned_start,
    restance_fields,
    stance_of,
)
from executive.world.observation import measure_base

__all__ = ["REPLANNER_KEY", "Restance", "install_replanner"]

Status = py_trees.common.Status
REPLANNER_KEY = "replanner"


def install_replanner(replanner: Any) -> None:
    """Put the re-planner the :class:`Restance` behaviours ask (or None: none) on the blackboard."""
    client = py_trees.blackboard.Client(name="executive.replanner", namespace=NAMESPACE)
    client.register_key(REPLANNER_KEY, access=py_trees.common.Access.WRITE)
    client.set(REPLANNER_KEY, replanner)


class Restance(RobotBehaviour):
    """Measure the base after ``walk``, have ``rest`` re-planned from there, hand it to ``movers``.

    Args:
        name: the behaviour's name.
        walk: the walk step's name.
        rest: the steps after the walk with their planned trajectories
            (:func:`executive.planning.restance.rest_after`).
        movers: step name -> the behaviour that follows that step's trajectory (its ``trajectory``
            attribute is replaced by the re-planned one), for every step of ``rest`` that moves.
        still_speed: the base is at rest while its horizontal speed is at most this (m/s) ...
        still_s: ... for this long (s); then it is measured.
        settle_s: the longest wait (s): a base still moving then is measured as it is (the record
            says ``still`` false).
    """

    def __init__(
        self,
        name: str,
        *,
        walk: str,
        rest: AlternativePlan,
        movers: Mapping[str, Any],
        still_speed: float = 0.005,
        still_s: float = 0.5,
        settle_s: float = 4.0,
    ) -> None:
        super().__init__(name)
        missing = sorted(set(rest.trajectories) - set(movers))
        if missing:
            followed = ", ".join(missing)
            raise ValueError(f"{name}: no behaviour follows {followed}; the rest cannot be re-planned")
        self.walk = walk
        self.rest = rest
        self.movers = dict(movers)
        self.bb.register_key(REPLANNER_KEY, access=py_trees.common.Access.READ)
        self.still_speed, self.still_s, self.settle_s = still_speed, still_s, settle_s
        self.record: dict[str, Any] | None = None  # the log's restance line, once answered
        self._request: RestanceRequest | None = None
        self._replanner: Any = None
        self._t0 = 0.0  # robot time when the walk ended
        self._moving_at = 0.0  # robot time the base was last seen moving

    def initialise(self) -> None:
        self.record, self._request = None, None
        self._replanner = self.bb.get(REPLANNER_KEY) if self.bb.exists(REPLANNER_KEY) else None
        self._t0 = self._moving_at = self.robot.time

    def _still(self, robot: Any) -> bool | None:
        """True once the base has been at rest for ``still_s``; False when ``settle_s`` has passed
        first (measure anyway); None: wait."""
        t = robot.time
        velocity = np.asarray(robot.data.qvel, dtype=float)[robot.world.base_qvel]
        if float(np.hypot(velocity[0], velocity[1])) > self.still_speed:
            self._moving_at = t
        if t - self._moving_at >= self.still_s:
            return True
        return False if t - self._t0 >= self.settle_s else None

    def update(self) -> Status:
        robot = self.robot
        if self.failed_by_detector(robot):
            return Status.FAILURE
        if self._request is None:
            still = self._still(robot)
            if still is None:
                self.feedback_message = f"{self.name}: standing still before measuring the base"
                return Status.RUNNING
            position, quat = measure_base(robot.world, robot)
            base = planned_start(self.rest)[robot.world.base_qpos]
            offset = StanceOffset(stance_of(base[:3], base[3:]), stance_of(position, quat))
            self._request = RestanceRequest(self.rest, self.walk, offset, robot.time - self._t0, still)
            if self._replanner is None:
                self.record = restance_fields(self._request, None)
                self.feedback_message = f"{self.name}: no re-planner; the rest runs as planned"
                return Status.SUCCESS
            self._replanner.submit(self._request)
        result = self._replanner.poll()
        offset = self._request.offset
        if result is None:
            off = f"{offset.distance * 1000:.0f} mm off the plan"
            self.feedback_message = f"{self.name}: re-planning from the measured stance ({off})"
            return Status.RUNNING
        self.record = restance_fields(self._request, result)
        if not result.ok:
            robot.hold()
            return self.fail("guard", f"{self.name}: {result.reason}; the robot holds")
        for step, trajectory in result.trajectories.items():
            self.movers[step].trajectory = trajectory
        self.feedback_message = (
            f"{self.name}: the rest re-planned from the measured stance "
            f"({offset.distance * 1000:.0f} mm, {math.degrees(abs(offset.turn)):.1f} deg off the plan)"
        )
        return Status.SUCCESS

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self._request is not None and self.record is None:
            if self._replanner is not None:
                self._replanner.cancel()  # stopped while waiting: the answer is no longer wanted
