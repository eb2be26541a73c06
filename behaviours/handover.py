"""The handover: the receiving hand grasps, then the giving hand releases and retreats."""

from __future__ import annotations

import py_trees

from behaviours.gripper import Grasp, Release
from behaviours.move_hand import Retreat
from executive.planning.planner import Trajectory

__all__ = ["handover_subtree"]


def handover_subtree(
    name: str, giver: str, receiver: str, obj: str, retreat: Trajectory
) -> py_trees.composites.Sequence:
    """A Sequence: receiver grasps (the giver still holds), giver opens, giver retreats.

    The order keeps the object held by at least one hand at every instant; a
    receiver that fails to get a firm grasp fails the handover before the giver
    lets go.
    """
    return py_trees.composites.Sequence(
        name=name,
        memory=True,
        children=[
            Grasp(f"{receiver}.grasp", receiver, obj),
            Release(f"{giver}.release", giver, obj),
            Retreat(f"{giver}.retreat", retreat, touching=(giver, obj)),
        ],
    )
