"""Following a planned trajectory: move-hand, and its named uses lift, carry, place, retreat, home."""

from __future__ import annotations

from typing import Any

import numpy as np
import py_trees

from behaviours.robot_access import RobotBehaviour
from executive.planning.plan import MOVE_TOLERANCE
from executive.planning.planner import Trajectory
from executive.schema.types import GuardConfig

__all__ = ["Carry", "Home", "Lift", "MoveHand", "Place", "Retreat"]

Status = py_trees.common.Status


class MoveHand(RobotBehaviour):
    """Stream a planned trajectory's knots to the robot's joint servos, one control period per tick.

    Succeeds once the trajectory has played and the hands have settled within
    ``tolerance`` (m) of their planned final positions (or after ``settle_s``
    more seconds, failing if they are still off); fails at once when a
    physics detector flags a failure. ``update()`` never blocks: it only
    samples the trajectory and writes targets.

    The targets of the coming ticks are sampled ahead, ``chunk`` control periods at a time
    (:meth:`Trajectory.sample_many`, one vectorised call instead of two samples per tick); a
    tick whose trajectory time is not the next sampled one (a host's robot whose clock does
    not advance by exactly one period per tick) samples afresh from its own time. On the bundled
    physics (:class:`executive.execution.simulated.SimulatedRobot`) the legs' static load of each sampled
    target (the leg servos' feed-forward) is computed with them, in one batch
    (:meth:`executive.execution.simulated.JointTargetController.leg_loads`).

    A :class:`behaviours.guard.GuardedMotion`: a guard looks ahead along :attr:`trajectory` from
    :meth:`planned_time`, with the guard's own CoM limit (:meth:`com_limit`), and stops it with
    the plain hold (:meth:`hold_safely`).
    """

    chunk: int = 25  # control periods sampled ahead (0.5 s at 50 Hz)

    phase: str = "free"  # what the detectors are told: free / lift / carry / place
    support_required = False  # feet without a support polygon: the CoM margin is not measured
    holding = True  # its safe hold (hold_safely) is reached at once

    def __init__(
        self,
        name: str,
        trajectory: Trajectory,
        tolerance: float = MOVE_TOLERANCE,
        settle_s: float = 0.6,
        touching: tuple[str, str] | None = None,
        approaching: tuple[str, str] | None = None,
    ) -> None:
        super().__init__(name)
        self.trajectory = trajectory
        self.touching = touching  # (side, object) the hand may still touch (just released)
        self.approaching = approaching  # (side, object) the open hand moves onto to grasp
        self.tolerance = tolerance
        self.settle_s = settle_s
        self._t0 = 0.0
        self._robot: Any = None  # set in initialise
        self._ahead_t: np.ndarray = np.zeros(0)  # trajectory times of the targets sampled ahead
        self._ahead_q = np.zeros((0, 0))  # their qpos rows (one more than times: the next target)
        self._ahead_i = 0  # the row of the next tick
        self._ahead_load: np.ndarray | None = None  # leg loads of the sampled targets (bundled physics)
        self.end_error: dict[str, np.ndarray] | None = None  # per hand, executed - planned end (m)

    @property
    def started_at(self) -> float:
        """Robot time at which the trajectory started playing (its t = 0)."""
        return self._t0

    def planned_time(self, robot: Any) -> float:
        """Where the motion is along :attr:`trajectory` now (s)."""
        return robot.time - self._t0

    def com_limit(self, config: GuardConfig) -> float:
        """The least CoM margin (m) over the foot contacts: the guard's ``min_com_margin``."""
        return config.min_com_margin

    def hold_safely(self, robot: Any, clear_ahead: bool = True) -> str:
        """The plain hold: every joint servoed to where it is (nothing more to say: "")."""
        robot.hold()
        return ""

    def initialise(self) -> None:
        self._robot = self.robot  # the robot of this run of the motion: one blackboard read
        self._t0 = self._robot.time
        self._ahead_t, self._ahead_i = np.zeros(0), 0
        self.end_error = None
        self.feedback_message = f"following {self.trajectory.name} ({self.trajectory.duration:.2f} s)"
        self._set_detector_phase()

    def _set_detector_phase(self) -> None:
        holding: dict[str, str] = self.bb.holding
        carried = next(iter(holding.items()), None) if holding else None
        # Lifting off and setting down: the carried object may still/already touch the table.
        placing = carried[1] if carried and self.phase in ("lift", "place") else None
        self.robot.detector.set_phase(
            carried=carried, grasping=self.touching, placing=placing, approaching=self.approaching
        )

    def update(self) -> Status:
        robot = self._robot
        if self.failed_by_detector(robot):
            return Status.FAILURE
        t = robot.time - self._t0
        q, qvel = self._targets(t, robot.control_dt)
        if self._ahead_load is not None:
            robot.set_joint_targets(q, qvel, leg_load=self._ahead_load[self._ahead_i - 1])
        else:
            robot.set_joint_targets(q, qvel)
        if t < self.trajectory.duration:
            self.feedback_message = f"{self.trajectory.name}: {t:.2f}/{self.trajectory.duration:.2f} s"
            return Status.RUNNING
        error = self.hand_error()
        if error <= self.tolerance:
            self.end_error = self.hand_offsets()
            self.feedback_message = f"reached (hand error {error * 1000:.0f} mm)"
            return Status.SUCCESS
        if t < self.trajectory.duration + self.settle_s:
            return Status.RUNNING
        self.end_error = self.hand_offsets()
        # The message is the behaviour's own; whoever reports it prefixes the behaviour's name.
        return self.fail(
            "tracking",
            f"hand {error * 1000:.0f} mm from its planned end (tolerance {self.tolerance * 1000:.0f} mm)",
        )

    def _targets(self, t: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The target at trajectory time ``t`` and its rate over the period, (q(t + dt) - q(t)) / dt."""
        i = self._ahead_i
        if i >= len(self._ahead_t) or abs(self._ahead_t[i] - t) > 1e-9:  # 1 ns: clock rounding only
            times = t + dt * np.arange(self.chunk + 1, dtype=np.float64)
            self._ahead_t = times[:-1]
            self._ahead_q = self.trajectory.sample_many(times)
            # The bundled simulation's servos feed the legs' static load forward; a host's robot has none.
            leg_loads = getattr(getattr(self._robot, "controller", None), "leg_loads", None)
            self._ahead_load = leg_loads(self._ahead_q[:-1]) if leg_loads is not None else None
            i = 0
        self._ahead_i = i + 1
        q = self._ahead_q[i]
        return q, (self._ahead_q[i + 1] - q) / dt

    def hand_error(self) -> float:
        """Largest distance between a hand site and its planned final position."""
        return max(float(np.linalg.norm(e)) for e in self.hand_offsets().values())

    def hand_offsets(self) -> dict[str, np.ndarray]:
        """Per hand, where its site is less its planned final position (world frame, m)."""
        data, sites = self.robot.data, self.robot.world.ids.hand_sites
        return {
            side: data.site_xpos[sites[side]] - path[-1] for side, path in self.trajectory.hand_paths.items()
        }

    def terminate(self, new_status: Status) -> None:
        if new_status in (Status.FAILURE, Status.INVALID):
            self.robot.hold()  # safe hold where the robot is


class Lift(MoveHand):
    """Raise a grasped object clear of the table."""

    phase = "lift"


class Carry(MoveHand):
    """Transport a grasped object (transfer or handover approach)."""

    phase = "carry"


class Place(MoveHand):
    """Lower a carried object onto the table (table contact is expected)."""

    phase = "place"


class Retreat(MoveHand):
    """Move an empty hand away after releasing."""


class Home(MoveHand):
    """Return to the standing home posture."""
