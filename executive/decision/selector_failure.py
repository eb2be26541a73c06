"""What a selector's ended alternative left: the failure to log, the kind's check, the closest call.

:func:`failure_of` is a failed subtree's failure line (the detectors' verdict, else the failed
behaviour's own message); :func:`is_terminal` says whether it ends the task at once (a fall, an
unstable simulation: the failure-mode table's ``terminal``); :func:`check_placed` is the task
kind's check of a subtree that succeeded; :func:`closest_call` the ``outcome`` line's near miss.
"""

from __future__ import annotations

import math
from typing import Any

import py_trees

from executive.decision.audit import AuditLog
from executive.execution.runner import behaviour_failure
from executive.schema.failure_modes import failure_mode, mode_of_verdict
from executive.tasks.base import Task, TaskKind
from executive.world.model import World

__all__ = ["check_placed", "closest_call", "failure_of", "is_terminal"]


def failure_of(child: py_trees.behaviour.Behaviour, robot: Any) -> dict[str, Any]:
    """The detectors' verdict if they flagged one, else the failed behaviour's own message.

    Args:
        child: the failed subtree.
        robot: the robot (its ``failure``: the detectors' verdict, or None).

    Returns:
        The ``failure`` line's fields: ``mode``, ``detail``, ``behaviour``; with a verdict also
        ``time``, ``bodies`` and ``force``.
    """
    tip = child.tip()
    message = tip.feedback_message if tip is not None else ""
    found = robot.failure
    if found is not None:
        return {
            "mode": found.mode,
            "detail": found.detail,
            "behaviour": tip.name if tip else "",
            "time": found.time,
            "bodies": list(found.bodies),
            "force": found.force,
        }
    mode = behaviour_failure(tip, 0.0).mode
    return {"mode": mode, "detail": message, "behaviour": tip.name if tip else ""}


def is_terminal(failure: dict[str, Any]) -> bool:
    """Whether ``failure`` ends the task at once: nothing is re-tried on a robot that may not stand."""
    mode = mode_of_verdict(failure["mode"])
    return mode is not None and failure_mode(mode).terminal


def check_placed(
    kind: TaskKind, task: Task, estimate: World, robot: Any, log: AuditLog, name: str
) -> dict[str, Any] | None:
    """The task kind's check of what a succeeded subtree did; a passed check is logged.

    Args:
        kind: the task's kind (its ``verify``).
        task: the task.
        estimate: the estimate world.
        robot: the robot (its ``detector``, if it has one).
        log: the audit log.
        name: the selector's name (the log line's ``task``).

    Returns:
        The failure's fields if the check failed; None: done as asked, or nothing to check.
    """
    detector = getattr(robot, "detector", None)
    if detector is None:
        return None
    verdict = kind.verify(task, estimate, detector)
    if verdict is None:
        return None
    if verdict.ok:
        log.record(verdict.event, task=name, **verdict.fields)
        return None
    return verdict.fields


def closest_call(robot: Any) -> dict[str, Any] | None:
    """The detectors' near-miss record of the run so far (None: no detector keeps one)."""
    call = getattr(getattr(robot, "detector", None), "closest_call", None)
    if call is None:
        return None
    return {
        "distance": call.distance if math.isfinite(call.distance) else None,  # m; None: beyond horizon
        "bodies": list(call.distance_bodies),
        "time": call.distance_time,
        "ignored_force": call.ignored_force,
        "ignored_bodies": list(call.ignored_bodies),
        "self_contacts": call.self_contacts,
        "summary": call.describe(),
    }
