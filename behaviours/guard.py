"""Live risk guard: a decorator that re-checks risk on every tick while its motion runs.

``RiskGuard(child, ...)`` wraps a motion that follows planned knots, a
:class:`GuardedMotion`: a hand motion (:class:`behaviours.move_hand.MoveHand` and its kinds) or
a footstep (:class:`behaviours.step.Step`). On each tick, after the child has sent this
period's targets, it asks the :class:`executive.monitoring.live_risk.LiveRiskMonitor` on the
blackboard (``/executive/live_risk``) for the predicted clearance (measured configuration and
the next ``lookahead_s`` of the motion's planned knots, against the *current* estimate of the
scene) and the CoM margin over the current foot contacts (one sole while a foot swings), against
the motion's CoM limit. When a limit is crossed the motion is put in its safest hold
(:meth:`GuardedMotion.hold_safely`: a hand motion servoes every joint to where it is; a footstep
puts the robot on both feet) and, once the robot holds, the guard FAILS with the reason and what
the hold did; the selector then re-plans or escalates.

Without a monitor on the blackboard the guard is transparent (it only ticks its
child), so the same subtree runs with and without live checks.
"""

from __future__ import annotations

from typing import Any, Protocol

import py_trees

from behaviours.robot_access import NAMESPACE
from executive.planning.timing import Trajectory
from executive.schema.types import GuardConfig

__all__ = ["LIVE_RISK_KEY", "GuardedMotion", "RiskGuard", "install_monitor"]

Status = py_trees.common.Status
LIVE_RISK_KEY = "live_risk"


def install_monitor(monitor: Any) -> None:
    """Put the live risk monitor (or None: guards off) on the blackboard before ticking a tree."""
    client = py_trees.blackboard.Client(name="executive.guards", namespace=NAMESPACE)
    client.register_key(LIVE_RISK_KEY, access=py_trees.common.Access.WRITE)
    client.set(LIVE_RISK_KEY, monitor)


class GuardedMotion(Protocol):
    """What a guard needs of the motion it wraps (a py_trees behaviour).

    Attributes:
        name: the behaviour's name.
        status: its py_trees status.
        feedback_message: what it says it does.
        trajectory: the planned knots the guard looks ahead along (``qpos``, ``times``,
            ``carried``).
        support_required: True: feet that touch the floor at fewer than three points not in a
            line (a foot rolled onto an edge) put the CoM outside its support; False: the CoM
            margin is then not measured.
        holding: whether the robot has reached the hold :meth:`hold_safely` started.
    """

    name: str
    status: py_trees.common.Status
    feedback_message: str

    @property
    def trajectory(self) -> Trajectory: ...

    @property
    def support_required(self) -> bool: ...

    @property
    def holding(self) -> bool: ...

    def planned_time(self, robot: Any) -> float:
        """Where the motion is along :attr:`trajectory` now (s)."""

    def com_limit(self, config: GuardConfig) -> float:
        """The least CoM margin (m) over the foot contacts while the motion runs."""

    def hold_safely(self, robot: Any, clear_ahead: bool = True) -> str:
        """Start the safest hold from where the robot is; what it does in words ("" the plain hold).

        ``clear_ahead``: False when the planned knots ahead are what tripped the guard."""


class RiskGuard(py_trees.decorators.Decorator):
    """Fail (and hold) the moment the live risk of the wrapped motion crosses a guard limit.

    Args:
        child: the motion to guard.
        side, kind, obj, allow_contact: the motion step's hand (a footstep: its swing foot),
            kind, task object and planned contacts (:class:`executive.planning.plan.Step`), for
            the allowances.
        every: check every ``every``-th tick (1: every tick).
    """

    def __init__(
        self,
        child: GuardedMotion,
        *,
        side: str,
        kind: str,
        obj: str,
        allow_contact: tuple[str, ...] = (),
        every: int = 1,
        name: str | None = None,
    ) -> None:
        super().__init__(name=name or f"guard({child.name})", child=child)  # type: ignore[arg-type]
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
        self._com_limit = 0.0  # the motion's CoM limit (set in initialise)
        self._held = ""  # what the motion's safe hold does (hold_safely), once tripped
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
        self.tripped, self._held = None, ""
        # The monitor and robot the motion starts with serve its every tick (both are installed
        # before the tree ticks; blackboard reads cost a few us each).
        monitor = self._watch = self._monitor()
        self._robot = self.bb.robot if monitor is not None else None
        if monitor is not None:
            self._allow = self.allow(monitor)
            self._com_limit = self.motion.com_limit(monitor.config)

    def update(self) -> Status:
        status = self.decorated.status
        self.feedback_message = self.decorated.feedback_message
        monitor = self._watch
        if monitor is None:
            return status
        if self.tripped is not None:  # in the motion's safe hold
            return self._holding(status)
        if status != Status.RUNNING:
            return status
        self._ticks += 1
        if (self._ticks - 1) % self.every:
            return status
        robot = self._robot
        motion = self.motion
        traj = motion.trajectory
        limit = self._com_limit
        t = motion.planned_time(robot)
        verdict = monitor.check(
            robot.data.qpos,
            traj.qpos,
            traj.times,
            t,
            carried=traj.carried[1] if traj.carried else None,
            allow=self._allow or frozenset(),
            com_margin=monitor.com_margin(
                robot.world, robot.data, at_least=limit, on_edge=motion.support_required
            ),
            com_limit=limit,
        )
        self.last_verdict = verdict
        if verdict.ok:
            return status
        self.tripped = verdict
        # the safest hold from where the robot is, before anything else
        ahead = verdict.crossed == "clearance" and verdict.at_s > t  # the path ahead tripped it
        self._held = motion.hold_safely(robot, clear_ahead=not ahead)
        return self._holding(status)

    def _holding(self, status: Status) -> Status:
        """While the motion reaches its hold: RUNNING; then FAILURE with the reason and the hold."""
        reason = self.tripped.reason + (f"; {self._held}" if self._held else "")
        if status == Status.FAILURE:  # the motion failed on its way to the hold (a detector): its verdict
            return status
        if not self.motion.holding:
            self.feedback_message = f"{reason} (holding)"
            return Status.RUNNING
        self.feedback_message = reason
        self.verdict = "guard"
        return Status.FAILURE
