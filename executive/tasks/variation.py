"""What of the scene a task depends on that a scene variant may move: its varied points.

A fidelity suite (:mod:`executive.validation.variants`) draws variants of a scenario's scene:
objects and obstacles shift, turn, change size, mass and friction. A task whose block names a
point of that scene (a transfer's target, a press's point on its button) must move with it, or
the variant is not the same task on another scene. Each task kind says which of its block's
points a variant moves, and how, through :meth:`executive.tasks.base.TaskKind.varied_points`:

* a point drawn on its own (``follows`` empty): a target, shifted within the suite's target range;
* a point that ``follows`` a scene body: it moves exactly as that body does (a press's point on
  the top of the button it presses).

``places`` names the object the task leaves at the point (a transfer's, a place's, a push's), so
the variant checks that object's clearance there, against the scene as the tasks before left it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["VariedPoint"]


@dataclass(frozen=True)
class VariedPoint:
    """A point of a task's YAML block that a scene variant moves.

    Attributes:
        key: the block's key that holds it (``to``, ``point``).
        point: (x, y, z) as the task has it; z None for a point on the table top (it follows
            the table's height).
        follows: the scene body it moves with ("" : drawn on its own within the target range).
        places: the object the task leaves at the point ("" : none).
        yaw_rad: that object's yaw there (None: it keeps its own).
    """

    key: str
    point: tuple[float, float, float | None]
    follows: str = ""
    places: str = ""
    yaw_rad: float | None = None
