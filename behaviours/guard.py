"""Live risk guard: a decorator that re-checks risk on every tick while its motion runs.

``RiskGuard(child, ...)`` wraps a trajectory-following behaviour
(:class:`behaviours.move_hand.MoveHand` and its kinds). On each tick, after the
child has sent this period's targets, it asks the
:class:`executive.monitoring.live_risk.LiveRiskMonitor` on the blackboard
(``/executive/live_risk``) for the predicted clearance (measured configuration
and the next ``lookahead_s`` of planned knots, against the *current* estimate of
the scene) and the CoM margin over the current foot contacts. When a limit is
crossed the robot is put in a safe hold (every joint servoed to where it is)
and the guard FAILS with the reason; the selector then re-plans or escalates.

Without a monitor on the blackboard the guard is transparent (it only ticks its
child), so the same subtree runs with and without live checks.
"""

from __future__ import annotations

from typing import Any

import py_trees

from behaviours.move_hand import MoveHand
from behaviours.robot_access import NAMESPACE

__all__ = ["LIVE_RISK_KEY", "RiskGuard", "install_monitor"]

Status = py_trees.common.Status
LIVE_RISK_KEY = "live_risk"


def install_monitor(monitor: Any) -> None:
    """Put the live risk monitor (or None: guards off) on the blackboard before ticking a tree."""
    client = py_trees.blackboard.Client(name="executive.guards", namespace=NAMESPACE)
    client.register_key(LIVE_RISK_KEY, access=py_trees.common.Access.WRITE)
    client.set(LIVE_RISK_KEY, monitor)


class RiskGuard(py_trees.decorators.Decorator):
    """Fail (and hold) the moment the live risk of the wrapped motion crosses a guard limit.

    Args:
        child: the motion to guard.
        side, kind, obj, allow_contact: the motion step's hand, kind, task object and
            planned contacts (:class:`executive.planning.plan.Step`), for the allowances.
        every: check every ``every``-th tick (1: every tick).
    """

    def __init__(
        self,
        child: MoveHand,
        *,
        side: str,
        kind: str,
        obj: str,
        allow_contact: tuple[str, ...] = (),
        every: int = 1,
        name: str | None = None,
    ) -> None:
        super().__init__(name=name or f"guard({child.name})", child=child)
        self.motion = child
        self.side, self.kind, self.obj, self.allow_contact = side, kind, obj, allow_contact
        self.every = max(1, every)
        self.bb = self.attach_blackboard_client(name=self.name, namespace=NAMESPACE)
        self.bb.register_key("robot", access=py_trees.common.Access.READ)
        self.bb.register_key(LIVE_RISK_KEY, access=py_trees.common.Access.READ)
        self._allow: frozenset[tuple[str, str]] | None = None
        self._allow_of: tuple[Any, frozenset[tuple[str, str]]] | None = None  # (monitor, its allow)
        self._ticks = 0
        self._watch: Any = None  # the monitor of the running motion (set in initialise)
        self._robot: Any = None
        self.last_verdict: Any = None  # executive.monitoring.live_risk.GuardVerdict of the latest check
        self.tripped: Any = None  # the verdict that stopped the motion, if any
        self.verdict = ""  # "guard" once tripped (the failure-mode table's outcome)

    def _monitor(self) -> Any:
        return self.bb.get(LIVE_RISK_KEY) if self.bb.exists(LIVE_RISK_KEY) else None

    def allow(self, monitor: Any) -> frozenset[tuple[str, str]]:
        """The pairs this motion may bring into contact (the monitor's collision model names them;
        worked out once per monitor)."""
        if self._allow_of is None or self._allow_of[0] is not monitor:
            pairs = monitor.collision.step_allow(
                self.side, self.kind, self.obj, self.allow_contact, self.motion.trajectory.carried
            )
            self._allow_of = (monitor, frozenset(pairs))
        return self._allow_of[1]

    def prepare(self, monitor: Any) -> None:
        """Let ``monitor`` compute the planned knots' distances ahead (e.g. in a planning thread),
        so the ticks only compute the measured configuration's."""
        prepare = getattr(monitor, "prepare", None)
        if callable(prepare):
            traj = self.motion.trajectory
            prepare(traj.qpos, carried=traj.carried[1] if traj.carried else None, allow=self.allow(monitor))

    def initialise(self) -> None:
        self._ticks = 0
        self.tripped = None
        # The monitor and robot the motion starts with serve its every tick (both are installed
        # before the tree ticks; blackboard reads cost a few us each).
        monitor = self._watch = self._monitor()
        self._robot = self.bb.robot if monitor is not None else None
        if monitor is not None:
            self._allow = self.allow(monitor)

    def update(self) -> Status:
        status = self.decorated.status
        self.feedback_message = self.decorated.feedback_message
        monitor = self._watch
        if monitor is None or status != Status.RUNNING:
            return status
        self._ticks += 1
        if (self._ticks - 1) % self.every:
            return status
        robot = self._robot
        traj = self.motion.trajectory
        t = robot.time - self.motion.started_at
        verdict = monitor.check(
            robot.data.qpos,
            traj.qpos,
            traj.times,
            t,
            carried=traj.carried[1] if traj.carried else None,
            allow=self._allow or frozenset(),
            com_margin=monitor.com_margin(robot.world, robot.data, at_least=monitor.config.min_com_margin),
        )
        self.last_verdict = verdict
        if verdict.ok:
            return status
        self.tripped = verdict
        robot.hold()  # safe hold where the robot is, before anything else
        self.feedback_message = verdict.reason
        self.verdict = "guard"
        return Status.FAILURE
