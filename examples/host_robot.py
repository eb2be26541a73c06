"""A host controller that owns its robot and embeds the executive: the pattern to copy.

    python examples/host_robot.py [SCENARIO] [--threshold X] [--rollouts N] [--out DIR] [--fast]

The robot here is a MuJoCo simulation of its own (:class:`RobotStandIn`), standing in for the
hardware: the host reads its joints and sends it joint targets, and nothing else crosses. Three
parts run:

* the **servo thread**, 500 Hz: interpolates the executive's latest joint targets over the control
  period (:class:`TargetRamp`) and steps the robot one 2 ms servo period (a real robot's joint
  controllers do this part);
* the **control loop**, 100 Hz in the main thread: ``robot.sync()`` reads the joints into the
  executive's mirror and runs its failure detectors, then ``executive.tick()`` ticks the tree (it
  never blocks: planning runs in the executive's worker process);
* the **approver**: when the chosen alternative's risk is above the threshold the executive asks
  a callback, which here approves when the collision risk is small (``--threshold`` lowers the
  scenario's threshold so it is asked).

Ctrl-C (SIGINT) or SIGTERM: the handler only notes the request; the control loop then stops the
executive between two ticks (the tree is halted, the robot holds where it is, the log is closed),
keeps the robot holding for ``HOLD_S`` and says how far it moved meanwhile. ``--fast`` runs the
servo thread and the control loop in lockstep as fast as the computer allows instead of at the
wall clock's pace (tests, CI). docs/embedding.md explains the pattern and what to do when the
host's loop runs faster than a tick takes.
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from executive import (
    ApprovalDecision,
    ApprovalRequest,
    CallbackChannel,
    Executive,
    HostRobot,
    freeze_startup_heap,
    load,
)
from executive.decision.audit import now_iso
from executive.decision.physics_check import with_rollouts
from executive.execution.robot_interface import JointState, joint_addresses, joint_state
from executive.execution.simulated import SimulatedRobot
from executive.schema.types import Scenario
from executive.world import touch
from executive.world.model import World, build

SERVO_HZ = 500  # the robot's joint servo loop
CONTROL_HZ = 100  # the host's control loop: one executive tick per period
HOLD_S = 0.5  # s of robot time the robot is watched holding after a stop
LOGGED = ("selection", "approval", "execute", "failure", "outcome", "stop", "planning_worker")


class RobotStandIn:
    """The robot: a MuJoCo world driven by position servos with gravity feed-forward, one servo
    period per :meth:`step`. Everything the host knows of it goes through :meth:`read`."""

    def __init__(self, world: World) -> None:
        self.world = world
        self.servo = SimulatedRobot(world, control_dt=1.0 / SERVO_HZ)
        self.joints = joint_addresses(world)  # joint name -> its qpos address
        self.lock = threading.Lock()  # the servo thread steps, the control loop reads

    @property
    def time(self) -> float:
        return self.servo.time

    def step(self, q_target: np.ndarray) -> None:
        with self.lock:
            self.servo.set_joint_targets(q_target)
            self.servo.advance()

    def read(self) -> JointState:
        """Joint positions, base pose and the objects (seen exactly here: a perception stack would
        report its own estimates, and leave out what it does not see)."""
        with self.lock:
            objects = {name: self.world.object_pose(name) for name in self.world.ids.object_bodies}
            return joint_state(self.world, objects=objects)


class TargetRamp:
    """The executive's joint targets, one per control period, ramped linearly over the next period
    (in robot time) from where the last ramp had got to: the servo never jumps, never overshoots."""

    def __init__(self, q: np.ndarray, period: float) -> None:
        self.period, self.lock = period, threading.Lock()
        self.start, self.goal, self.t0 = q.copy(), q.copy(), 0.0

    def command(self, goal: np.ndarray, now: float) -> None:
        with self.lock:
            self.start, self.goal, self.t0 = self._at(now), goal, now

    def at(self, now: float) -> np.ndarray:
        with self.lock:
            return self._at(now)

    def _at(self, now: float) -> np.ndarray:
        alpha = min(max((now - self.t0) / self.period, 0.0), 1.0)
        return self.start + alpha * (self.goal - self.start)


class HostJointIO:
    """The executive's ``JointIO`` (executive.execution.robot_interface) over the robot: read the
    joints, send targets and gripper commands, report what the fingertips touch."""

    def __init__(self, robot: RobotStandIn, ramp: TargetRamp) -> None:
        self.robot, self.ramp = robot, ramp

    def read(self) -> JointState:
        return self.robot.read()

    def send_joint_targets(self, targets: Mapping[str, float]) -> None:
        goal = self.ramp.goal.copy()
        for name, value in targets.items():
            goal[self.robot.joints[name]] = value
        self.ramp.command(goal, self.robot.time)

    def send_gripper(self, side: str, closed: bool) -> None:
        with self.robot.lock:
            self.robot.servo.set_gripper(side, closed)

    def hand_contacts(self, side: str, obj: str) -> tuple[int, float]:
        """Touch sensing: hand links on ``obj`` and their normal force (N); here the contacts of the
        simulation, on a robot its fingertip sensors."""
        with self.robot.lock:
            return touch.hand_contacts(self.robot.world, side, obj)


class WallClock:
    """Each loop at its own period of the wall clock; a late period is counted, not caught up."""

    def __init__(self) -> None:
        self.next = {"servo": time.perf_counter(), "control": time.perf_counter()}
        self.late = {"servo": 0, "control": 0}

    def wait(self, loop: str, period: float) -> None:
        self.next[loop] += period
        delay = self.next[loop] - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        else:
            self.late[loop] += 1
            self.next[loop] = time.perf_counter()

    def done(self, loop: str) -> None:
        pass

    def release(self) -> None:
        pass


class Lockstep:
    """``--fast``: the servo thread steps a control period's servo periods after each tick, the
    control loop ticks after them: robot time runs as fast as the computer allows, except while
    the robot only holds (``holding()``: the executive plans), when it keeps the wall clock's pace."""

    def __init__(self, steps_per_tick: int, holding: Any) -> None:
        self.n, self.steps, self.ticks = steps_per_tick, 0, 0
        self.cond, self.released, self.holding = threading.Condition(), False, holding
        self.late = {"servo": 0, "control": 0}

    def wait(self, loop: str, period: float) -> None:
        if loop == "control" and self.holding():
            time.sleep(period)
        with self.cond:
            if loop == "servo":
                self.cond.wait_for(lambda: self.released or self.steps < self.ticks * self.n)
            else:
                self.cond.wait_for(lambda: self.released or self.steps >= self.ticks * self.n)

    def done(self, loop: str) -> None:
        with self.cond:
            if loop == "servo":
                self.steps += 1
            else:
                self.ticks += 1
            self.cond.notify_all()

    def release(self) -> None:
        with self.cond:
            self.released = True
            self.cond.notify_all()


def servo_loop(robot: RobotStandIn, ramp: TargetRamp, pace: Any, stop: threading.Event) -> None:
    """The 500 Hz servo thread: the ramped target at the robot's time, one servo period."""
    while not stop.is_set():
        pace.wait("servo", 1.0 / SERVO_HZ)
        robot.step(ramp.at(robot.time))
        pace.done("servo")


def approver(request: ApprovalRequest) -> ApprovalDecision:
    """The host's policy: approve the recommended alternative if its collision risk is below 5 %."""
    best = next((a for a in request.alternatives if a.name == request.recommended), None)
    ok = best is not None and best.risk.get("collision", 1.0) < 0.05
    print(f"[host] approval asked: {request.reason} -> {'approve' if ok else 'abort'}", flush=True)
    return ApprovalDecision(
        "approve" if ok else "abort",
        request.recommended if ok else None,
        by="callback:host-robot",
        at=now_iso(),
        note="collision probability below 5 %" if ok else "collision probability 5 % or more",
    )


@dataclasses.dataclass
class HostRun:
    """What a run leaves: the executive (its log and summary), the robot, the hold after a stop."""

    executive: Executive
    robot: RobotStandIn
    tick_ms: dict[str, list[float]]  # by phase (planning, executing, ...)
    late: dict[str, int]
    hold_drift_rad: float | None = None  # largest joint motion while holding after a stop
    stopped_by: str | None = None


def _scenario(args: argparse.Namespace) -> Scenario:
    scenario = with_rollouts(load(args.scenario), args.rollouts)
    if args.threshold is not None:
        risk = dataclasses.replace(scenario.risk, threshold=args.threshold)
        scenario = dataclasses.replace(scenario, risk=risk)
    return scenario


def _phase(executive: Executive) -> str:
    task = executive.current_task
    return task.phase if task is not None else "idle"


def control_loop(
    executive: Executive, mirror: HostRobot, pace: Any, stop_requested: list[str]
) -> dict[str, list[float]]:
    """The 100 Hz loop: read the robot into the executive's mirror, tick; stop between two ticks
    when a signal asked. Returns each tick's duration (ms) by the phase it ticked in."""
    tick_ms: dict[str, list[float]] = {}
    seen, shown_s = 0, -1
    while not executive.done:
        if stop_requested:
            mirror.sync()  # hold where the robot is now, not where it was a period ago
            name = stop_requested[0]
            reason = "interrupted by the operator (Ctrl-C)" if name == "SIGINT" else f"stopped by {name}"
            by = "operator:interrupt" if name == "SIGINT" else f"signal:{name}"
            executive.stop(f"{reason}: tree halted, robot holding", by=by)
            break
        pace.wait("control", 1.0 / CONTROL_HZ)
        mirror.sync()
        phase, t0 = _phase(executive), time.perf_counter()
        executive.tick()
        tick_ms.setdefault(phase, []).append((time.perf_counter() - t0) * 1e3)
        pace.done("control")
        for entry in executive.log.entries[seen:]:
            if entry["kind"] in LOGGED:
                detail = entry.get("reason") or entry.get("alternative") or entry.get("outcome") or ""
                print(f"[{entry['at']}] {entry['kind']}: {detail}", flush=True)
        seen = len(executive.log.entries)
        if phase == "executing" and int(mirror.time) > shown_s:  # once a second of robot time
            shown_s = int(mirror.time)
            print(f"[robot {shown_s} s] {executive.describe()}", flush=True)
    return tick_ms


def _hold(robot: RobotStandIn, pace: Any) -> float:
    """Keep the loops going for HOLD_S of robot time; the largest joint motion meanwhile (rad)."""
    before = robot.read()
    end = robot.time + HOLD_S
    while robot.time < end:
        pace.wait("control", 1.0 / CONTROL_HZ)
        pace.done("control")
    after = robot.read()
    return max(abs(after.joints[name] - q) for name, q in before.joints.items())


def run(args: argparse.Namespace) -> HostRun:
    """Build the robot, the executive on it and the loops; run the mission (or until a signal)."""
    scenario = _scenario(args)
    robot = RobotStandIn(build(scenario))
    ramp = TargetRamp(robot.servo.q_target, 1.0 / CONTROL_HZ)
    mirror = HostRobot(build(scenario), HostJointIO(robot, ramp), control_dt=1.0 / CONTROL_HZ)
    channel = CallbackChannel(approver, name="host-robot")
    executive = Executive(scenario, approval=channel, robot=mirror, out=args.out)
    freeze_startup_heap()  # built once: keep the full garbage collections out of the loops
    switch = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)  # the servo thread gets the interpreter within 0.5 ms of a tick's
    holding = lambda: _phase(executive) in ("planning", "awaiting_approval")  # noqa: E731
    pace = Lockstep(SERVO_HZ // CONTROL_HZ, holding) if args.fast else WallClock()
    stop_servo, stop_requested = threading.Event(), []

    def request_stop(signum: int, frame: object) -> None:  # between two bytecodes: only note it
        stop_requested.append(signal.Signals(signum).name)

    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    servo = threading.Thread(target=servo_loop, args=(robot, ramp, pace, stop_servo), name="servo")
    servo.start()
    try:
        tick_ms = control_loop(executive, mirror, pace, stop_requested)
        drift = _hold(robot, pace) if stop_requested else None
    finally:
        if not executive.done:  # an error in the loop: the robot still holds, the log is closed
            executive.stop("stopped by an error in the host's loop")
        stop_servo.set()
        pace.release()
        servo.join()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.setswitchinterval(switch)
    stopped_by = stop_requested[0] if stop_requested else None
    return HostRun(executive, robot, tick_ms, dict(pace.late), drift, stopped_by)


def report(result: HostRun) -> None:
    """The outcome, the ticks against the period by phase, the late periods, the hold after a stop."""
    summary = result.executive.summary()
    print(
        f"outcome {summary['outcome']}; {result.robot.time:.1f} s of robot time; late periods: "
        f"control {result.late['control']}, servo {result.late['servo']}",
        flush=True,
    )
    for phase, values in result.tick_ms.items():
        ms = np.array(values)
        print(
            f"  {phase:<18}{len(ms):>6} ticks: median {np.median(ms):.2f} ms, 99th percentile "
            f"{np.percentile(ms, 99):.2f} ms, longest {ms.max():.2f} ms (period {1e3 / CONTROL_HZ:.0f} ms)",
            flush=True,
        )
    if result.hold_drift_rad is not None:
        print(
            f"stopped by {result.stopped_by}; held {HOLD_S:.1f} s: joints moved at most "
            f"{result.hold_drift_rad * 1e3:.2f} mrad",
            flush=True,
        )


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer", help="a bundled name or a file")
    parser.add_argument("--threshold", type=float, help="override risk.threshold (lower: approval asked)")
    parser.add_argument("--rollouts", type=int, help="override risk.rollouts.count (0: the dry runs only)")
    parser.add_argument("--out", help="the run folder (decisions.jsonl, summary.json)")
    parser.add_argument("--fast", action="store_true", help="lockstep, not the wall clock's pace")
    return parser


def main(argv: list[str] | None = None) -> int:
    result = run(build_parser().parse_args(argv))
    report(result)
    return 0 if result.executive.outcome == "success" else 1


if __name__ == "__main__":  # the executive starts worker processes (spawned: they import this file)
    sys.exit(main())
