"""Geometry of a press: the face under a point, the hand's frame and reach along it, its compliance.

A press pushes a hand site's frame along its +z axis (the way a top-down grasp comes down)
into a point on an obstacle's surface. :func:`surface_at` finds the face (its outward
normal) and how far the point is from it; :func:`press_quat` turns the hand so its z axis
points into that face; :func:`hand_lead` is how far the hand's geoms reach past its site
along that axis (what touches first); :func:`press_compliance` is the hand's static
compliance along it under the arm's position servos (m/N): a target that far beyond the
surface per newton makes the servos push with that force on a rigid panel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.schema.types import Body
from executive.world.model import World

__all__ = ["Surface", "hand_lead", "press_compliance", "press_quat", "servo_shift", "surface_at"]

FloatArray = NDArray[np.float64]
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Surface:
    """The face of a body nearest a point: its outward unit normal and the point's signed distance (m)."""

    normal: FloatArray
    distance: float  # > 0 outside the body, < 0 inside


def _rotation(rpy: tuple[float, float, float]) -> FloatArray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), the scenario's convention."""
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, np.asarray(rpy, dtype=float), "XYZ")
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)


def surface_at(body: Body, point: FloatArray) -> Surface:
    """The face of ``body`` (box, cylinder along its local z, or sphere) nearest ``point``.

    Args:
        body: a scene body (its centre, orientation and full sizes).
        point: a world point (m).

    Returns:
        The face's outward normal (world frame) and the point's signed distance from it.
    """
    rot = _rotation(body.orientation_rad)
    local = rot.T @ (np.asarray(point, dtype=float) - np.asarray(body.position))
    if body.shape == "sphere":
        r = float(np.linalg.norm(local))
        normal = local / r if r > 0 else np.array([0.0, 0.0, 1.0])
        return Surface(rot @ normal, r - body.size[0])
    if body.shape == "cylinder":
        radius, half = body.size[0], body.size[1] / 2
        rho = math.hypot(local[0], local[1])
        radial, axial = rho - radius, abs(local[2]) - half
        if axial >= radial or rho == 0.0:
            normal = np.array([0.0, 0.0, math.copysign(1.0, local[2])])
        else:
            normal = np.array([local[0] / rho, local[1] / rho, 0.0])
        outside = math.hypot(max(radial, 0.0), max(axial, 0.0))
        return Surface(rot @ normal, outside if outside > 0 else max(radial, axial))
    half_sizes = np.asarray(body.size, dtype=float) / 2
    excess = np.abs(local) - half_sizes
    axis = int(np.argmax(excess))
    normal = np.zeros(3)
    normal[axis] = math.copysign(1.0, local[axis])
    outside = float(np.linalg.norm(np.maximum(excess, 0.0)))
    return Surface(rot @ normal, outside if outside > 0 else float(excess[axis]))


def press_quat(closing: FloatArray, normal: FloatArray) -> FloatArray:
    """Hand site frame (w x y z) with +z into the face (along -``normal``), +y near ``closing``.

    ``closing``: the direction the hand's jaws prefer to close along (its home frame's, or the
    profile's), projected onto the face; the face's horizontal direction when it is along z.
    """
    z_axis = -np.asarray(normal, dtype=float)
    y_axis = np.asarray(closing, dtype=float) - float(np.dot(closing, z_axis)) * z_axis
    if np.linalg.norm(y_axis) < 1e-6:
        y_axis = np.cross(z_axis, UP) if abs(z_axis[2]) < 0.99 else np.array([0.0, 1.0, 0.0])
    y_axis /= np.linalg.norm(y_axis)
    x_axis = np.cross(y_axis, z_axis)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x_axis, y_axis, z_axis]).ravel())
    return quat


def _support(model: mujoco.MjModel, geom: int, axes: FloatArray, direction: FloatArray) -> float:
    """How far geom ``geom`` reaches from its centre along unit ``direction`` (its axes as columns)."""
    size = model.geom_size[geom]
    along = np.abs(axes.T @ direction)  # |cos| of each geom axis with the direction
    kind = int(model.geom_type[geom])
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return float(np.dot(size, along))
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return float(size[0] + size[1] * along[2])
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return float(size[1] * along[2] + size[0] * math.sqrt(max(0.0, 1.0 - along[2] ** 2)))
    if kind == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        return float(np.linalg.norm(size * (axes.T @ direction)))
    mesh = int(model.geom_dataid[geom])
    if kind == mujoco.mjtGeom.mjGEOM_MESH and mesh >= 0:  # its vertices, in the geom's frame
        start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        return float(np.max(model.mesh_vert[start : start + count] @ (axes.T @ direction)))
    return float(model.geom_rbound[geom])  # anything else: its bounding sphere


def hand_lead(world: World, side: str) -> float:
    """How far ``side``'s hand geoms reach past its site along the site's +z axis (m), gripper closed.

    A press pushes with the closed hand (open jaws would straddle a small button). Negative when
    the site itself is ahead of every geom.
    """
    model = world.model
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, world.ids.keyframe)
    gripper = world.profile.arms[side].gripper
    for actuator, closed in zip(world.ids.gripper_actuators[side], gripper.closed, strict=True):
        if model.actuator_trntype[actuator] == mujoco.mjtTrn.mjTRN_JOINT:  # a position servo's target
            data.qpos[int(model.jnt_qposadr[int(model.actuator_trnid[actuator, 0])])] = closed
    mujoco.mj_kinematics(model, data)
    site = world.ids.hand_sites[side]
    rot = data.site_xmat[site].reshape(3, 3)
    origin = data.site_xpos[site]
    bodies = set(world.ids.hand_bodies[side])
    lead = -math.inf
    for geom in world.ids.robot_geoms:
        if int(model.geom_bodyid[geom]) not in bodies:
            continue
        centre = rot.T @ (data.geom_xpos[geom] - origin)
        axes = rot.T @ data.geom_xmat[geom].reshape(3, 3)
        lead = max(lead, float(centre[2]) + _support(model, geom, axes, np.array([0.0, 0.0, 1.0])))
    return lead


def servo_shift(world: World, data: mujoco.MjData, side: str, direction: FloatArray) -> FloatArray:
    """Servo target shift (full-model qpos layout) per newton the hand is to push along ``direction``.

    A position servo of stiffness ``kp`` pushes ``kp (target - q)``; for the hand, held still by
    a rigid surface, to push with force ``F`` along ``direction`` its joints must add the torques
    ``J^T F`` (``J``: the hand site's translational Jacobian), so joint ``j``'s target moves by
    ``J_j^T F / kp_j`` (Salisbury 1980, active stiffness control). Arm and waist joints only: the
    legs stand on the floor, their servos are fed their own load.

    Args:
        world: the world whose model and profile give the joints and their servo gains.
        data: a state of that model with its kinematics computed (``mj_kinematics``, ``mj_comPos``).
        side: the pressing hand.
        direction: the unit direction of the force the hand exerts.

    Returns:
        The shift of the servo targets per newton (zero outside the arm and waist joints).
    """
    model = world.model
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites[side])
    joints = set(world.ids.arm_joints[side])
    joints |= {int(model.joint(n).id) for n in world.profile.waist_joints}
    along = np.asarray(direction, dtype=float) @ jac
    shift = np.zeros(model.nq)
    for a in range(model.nu):
        joint = int(model.actuator_trnid[a, 0])
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or joint not in joints:
            continue
        kp = float(model.actuator_gainprm[a, 0])
        if kp > 0:
            shift[int(model.jnt_qposadr[joint])] = float(along[int(model.jnt_dofadr[joint])]) / kp
    return shift


def press_compliance(world: World, side: str, qpos: FloatArray, direction: FloatArray) -> float:
    """The hand's static compliance along ``direction`` (m/N) under its arm's and waist's servos.

    A force ``F`` on the hand moves it by ``J K^-1 J^T F`` (``K``: the servos' stiffnesses): the
    joints give way by :func:`servo_shift` per newton, the hand by ``J`` times that.

    Args:
        world: the world whose model and profile give the joints and their servo gains.
        side: the pressing hand.
        qpos: the configuration (full-model qpos) the Jacobian is taken at.
        direction: the unit direction of the force.

    Returns:
        Metres of hand displacement along ``direction`` per newton along it.
    """
    model = world.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    shift = servo_shift(world, data, side, direction)
    jac = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jac, None, world.ids.hand_sites[side])
    along = np.asarray(direction, dtype=float) @ jac
    hinge = model.jnt_type == mujoco.mjtJoint.mjJNT_HINGE
    hinge |= model.jnt_type == mujoco.mjtJoint.mjJNT_SLIDE
    qadr, dadr = model.jnt_qposadr[hinge], model.jnt_dofadr[hinge]
    return float(np.dot(along[dadr], shift[qadr]))
