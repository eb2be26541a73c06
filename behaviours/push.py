"""Pushing: a hand, jaws closed, comes down behind an object and slides it along the table."""

from __future__ import annotations

import py_trees

from behaviours.move_hand import MoveHand

__all__ = ["Push"]

Status = py_trees.common.Status


class Push(MoveHand):
    """Follow a push step's trajectory with the jaws closed, touching the object it pushes.

    ``touching`` is the (side, object) pair of the push. The detectors are told so
    (``set_phase(pushing=...)``): that hand may touch the object and the object slides on the
    table, away from the hand as it likes (no hold distance: it is not held); the object
    running into anything else, or the robot touching anything else, is still a failure.
    A hand that stalls behind an object too heavy for the arm ends short of its planned end
    and fails as any move does, its message starting ``drop: the push stalled``: the object
    is not brought to its target (the drop mode), the robot stands.
    """

    phase = "push"

    def initialise(self) -> None:
        super().initialise()
        if self.touching is not None:
            self._robot.set_gripper(self.touching[0], closed=True)

    def update(self) -> Status:
        status = super().update()
        if status != Status.FAILURE or self._robot.failure is not None or self.touching is None:
            return status
        # The task failed, not the robot (the drop mode: the object does not reach its target).
        obj = self.touching[1]
        if self.trajectory.carried is not None:  # the hand stopped behind an object it cannot slide
            self.feedback_message = f"drop: the push stalled behind {obj}: {self.feedback_message}"
            self.verdict = "drop"
        else:  # coming down behind it, the hand landed on it: it is nearer than estimated
            self.feedback_message = (
                f"drop: the hand came down on {obj}, not behind it: {self.feedback_message}"
            )
            self.verdict = "drop"
        return status

    def _set_detector_phase(self) -> None:
        holding: dict[str, str] = self.bb.holding
        carried = next(iter(holding.items()), None) if holding else None
        self.robot.detector.set_phase(carried=carried, pushing=self.touching)
