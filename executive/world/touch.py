"""Touch: which hand geoms touch an object in a world's current contacts, and how hard."""

from __future__ import annotations

import mujoco
import numpy as np

from executive.world.model import World

__all__ = ["hand_contacts"]


def hand_contacts(world: World, side: str, obj: str) -> tuple[int, float]:
    """How many distinct hand geoms of ``side`` touch ``obj`` in ``world.data``, and their total
    normal force (N).

    Args:
        world: a world whose data holds current contacts (after ``mj_step`` or ``mj_forward``).
        side: a hand of the robot's profile.
        obj: an object of the scene.

    Returns:
        (number of distinct hand geoms touching, sum of their contacts' normal forces).
    """
    model, data = world.model, world.data
    hand = set(world.ids.hand_bodies[side])
    target = world.ids.object_geoms[obj]
    touching: set[int] = set()
    total = 0.0
    wrench = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        g1, g2 = int(c.geom1), int(c.geom2)
        other = g2 if g1 == target else g1 if g2 == target else -1
        if other < 0 or model.geom_bodyid[other] not in hand:
            continue
        mujoco.mj_contactForce(model, data, i, wrench)  # wrench[0]: normal force in the contact frame
        touching.add(other)
        total += abs(float(wrench[0]))
    return len(touching), total
