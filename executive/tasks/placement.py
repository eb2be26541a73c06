"""Where a task puts an object down, and whether it came to rest there.

Shared by the kinds that put an object down (``transfer``, ``place``, and the handover
and regrasp a transfer is made of): :class:`Destination` is what such a task gives
(object, ``to``, ``to_yaw_rad``), :func:`target_placement` the object's centre and yaw
there, :func:`placed_verdict` the failure detector's check afterwards.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from executive.schema.types import Body
from executive.tasks.base import Verdict
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["Destination", "Placement", "placed_verdict", "target_placement"]


class Destination(Protocol):
    """A task that puts ``object`` at ``to`` (centre x, y[, z]; z None: resting on the table).

    ``to_yaw_rad`` None keeps the object's yaw. A transfer's and a place's task are ones.
    """

    @property
    def object(self) -> str: ...

    @property
    def to(self) -> tuple[float, float, float | None]: ...

    @property
    def to_yaw_rad(self) -> float | None: ...


@dataclass(frozen=True)
class Placement:
    """Where an object goes: its centre, its yaw, the hand site's height above its centre."""

    centre: np.ndarray
    yaw: float
    site_above_centre: float


def target_placement(
    world: World,
    body: Body,
    to: tuple[float, float, float | None],
    yaw: float | None,
    site_above_centre: float,
) -> Placement:
    """The placement of ``body`` at ``to`` (z None: resting on the table), yaw None: ``body``'s current."""
    scene = world.scenario.scene
    z = to[2] if to[2] is not None else scene.table.height + body.half_height()
    _, quat = world.object_pose(body.name)
    return Placement(np.array([to[0], to[1], z]), yaw if yaw is not None else yaw_of(quat), site_above_centre)


def placed_verdict(
    world: World, detector: object, obj: str, to: tuple[float, float, float | None], to_yaw: float | None
) -> Verdict | None:
    """The detector's verdict on ``obj`` resting at ``to`` (None: no detector that can tell)."""
    check = getattr(detector, "check_placed", None)
    if check is None:
        return None
    body = next(b for b in world.scenario.scene.objects if b.name == obj)
    yaw = to_yaw if to_yaw is not None else body.orientation_rad[2]
    found = check(obj, (to[0], to[1]), yaw, body.yaw_symmetry)
    if found is None:
        return Verdict(True, "placed", {"object": obj, "target": list(to)})
    fields = {"mode": found.mode, "detail": found.detail, "behaviour": "placement", "time": found.time}
    return Verdict(False, "failure", fields, found)
