"""A hand's grip on an object for the hold model: the grip force, the pads and their faces.

:func:`grip` reads it off the model: a parallel jaw's force from its position servos closing on
an object they cannot reach, a thumb against fingers' from their squeeze
(:func:`executive.risk.hand_grip.dexterous_squeeze`); the pads' contact parameters from
:mod:`executive.risk.hold_contact`.

Usage::

    g = grip(world, "left", "book", closing_axis_object=np.array([0.0, 1.0, 0.0]))
    g.force, g.contact.mu
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.risk.hand_grip import dexterous_squeeze
from executive.risk.hand_span import posed_hand
from executive.risk.hold_contact import ContactParameters, contact_parameters
from executive.risk.model_geometry import body_half_extent
from executive.world.model import World

__all__ = ["Grip", "HoldModelUnavailable", "grip"]

FloatArray = NDArray[np.float64]


class HoldModelUnavailable(ExecutiveError):
    """The hold model cannot describe this hand (e.g. no parallel jaws on slide joints)."""


@dataclass(frozen=True)
class Grip:
    """One hand's parallel jaw closed on an object.

    force: N, normal force of each pad on the object; pads: the pad geom ids; pad_centre /
    pad_half: each pad's centre and half extents along the hand site's x (lateral) and z
    (approach) axes, in the site frame (m); contact: the pad-object contact parameters at
    nominal friction; inv_weight: MuJoCo's body_invweight0 (translation) of pad body + object.
    """

    side: str
    force: float
    pads: tuple[int, ...]
    pad_centre: FloatArray  # (2,) x z
    pad_half: FloatArray  # (2,) x z
    contact: ContactParameters
    inv_weight: float
    impratio: float
    half_width: float  # m, the object's half width across the jaws
    pad_friction_wins: bool  # the pad's priority is higher: the object's friction never counts


def _pad_geom(model: mujoco.MjModel, body: int) -> int:
    """The collidable geom of a finger body with the highest priority (then condim): its pad."""
    geoms = [
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] == body and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]
    if not geoms:
        raise HoldModelUnavailable(f"finger body {body} has no collidable geom")
    return max(geoms, key=lambda g: (int(model.geom_priority[g]), int(model.geom_condim[g]), -g))


def _servo_force(model: mujoco.MjModel, actuator: int, q_contact: float, q_closed: float) -> float:
    """Force of a position servo holding at q_contact while told q_closed: kp |error|, clipped."""
    kp = float(model.actuator_gainprm[actuator, 0])
    force = kp * abs(q_contact - q_closed)
    if model.actuator_forcelimited[actuator]:
        force = min(force, float(np.max(np.abs(model.actuator_forcerange[actuator]))))
    return force


def grip(world: World, side: str, obj: str, closing_axis_object: FloatArray) -> Grip:
    """The ``side`` hand's jaw closed on ``obj`` across ``closing_axis_object`` (object frame).

    Args:
        world: the estimate world (its data places the pads in the hand; any pose will do).
        side: an arm of the profile.
        obj: an object of the scene.
        closing_axis_object: unit vector, the jaws' closing axis in the object's body frame.

    Returns:
        The :class:`Grip`.

    Raises:
        HoldModelUnavailable: the gripper's actuators are not position servos on joints, or a
            hand without slide jaws has no thumb opposing its fingers, so no grip force can be
            read off the model.

    A hand whose servos drive hinge joints (the G1's Dex3) is a thumb against fingers: its
    force is their squeeze at the closed targets (:func:`executive.risk.hand_grip.dexterous_squeeze`)
    and its pads the chains' contact geoms (:func:`_dexterous_grip`).
    """
    model, data = world.model, world.data
    acts = world.ids.gripper_actuators[side]
    joints = [int(model.actuator_trnid[a, 0]) for a in acts]
    if not acts or any(
        model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT
        or model.actuator_biastype[a] != mujoco.mjtBias.mjBIAS_AFFINE
        for a in acts
    ):
        raise HoldModelUnavailable(
            f"the {side} gripper's actuators are not position servos on joints; "
            "the hold model does not cover it"
        )
    if any(model.jnt_type[j] != mujoco.mjtJoint.mjJNT_SLIDE for j in joints):
        return _dexterous_grip(world, side, obj, np.asarray(closing_axis_object, dtype=float))
    geom = world.ids.object_geoms[obj]
    width = 2.0 * body_half_extent(model, geom, np.asarray(closing_axis_object, dtype=float))
    closed = world.profile.arms[side].gripper.closed
    force = min(_servo_force(model, a, width / 2.0, c) for a, c in zip(acts, closed, strict=True))
    pads = tuple(_pad_geom(model, int(model.jnt_bodyid[j])) for j in joints)
    site = world.ids.hand_sites[side]
    rot = data.site_xmat[site].reshape(3, 3)
    centres, halves = [], []
    for pad in pads:
        rel = rot.T @ data.geom_xmat[pad].reshape(3, 3)
        centres.append(rot.T @ (data.geom_xpos[pad] - data.site_xpos[site]))
        halves.append(np.abs(rel) @ model.geom_size[pad])
    centre, half = np.mean(centres, axis=0), np.min(halves, axis=0)
    body_pad, body_obj = int(model.geom_bodyid[pads[0]]), int(model.geom_bodyid[geom])
    pa, pb = int(model.geom_priority[pads[0]]), int(model.geom_priority[geom])
    wins = pa > pb
    return Grip(
        side=side,
        force=force,
        pads=pads,
        pad_centre=np.array([centre[0], centre[2]]),
        pad_half=np.array([half[0], half[2]]),
        contact=contact_parameters(model, pads[0], geom),
        inv_weight=float(model.body_invweight0[body_pad, 0] + model.body_invweight0[body_obj, 0]),
        impratio=float(model.opt.impratio),
        half_width=width / 2.0,
        pad_friction_wins=bool(wins),
    )


def _dexterous_grip(world: World, side: str, obj: str, closing_axis_object: FloatArray) -> Grip:
    """A thumb-against-fingers hand's :class:`Grip` on ``obj``: the squeeze of its chains.

    The pads are the chains' contact geoms at the closed targets; the patch the object's
    overlap with their contact points' spread across the site's x and z (each point widened
    by its geom's half extent along those axes, the thumb's and the fingers' the smaller).
    """
    model = world.model
    geom = world.ids.object_geoms[obj]
    width = 2.0 * body_half_extent(model, geom, closing_axis_object)
    try:
        squeeze = dexterous_squeeze(world, side, width)
    except ValueError as exc:
        raise HoldModelUnavailable(str(exc)) from exc
    data = posed_hand(world, side, tuple(world.profile.arms[side].gripper.closed))
    rot = data.site_xmat[world.ids.hand_sites[side]].reshape(3, 3)
    sides = []
    for thumb in (True, False):
        chains = [c for c in squeeze.chains if c.thumb == thumb]
        points = np.array([[c.point[0], c.point[2]] for c in chains])
        reach = np.array(
            [
                (np.abs(rot.T @ data.geom_xmat[c.geom].reshape(3, 3)) @ model.geom_aabb[c.geom, 3:])
                for c in chains
            ]
        )
        lo = np.min(points - reach[:, [0, 2]], axis=0)
        hi = np.max(points + reach[:, [0, 2]], axis=0)
        sides.append(((lo + hi) / 2.0, (hi - lo) / 2.0))
    pads = tuple(c.geom for c in squeeze.chains)
    body_pad, body_obj = int(model.geom_bodyid[pads[0]]), int(model.geom_bodyid[geom])
    return Grip(
        side=side,
        force=squeeze.force,
        pads=pads,
        pad_centre=np.mean([c for c, _ in sides], axis=0),
        pad_half=np.min([h for _, h in sides], axis=0),
        contact=contact_parameters(model, pads[0], geom),
        inv_weight=float(model.body_invweight0[body_pad, 0] + model.body_invweight0[body_obj, 0]),
        impratio=float(model.opt.impratio),
        half_width=width / 2.0,
        pad_friction_wins=bool(int(model.geom_priority[pads[0]]) > int(model.geom_priority[geom])),
    )
