"""Where the object is relative to a hand about to close on it, and how far off it may be.

:func:`grasp_error` measures the pre-grasp error (along the jaws, across them, in yaw);
:func:`grasp_tolerance` the largest error per axis a grasp survives; and
:func:`tolerance_probabilities` the chance that a Gaussian object pose error exceeds each.

Usage::

    err = grasp_error(hand_position, hand_rotation, object_position, object_rotation)
    tol = grasp_tolerance(world, "left", "book")
    p_axes = tolerance_probabilities(err, tol, position_sigma=0.01, yaw_sigma=0.05)
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from executive.risk.gaussian import exceed_probability
from executive.risk.hand_span import hand_span
from executive.risk.model_geometry import half_extent
from executive.world.model import World

__all__ = [
    "AXIS_SNAP",
    "GraspError",
    "GraspTolerance",
    "closing_axis",
    "grasp_error",
    "grasp_tolerance",
    "has_slide_jaws",
    "is_axisymmetric",
    "tolerance_probabilities",
]

FloatArray = NDArray[np.float64]
#: A hand's closing axis within this angle of the object's y is taken as its y (the grasp across
#: its width that the hand meant; the residual turn is the yaw error the tolerances judge).
AXIS_SNAP = np.radians(10.0)


@dataclass(frozen=True)
class GraspError:
    """Where the object's grasp point is relative to the hand at grasp time (horizontal).

    closing: m, along the horizontal projection of the hand's closing axis (site y);
    lateral: m, horizontal and perpendicular to it; yaw: rad, in (-pi/2, pi/2], the rotation
    of the object's closing axis relative to the hand's (0 for an axisymmetric object).
    """

    closing: float
    lateral: float
    yaw: float

    @property
    def translational(self) -> float:
        return float(np.hypot(self.closing, self.lateral))


@dataclass(frozen=True)
class GraspTolerance:
    """Largest |error| per axis that a grasp survives (m, m, rad); see :func:`grasp_tolerance`."""

    closing: float
    lateral: float
    yaw: float


def _wrap_half_pi(angle: float) -> float:
    """Angle modulo pi into (-pi/2, pi/2] (a jaw's closing axis is a line, not a direction)."""
    wrapped = float(np.mod(angle + np.pi / 2.0, np.pi) - np.pi / 2.0)
    return np.pi / 2.0 if wrapped == -np.pi / 2.0 else wrapped


def _horizontal_axes(hand_rotation: FloatArray) -> tuple[FloatArray, FloatArray]:
    y = np.array(hand_rotation[:, 1], dtype=float)
    y[2] = 0.0
    norm = float(np.linalg.norm(y))
    if norm < 1e-9:
        raise ValueError("grasp_error: the hand's closing axis (site y) is vertical")
    y /= norm
    return y, np.array([y[1], -y[0], 0.0])  # closing, lateral = closing x z


def grasp_error(
    hand_position: ArrayLike,
    hand_rotation: ArrayLike,
    object_position: ArrayLike,
    object_rotation: ArrayLike,
    *,
    closing_axis_object: ArrayLike = (0.0, 1.0, 0.0),
    axisymmetric: bool = False,
) -> GraspError:
    """Pre-grasp error of a hand pose (site position, rotation with columns x y z) vs an object pose.

    The object's grasp point is its centre; ``closing_axis_object`` is the object-frame axis
    the jaws should close along (the book's width, y).
    """
    hp = np.asarray(hand_position, dtype=float).reshape(3)
    hr = np.asarray(hand_rotation, dtype=float).reshape(3, 3)
    op = np.asarray(object_position, dtype=float).reshape(3)
    orot = np.asarray(object_rotation, dtype=float).reshape(3, 3)
    closing, lateral = _horizontal_axes(hr)
    offset = op - hp
    offset[2] = 0.0
    yaw = 0.0
    if not axisymmetric:
        axis = orot @ np.asarray(closing_axis_object, dtype=float).reshape(3)
        if np.hypot(axis[0], axis[1]) > 1e-9:
            yaw = _wrap_half_pi(float(np.arctan2(axis[1], axis[0]) - np.arctan2(closing[1], closing[0])))
    return GraspError(float(offset @ closing), float(offset @ lateral), yaw)


def is_axisymmetric(model: mujoco.MjModel, geom: int, rotation: FloatArray) -> bool:
    kind = int(model.geom_type[geom])
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return True
    return kind == mujoco.mjtGeom.mjGEOM_CYLINDER and abs(float(rotation[2, 2])) > 0.99


def has_slide_jaws(world: World, side: str) -> bool:
    """Whether the ``side`` gripper's actuators all drive slide joints (parallel jaws, as the
    bundled humanoid's), not a dexterous hand's hinges (the G1's Dex3)."""
    model = world.model
    acts = world.ids.gripper_actuators[side]
    return bool(acts) and all(
        model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
        and model.jnt_type[int(model.actuator_trnid[a, 0])] == mujoco.mjtJoint.mjJNT_SLIDE
        for a in acts
    )


def closing_axis(object_rotation: FloatArray, hand_rotation: FloatArray) -> tuple[float, float, float]:
    """The axis (object frame, unit) the hand's jaws close along: its site's y turned into the object's frame.

    Within :data:`AXIS_SNAP` of the object's y either way it is that y, (0, 1, 0): a grasp across
    the object's width, as every grasp from above closes.
    """
    axis = np.asarray(object_rotation, dtype=float).T @ np.asarray(hand_rotation, dtype=float)[:, 1]
    if abs(float(axis[1])) >= float(np.cos(AXIS_SNAP)):
        return (0.0, 1.0, 0.0)
    axis /= float(np.linalg.norm(axis))
    return (float(axis[0]), float(axis[1]), float(axis[2]))


def grasp_tolerance(
    world: World,
    side: str,
    obj: str,
    *,
    jaw_opening: float | None = None,
    closing_axis_object: ArrayLike = (0.0, 1.0, 0.0),
) -> GraspTolerance:
    """Geometric tolerances of a parallel-jaw grasp of ``obj`` by the ``side`` hand.

    closing: (jaw opening - object width) / 2, the jaw clearance; lateral: half the object's
    extent across the jaws (the pads must land on it); yaw: the largest rotation at which the
    object still fits between the open jaws, w cos t + L sin t <= opening (pi/2 if it always
    fits, 0 if it never does). jaw_opening None: the sum over the gripper's actuators of
    (open - closed) when they drive slide joints measured from touching pads; for any other
    hand (the G1's Dex3) the free span between its open thumb and fingers across the site,
    measured on the model (:func:`executive.risk.hand_span.hand_span`). See
    docs/hold_and_grasp.md.
    """
    model = world.model
    if side not in world.profile.arms:
        raise ValueError(f"grasp_tolerance: no arm '{side}'; the profile has {sorted(world.profile.arms)}")
    if obj not in world.ids.object_geoms:
        raise ValueError(f"grasp_tolerance: no object '{obj}'; objects: {sorted(world.ids.object_geoms)}")
    if jaw_opening is None:
        grip = world.profile.arms[side].gripper
        if has_slide_jaws(world, side):
            jaw_opening = float(sum(abs(o - c) for o, c in zip(grip.open, grip.closed, strict=True)))
        else:  # a dexterous hand: the opening its open fingers and thumb leave, measured
            jaw_opening = hand_span(world, side).opening
    geom = world.ids.object_geoms[obj]
    c_axis = np.asarray(closing_axis_object, dtype=float).reshape(3)
    c_axis = c_axis / np.linalg.norm(c_axis)
    l_axis = np.cross(c_axis, np.array([0.0, 0.0, 1.0]))
    if np.linalg.norm(l_axis) < 1e-9:
        l_axis = np.array([1.0, 0.0, 0.0])
    l_axis /= np.linalg.norm(l_axis)
    width = 2.0 * half_extent(model, geom, c_axis)
    length = 2.0 * half_extent(model, geom, l_axis)
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    if is_axisymmetric(model, geom, rot):
        yaw = np.pi / 2.0 if width <= jaw_opening else 0.0
    elif width > jaw_opening:
        yaw = 0.0
    else:
        diag = float(np.hypot(width, length))
        yaw = (
            np.pi / 2.0
            if diag <= jaw_opening
            else float(np.arctan2(length, width) - np.arccos(jaw_opening / diag))
        )
    return GraspTolerance(closing=(jaw_opening - width) / 2.0, lateral=length / 2.0, yaw=float(yaw))


def tolerance_probabilities(
    error: GraspError, tolerance: GraspTolerance, position_sigma: float, yaw_sigma: float
) -> FloatArray:
    """Per-axis P(|error| > tolerance) (closing, lateral, yaw) with Gaussian object pose errors.

    The object position error is isotropic in the horizontal plane (sigma per axis), so in
    the hand's horizontal axes it is again N(0, sigma^2) per axis, independent. For
    e ~ N(mu, s^2): P(|e| > t) = Phi(-(t + mu)/s) + Phi(-(t - mu)/s).
    """
    means = np.array([error.closing, error.lateral, error.yaw])
    tols = np.array([tolerance.closing, tolerance.lateral, tolerance.yaw])
    sigmas = np.array([position_sigma, position_sigma, yaw_sigma])
    return exceed_probability(tols, sigmas, means)
