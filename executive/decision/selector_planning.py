"""One selector's planning work: the estimate it starts from, the job's round trip to the worker.

:func:`refresh_estimate` puts the objects where the robot observes them before a decision;
:class:`PlanningLink` sends the decision's :class:`~executive.decision.planning_job.PlanningJob` to
the planning worker (:mod:`executive.decision.planning_worker`) and polls for its result, or
(``background`` False) works it out at once in the ticking process. What to do when a worker is
lost (log it, replace it, re-plan, or fail after :data:`MAX_WORKER_LOSSES`) is the selector's.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from executive.decision.physics_check import PhysicsCheck
from executive.decision.planning_job import Planning, PlanningJob, PlanningResult
from executive.decision.planning_worker import PlanningWorker, WorkerLost
from executive.tasks.base import Task
from executive.world.model import World

__all__ = ["MAX_WORKER_LOSSES", "PlanningLink", "object_state", "refresh_estimate"]

FloatArray = np.ndarray

#: Planning workers lost in one decision before the task fails (each is replaced and re-planned).
MAX_WORKER_LOSSES = 3


def refresh_estimate(world: World, q: FloatArray, observed: dict[str, tuple[FloatArray, FloatArray]]) -> None:
    """Put the objects the robot observes where it sees them; the others stay estimated.

    Args:
        world: the estimate (its ``data.qpos`` and kinematics are updated).
        q: the planning start (measured joints); its object coordinates are set to the estimate's.
        observed: object name -> (position, quaternion) as observed.
    """
    for name, adr in world.ids.object_qpos.items():
        if name in observed:
            pos, quat = observed[name]
            world.data.qpos[adr : adr + 3] = pos
            world.data.qpos[adr + 3 : adr + 7] = quat
        q[adr : adr + 7] = world.data.qpos[adr : adr + 7]
    mujoco.mj_kinematics(world.model, world.data)


def object_state(world: World, task: Task) -> dict[str, Any] | None:
    """The task's object as ``world`` has it (name, position, quat); None for a task that moves none."""
    if not task.object:  # a task that moves no object (a press)
        return None
    pos, quat = world.object_pose(task.object)
    return {"name": task.object, "position": pos, "quat": quat}


class PlanningLink:
    """A selector's planning jobs: sent to a worker and polled, or worked out in the tick.

    Args:
        name: the selector's name (its planner and collision model when planning in the tick).
        estimate: the estimate world (a worker of the selector's own is built from its scenario).
        physics: the physics check planning in the tick uses (its pool size sizes an own worker's).
        background: plan in a worker process; False: in the tick (blocking).
        worker: the worker to use (shared by a mission's selectors); None with ``background``:
            one of the selector's own, started on its first job and closed by :meth:`close`.
    """

    def __init__(
        self,
        name: str,
        estimate: World,
        physics: PhysicsCheck | None,
        *,
        background: bool,
        worker: PlanningWorker | None,
    ) -> None:
        self.name = name
        self.estimate = estimate
        self.physics = physics
        self.background = background
        self.worker = worker
        self.own_worker = False  # whether this link started (and closes) its worker
        self.local: Planning | None = None  # the in-tick work (background False)
        self.job: PlanningJob | None = None  # the decision being worked out
        self.ticket: int | None = None  # its ticket with the worker
        self.lost: WorkerLost | None = None  # the worker was found gone when the job was sent
        self.losses = 0  # workers lost in this decision
        self.result: PlanningResult | None = None  # its result, once received

    def setup(self) -> None:
        """Planning in the tick: build the planner and collision model of the estimate now (once)."""
        if not self.background and self.local is None:
            self.local = Planning(self.estimate, self.physics)
            self.local.tools(self.name)

    def reset(self) -> None:
        """Forget the decision (a new run of the task)."""
        self.job, self.ticket, self.lost, self.result = None, None, None, None
        self.losses = 0

    def submit(self, job: PlanningJob, monitor: Any) -> None:
        """Hand ``job`` to the worker, or (``background`` False) work it out now into :attr:`result`.

        Args:
            job: the decision's work.
            monitor: the live risk monitor in-tick planning prepares guard distances with (None: none).
        """
        self.job = job
        self.ticket, self.lost, self.result = None, None, None
        if not self.background:
            self.setup()
            assert self.local is not None
            self.local.monitor = monitor
            self.result = self.local.run(job)
            return
        if self.worker is None:  # a selector on its own: its own worker
            jobs = self.physics.pool.jobs if self.physics is not None else 0
            self.worker, self.own_worker = PlanningWorker(self.estimate.scenario, jobs), True
        try:
            self.ticket = self.worker.submit(job)
        except WorkerLost as lost:  # gone while idle: the next poll replaces it
            self.lost = lost

    def receive(self) -> PlanningResult | None:
        """The worker's result if it has come (None: not yet), kept in :attr:`result`.

        Raises:
            WorkerLost: the worker died or hangs.
        """
        if self.lost is not None:
            raise self.lost
        assert self.worker is not None and self.ticket is not None
        result = self.worker.poll(self.ticket)
        assert result is None or isinstance(result, PlanningResult)  # a decision's ticket
        if result is not None:
            self.ticket = None
            self.result = result
            self.losses = 0
        return result

    def count_loss(self) -> int:
        """Count a lost worker; the number lost in this decision."""
        self.losses += 1
        return self.losses

    def replace(self) -> int | None:
        """Start a fresh worker in place of the lost one; its pid."""
        assert self.worker is not None
        return self.worker.replace()

    def forget(self) -> None:
        """Tell the worker the job's result is no longer wanted (the selector was halted)."""
        if self.ticket is not None and self.worker is not None:
            self.worker.forget(self.ticket)
            self.ticket = None

    def close(self) -> None:
        """Close the worker if this link started it."""
        if self.own_worker and self.worker is not None:
            self.worker.close()
            self.worker, self.own_worker = None, False
