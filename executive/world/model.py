"""Builds the MuJoCo world of a scenario: robot + floor + table + objects + obstacles.

Two worlds per run: the *estimate* is the scene as the
robot believes it (nominal poses and parameters at start-up; its objects then
follow what the robot observes, and which hand holds which object, ``World.held``:
:mod:`executive.world.observation`); the *truth* is what physics
runs, sampled from the scenario's ``uncertainty`` block with an injected
``numpy.random.Generator``. The planner and the risk models only ever see the
estimate.

The robot's MJCF is loaded with ``mujoco.MjSpec`` (a copy of the process's cached
parse, :mod:`executive.world.model_cache`) and the scene is added to its world body,
so any robot model with a profile works. The robot's standing
keyframe is re-created over the whole world (robot joints first, then one
free joint per object), under the profile's keyframe name, with the profile's
``home_joints`` angles and every hand at its open pose: the home pose.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import WorldError
from executive.robot.profile import load_profile
from executive.robot.profile_types import RobotProfile
from executive.schema.types import Body, Scenario
from executive.world import model_cache
from executive.world.heading import yaw_quat

__all__ = [
    "Grip",
    "Perturbation",
    "World",
    "WorldIds",
    "build",
    "build_pair",
    "is_descendant",
    "sample_perturbation",
    "subtree_bodies",
]

FloatArray = NDArray[np.float64]

_OBJECT_RGBA = (0.75, 0.25, 0.15, 1.0)
_OBSTACLE_RGBA = (0.25, 0.35, 0.7, 1.0)
_TABLE_RGBA = (0.55, 0.42, 0.3, 1.0)


@dataclass(frozen=True)
class Perturbation:
    """How the truth differs from the estimate; all zero for the estimate itself.

    object_offsets: name -> (dx, dy, dyaw) in m, m, rad.
    obstacle_offsets: name -> (dx, dy) in m.
    object_mass_scale: name -> factor on the object's mass.
    friction_scale: factor on every object's and the table's friction.
    com_offset: (dx, dy) shift of the robot's whole-body CoM in m, made by
        moving the torso's centre of mass (a model error the robot does not know).
    """

    object_offsets: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    obstacle_offsets: dict[str, tuple[float, float]] = field(default_factory=dict)
    object_mass_scale: dict[str, float] = field(default_factory=dict)
    friction_scale: float = 1.0
    com_offset: tuple[float, float] = (0.0, 0.0)

    def is_zero(self) -> bool:
        return (
            all(v == (0.0, 0.0, 0.0) for v in self.object_offsets.values())
            and all(v == (0.0, 0.0) for v in self.obstacle_offsets.values())
            and all(v == 1.0 for v in self.object_mass_scale.values())
            and self.friction_scale == 1.0
            and self.com_offset == (0.0, 0.0)
        )


def sample_perturbation(scenario: Scenario, rng: np.random.Generator) -> Perturbation:
    """Draw a truth from the scenario's 1-sigma uncertainty (Gaussian, independent).

    Draws happen in a fixed order (objects, obstacles, masses, friction, CoM)
    so the same generator state always gives the same truth. Scale factors
    are clipped to stay positive (at 0.2 of nominal).
    """
    u = scenario.uncertainty
    objects = scenario.scene.objects
    object_offsets = {
        b.name: (
            float(rng.normal(0.0, u.object_position)) if u.object_position else 0.0,
            float(rng.normal(0.0, u.object_position)) if u.object_position else 0.0,
            float(rng.normal(0.0, u.object_yaw_rad)) if u.object_yaw_rad else 0.0,
        )
        for b in objects
    }
    obstacle_offsets = {
        b.name: (
            float(rng.normal(0.0, u.obstacle_position)) if u.obstacle_position else 0.0,
            float(rng.normal(0.0, u.obstacle_position)) if u.obstacle_position else 0.0,
        )
        for b in scenario.scene.obstacles
    }
    masses = {
        b.name: max(0.2, 1.0 + float(rng.normal(0.0, u.object_mass))) if u.object_mass else 1.0
        for b in objects
    }
    friction = max(0.2, 1.0 + float(rng.normal(0.0, u.friction))) if u.friction else 1.0
    com = (float(rng.normal(0.0, u.com)), float(rng.normal(0.0, u.com))) if u.com else (0.0, 0.0)
    return Perturbation(object_offsets, obstacle_offsets, masses, friction, com)


@dataclass(frozen=True)
class WorldIds:
    """Indices into the compiled model that the executive uses again and again."""

    base_body: int
    torso_body: int
    head_body: int | None
    robot_bodies: tuple[int, ...]  # every body of the robot's tree
    robot_geoms: tuple[int, ...]  # every collision-capable geom of the robot
    floor_geom: int
    table_geoms: tuple[int, ...]
    object_bodies: dict[str, int]
    object_geoms: dict[str, int]
    object_qpos: dict[str, int]  # qpos address of each object's free joint
    obstacle_geoms: dict[str, int]
    hand_sites: dict[str, int]  # side -> site id
    hand_bodies: dict[str, tuple[int, ...]]  # side -> bodies of the hand subtree
    foot_geoms: dict[str, tuple[int, ...]]  # side -> sole geoms
    arm_joints: dict[str, tuple[int, ...]]  # side -> joint ids
    gripper_actuators: dict[str, tuple[int, ...]]  # side -> actuator ids
    keyframe: int


@dataclass
class Grip:
    """How a hand holds an object: the object's pose in the hand site's frame.

    ``position`` (m) and ``quat`` (w x y z) are the mean of ``looks`` measurements (one per
    observation while held); ``looks`` 0: not measured, the object assumed at the site.
    """

    side: str
    position: FloatArray
    quat: FloatArray
    looks: int


@dataclass
class World:
    """A compiled world: MuJoCo model and data plus what the executive needs to know of them."""

    model: mujoco.MjModel
    data: mujoco.MjData
    scenario: Scenario
    profile: RobotProfile
    kind: Literal["estimate", "truth"]
    perturbation: Perturbation
    ids: WorldIds
    #: object name -> side of the hand that holds it (kept by :mod:`executive.world.observation`)
    held: dict[str, str] = field(default_factory=dict)
    #: object name -> how the holding hand holds it (kept with ``held``)
    grips: dict[str, Grip] = field(default_factory=dict)
    #: the robot's base in ``data`` is where the robot measured it after a walk (else: its start)
    follows_base: bool = False

    def held_by(self, obj: str) -> str | None:
        """The side of the hand that holds ``obj`` (None: no hand holds it).

        Args:
            obj: an object of the scene.

        Returns:
            ``"left"``/``"right"`` (a side of the robot's profile) or None.
        """
        return self.held.get(obj)

    def reset(self) -> None:
        """Put the world in its home state: the robot's standing keyframe, objects at rest, none held."""
        self.held.clear()
        self.grips.clear()
        self.follows_base = False
        mujoco.mj_resetDataKeyframe(self.model, self.data, self.ids.keyframe)
        mujoco.mj_forward(self.model, self.data)

    @property
    def robot_mass(self) -> float:
        return float(self.model.body_subtreemass[self.ids.base_body])

    def own_model(self) -> mujoco.MjModel:
        """The model the robot knows itself by: this world's model with the truth's CoM error
        (``perturbation.com_offset``, a model error the robot does not know) undone, as the
        estimate's. A copy; the world's model itself when it has no such error."""
        dx, dy = self.perturbation.com_offset
        if (dx, dy) == (0.0, 0.0):
            return self.model
        model = copy.copy(self.model)
        torso = self.ids.torso_body
        scale = float(model.body_subtreemass[self.ids.base_body] / model.body_mass[torso])
        model.body_ipos[torso, :2] -= (dx * scale, dy * scale)  # undoes _shift_torso_com
        return model

    def _base_joint(self) -> int:
        """The robot's floating base joint."""
        model = self.model
        return next(
            j
            for j in range(model.njnt)
            if model.jnt_bodyid[j] == self.ids.base_body and model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE
        )

    @property
    def base_qpos(self) -> slice:
        """The robot's floating base in ``qpos`` (position, then quaternion w x y z)."""
        adr = int(self.model.jnt_qposadr[self._base_joint()])
        return slice(adr, adr + 7)

    @property
    def base_qvel(self) -> slice:
        """The robot's floating base in ``qvel`` (linear velocity in the world frame, then angular)."""
        adr = int(self.model.jnt_dofadr[self._base_joint()])
        return slice(adr, adr + 6)

    @property
    def robot_dof(self) -> int:
        """Actuated degrees of freedom of the robot (joints other than its floating base)."""
        return sum(
            1
            for j in range(self.model.njnt)
            if self.model.jnt_bodyid[j] in self.ids.robot_bodies
            and self.model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE
        )

    def home_qpos(self) -> FloatArray:
        return np.array(self.model.key_qpos[self.ids.keyframe], dtype=float)

    def home_ctrl(self) -> FloatArray:
        return np.array(self.model.key_ctrl[self.ids.keyframe], dtype=float)

    def object_pose(self, name: str) -> tuple[FloatArray, FloatArray]:
        """Position and quaternion (w x y z) of an object in the current data."""
        body = self.ids.object_bodies[name]
        return self.data.xpos[body].copy(), self.data.xquat[body].copy()


def build(
    scenario: Scenario,
    perturbation: Perturbation | None = None,
    kind: Literal["estimate", "truth"] | None = None,
) -> World:
    """Compile the world of ``scenario``; with a perturbation, the truth it describes.

    The returned world is reset to its home state.
    """
    pert = perturbation if perturbation is not None else Perturbation()
    world_kind: Literal["estimate", "truth"] = kind or ("estimate" if perturbation is None else "truth")
    profile = load_profile(scenario.robot.profile)
    mjcf = scenario.robot.mjcf
    try:
        spec = model_cache.robot_spec(mjcf)  # a copy of this process's parse of the MJCF
    except Exception as exc:  # mujoco raises ValueError with the parser's text
        raise WorldError(f"{mjcf}: MuJoCo could not load the robot model: {exc}") from exc

    key_qpos, key_ctrl = _take_keyframe(spec, profile, str(mjcf))
    _add_hand_sites(spec, profile, str(mjcf))
    _check_names_free(spec, scenario, str(mjcf))
    _shift_torso_com(spec, profile, pert.com_offset, mjcf)
    # Grasping wants elliptic friction cones with a high impedance ratio (MuJoCo docs, "Contact").
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = max(spec.option.impratio, 10.0)
    spec.visual.global_.offwidth = max(spec.visual.global_.offwidth, 1600)
    spec.visual.global_.offheight = max(spec.visual.global_.offheight, 1200)

    floor_name = _add_floor(spec)
    table_names = _add_table(spec, scenario, pert.friction_scale)
    object_qpos: list[float] = []
    for body in scenario.scene.objects:
        dx, dy, dyaw = pert.object_offsets.get(body.name, (0.0, 0.0, 0.0))
        mass = float(body.mass or 0.0) * pert.object_mass_scale.get(body.name, 1.0)
        pos, quat = _pose(body, dx, dy, dyaw)
        _add_object(spec, body, pos, quat, mass, pert.friction_scale)
        object_qpos.extend([*pos, *quat])
    for body in scenario.scene.obstacles:
        dx, dy = pert.obstacle_offsets.get(body.name, (0.0, 0.0))
        pos, quat = _pose(body, dx, dy, 0.0)
        _add_obstacle(spec, body, pos, quat)

    spec.add_key(name=profile.keyframe, qpos=[*key_qpos, *object_qpos], ctrl=list(key_ctrl))
    try:
        model = spec.compile()
    except Exception as exc:
        raise WorldError(_compile_message(scenario, str(exc))) from exc
    data = mujoco.MjData(model)
    ids = _collect_ids(model, profile, scenario, floor_name, table_names)
    _set_home_joints(model, profile, ids.keyframe)
    _open_hands_at_home(model, profile, ids)
    world = World(model, data, scenario, profile, world_kind, pert, ids)
    world.reset()
    return world


def _compile_message(scenario: Scenario, error: str) -> str:
    """Blame a compile error on the scene element MuJoCo names (an object's size or mass), else the model."""
    source = scenario.source or scenario.name
    text = " ".join(error.split())
    for group, bodies in (("objects", scenario.scene.objects), ("obstacles", scenario.scene.obstacles)):
        for i, body in enumerate(bodies):
            if f"Element name '{body.name}'" in error:
                what = f"size {list(body.size)} m" + (
                    f", mass {body.mass:g} kg" if body.mass is not None else ""
                )
                return (
                    f"{source}: scene.{group}[{i}].size: the scene did not compile because of '{body.name}' "
                    f"({what}): {text}; its size (or mass) is too small for MuJoCo"
                )
    return f"{source}: the scene did not compile with the robot model {scenario.robot.mjcf}: {text}"


def build_pair(scenario: Scenario, rng: np.random.Generator) -> tuple[World, World]:
    """The estimate world and a truth world sampled with ``rng``."""
    return build(scenario), build(scenario, sample_perturbation(scenario, rng), kind="truth")


# --- spec editing -------------------------------------------------------------------------


def _take_keyframe(
    spec: mujoco.MjSpec, profile: RobotProfile, source: str
) -> tuple[list[float], list[float]]:
    """Remove every keyframe from the robot's spec, returning the profile's (qpos, ctrl)."""
    keys = list(spec.keys)
    chosen = next((k for k in keys if k.name == profile.keyframe), None)
    if chosen is None:
        names = ", ".join(k.name or "(unnamed)" for k in keys) or "(none)"
        raise WorldError(
            f"{source}: the profile names keyframe '{profile.keyframe}' but the model has: {names}"
        )
    qpos = [float(v) for v in chosen.qpos]
    ctrl = [float(v) for v in chosen.ctrl]
    for key in keys:
        spec.delete(key)
    return qpos, ctrl


def _add_hand_sites(spec: mujoco.MjSpec, profile: RobotProfile, source: str) -> None:
    """Add a grasp-frame site for every hand the profile gives as body + offset."""
    for side, arm in profile.arms.items():
        if arm.hand.site is not None:
            continue
        name = arm.hand.body or arm.hand_body
        parent = spec.body(name)
        if parent is None:
            raise WorldError(f"{source}: no body '{name}' (the profile's {side} hand frame body)")
        parent.add_site(
            name=f"executive_{side}_hand",
            pos=list(arm.hand.offset),
            quat=list(arm.hand.quat),
            size=[0.01, 0.01, 0.01],
            group=5,
        )


def _check_names_free(spec: mujoco.MjSpec, scenario: Scenario, source: str) -> None:
    """Scene bodies are named after the scenario; they must not clash with the robot's names."""
    taken = {b.name for b in spec.bodies} | {g.name for g in spec.geoms}
    taken |= {"table", "table_top", "floor"} | {f"table_leg_{i}" for i in range(4)}
    for group, bodies in (("objects", scenario.scene.objects), ("obstacles", scenario.scene.obstacles)):
        for i, body in enumerate(bodies):
            if body.name in taken:
                raise WorldError(
                    f"{scenario.source or scenario.name}: scene.{group}[{i}].name: '{body.name}' is already "
                    f"a body or geom name in the robot model {source} (or a reserved scene name); rename it"
                )


def _shift_torso_com(
    spec: mujoco.MjSpec, profile: RobotProfile, offset: tuple[float, float], mjcf: Path
) -> None:
    """Move the whole-body CoM by ``offset`` by moving the torso's own CoM (mass-weighted)."""
    if offset == (0.0, 0.0):
        return
    torso = spec.body(profile.torso_body)
    if torso is None:
        raise WorldError(f"{mjcf}: no body '{profile.torso_body}' (the profile's torso_body)")
    # The compiled masses (MjSpec holds only what the file states explicitly): one compile
    # of the robot per process, kept by the model cache.
    inertial = model_cache.torso_inertia(mjcf, profile.base_body, profile.torso_body, spec.compile)
    scale = inertial.total_mass / inertial.mass
    # Shift in the torso frame: at the keyframe the torso is upright and faces +x, so
    # world xy and torso xy agree to first order.
    torso.explicitinertial = True
    if not torso.mass:
        torso.mass = inertial.mass
        torso.inertia = inertial.inertia
        torso.ipos = inertial.ipos
        torso.iquat = inertial.iquat
    torso.ipos = [torso.ipos[0] + offset[0] * scale, torso.ipos[1] + offset[1] * scale, torso.ipos[2]]


def _add_floor(spec: mujoco.MjSpec) -> str:
    """Add a checkered floor plane named ``floor`` unless the model already has a plane."""
    for geom in spec.worldbody.geoms:
        if geom.type == mujoco.mjtGeom.mjGEOM_PLANE:
            return str(geom.name or "")
    spec.add_texture(
        name="executive_floor_tex",
        type=mujoco.mjtTexture.mjTEXTURE_2D,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER,
        rgb1=[0.32, 0.34, 0.36],
        rgb2=[0.26, 0.28, 0.3],
        width=300,
        height=300,
    )
    spec.add_material(name="executive_floor_mat", texrepeat=[8, 8], reflectance=0.1).textures[
        mujoco.mjtTextureRole.mjTEXROLE_RGB
    ] = "executive_floor_tex"
    spec.worldbody.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[6.0, 6.0, 0.05],
        material="executive_floor_mat",
    )
    spec.worldbody.add_light(name="executive_key_light", pos=[1.0, 1.5, 3.0], dir=[-0.3, -0.4, -1.0])
    spec.worldbody.add_light(name="executive_fill_light", pos=[-1.5, -1.0, 3.0], dir=[0.4, 0.3, -1.0])
    return "floor"


def _add_table(spec: mujoco.MjSpec, scenario: Scenario, friction_scale: float) -> list[str]:
    table = scenario.scene.table
    sx, sy, thick = table.size
    body = spec.worldbody.add_body(
        name="table",
        pos=[table.position[0], table.position[1], 0.0],
        quat=yaw_quat(table.yaw_rad).tolist(),
    )
    names = ["table_top"]
    body.add_geom(
        name="table_top",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[sx / 2, sy / 2, thick / 2],
        pos=[0.0, 0.0, table.height - thick / 2],
        rgba=list(_TABLE_RGBA),
        friction=[1.0 * friction_scale, 0.005, 0.0001],
    )
    leg = 0.03
    leg_height = table.height - thick
    for i, (ex, ey) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        name = f"table_leg_{i}"
        names.append(name)
        body.add_geom(
            name=name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[leg, leg, leg_height / 2],
            pos=[ex * (sx / 2 - leg), ey * (sy / 2 - leg), leg_height / 2],
            rgba=list(_TABLE_RGBA),
        )
    return names


def _pose(body: Body, dx: float, dy: float, dyaw: float) -> tuple[list[float], list[float]]:
    roll, pitch, yaw = body.orientation_rad
    pos = [body.position[0] + dx, body.position[1] + dy, body.position[2]]
    return pos, _rpy_quat(roll, pitch, yaw + dyaw).tolist()


def _geom_kwargs(body: Body) -> dict[str, object]:
    if body.shape == "box":
        return {"type": mujoco.mjtGeom.mjGEOM_BOX, "size": [s / 2 for s in body.size]}
    if body.shape == "cylinder":
        return {"type": mujoco.mjtGeom.mjGEOM_CYLINDER, "size": [body.size[0], body.size[1] / 2, 0.0]}
    return {"type": mujoco.mjtGeom.mjGEOM_SPHERE, "size": [body.size[0], 0.0, 0.0]}


def _add_object(
    spec: mujoco.MjSpec, body: Body, pos: list[float], quat: list[float], mass: float, friction_scale: float
) -> None:
    b = spec.worldbody.add_body(name=body.name, pos=pos, quat=quat)
    b.add_freejoint(name=f"{body.name}_free")
    b.add_geom(
        name=body.name,
        mass=mass,
        friction=[body.friction * friction_scale, 0.01, 0.001],
        condim=4,
        rgba=list(body.rgba or _OBJECT_RGBA),
        **_geom_kwargs(body),
    )


def _add_obstacle(spec: mujoco.MjSpec, body: Body, pos: list[float], quat: list[float]) -> None:
    b = spec.worldbody.add_body(name=body.name, pos=pos, quat=quat)
    b.add_geom(
        name=body.name,
        friction=[body.friction, 0.005, 0.0001],
        rgba=list(body.rgba or _OBSTACLE_RGBA),
        **_geom_kwargs(body),
    )


def _rpy_quat(roll: float, pitch: float, yaw: float) -> FloatArray:
    """Quaternion (w x y z) of R = Rz(yaw) Ry(pitch) Rx(roll)."""
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, np.array([roll, pitch, yaw]), "XYZ")
    return quat


def _is_position_servo(model: mujoco.MjModel, actuator: int) -> bool:
    """A joint actuator whose control is the joint's target position (affine bias)."""
    return int(model.actuator_trntype[actuator]) == int(mujoco.mjtTrn.mjTRN_JOINT) and int(
        model.actuator_biastype[actuator]
    ) == int(mujoco.mjtBias.mjBIAS_AFFINE)


def _set_home_joints(model: mujoco.MjModel, profile: RobotProfile, key: int) -> None:
    """Replace the keyframe's angles of the profile's ``home_joints`` (and their servos' targets)."""
    for name, value in profile.home_joints.items():
        joint = int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name))
        hinge_or_slide = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        if joint < 0 or int(model.jnt_type[joint]) not in hinge_or_slide:
            raise WorldError(
                f"robot profile '{profile.name}' ({profile.source}): home_joints names '{name}', "
                "which is not a hinge or slide joint of the MJCF model"
            )
        lo, hi = model.jnt_range[joint]
        if model.jnt_limited[joint] and not lo <= value <= hi:
            raise WorldError(
                f"robot profile '{profile.name}' ({profile.source}): home_joints.{name} = {value:g} "
                f"is outside the joint's range [{lo:g}, {hi:g}]"
            )
        model.key_qpos[key, model.jnt_qposadr[joint]] = value
        for actuator in range(model.nu):
            if _is_position_servo(model, actuator) and int(model.actuator_trnid[actuator, 0]) == joint:
                model.key_ctrl[key, actuator] = value


def _open_hands_at_home(model: mujoco.MjModel, profile: RobotProfile, ids: WorldIds) -> None:
    """Start with every hand open: its gripper's targets and joints at the profile's open pose.

    A model's own keyframe may hold its fingers elsewhere (the menagerie's G1 stands with
    the Dex3 thumbs swung in); a grasp begins from the open hand the planner assumes (it
    freezes the finger joints at their start). A gripper actuator that is a position servo
    of one joint has its open target as that joint's position too.
    """
    key = ids.keyframe
    for side, arm in profile.arms.items():
        for actuator, value in zip(ids.gripper_actuators[side], arm.gripper.open, strict=True):
            model.key_ctrl[key, actuator] = value
            if _is_position_servo(model, actuator):
                joint = int(model.actuator_trnid[actuator, 0])
                model.key_qpos[key, model.jnt_qposadr[joint]] = value


# --- ids ----------------------------------------------------------------------------------


def _need(model: mujoco.MjModel, objtype: mujoco.mjtObj, name: str, what: str, profile: RobotProfile) -> int:
    idx = mujoco.mj_name2id(model, objtype, name)
    if idx < 0:
        raise WorldError(
            f"robot profile '{profile.name}' ({profile.source}): {what} '{name}' is not in the MJCF model"
        )
    return int(idx)


def subtree_bodies(model: mujoco.MjModel, root: int) -> tuple[int, ...]:
    """Every body in the kinematic subtree rooted at ``root`` (root included)."""
    return tuple(b for b in range(model.nbody) if is_descendant(model, b, root))


def is_descendant(model: mujoco.MjModel, body: int, root: int) -> bool:
    """True when ``body`` is ``root`` or below it (every body descends from the world, 0)."""
    while body > 0:
        if body == root:
            return True
        body = int(model.body_parentid[body])
    return root == 0


def _collect_ids(
    model: mujoco.MjModel,
    profile: RobotProfile,
    scenario: Scenario,
    floor_name: str,
    table_names: list[str],
) -> WorldIds:
    body, joint, geom, site, act = (
        mujoco.mjtObj.mjOBJ_BODY,
        mujoco.mjtObj.mjOBJ_JOINT,
        mujoco.mjtObj.mjOBJ_GEOM,
        mujoco.mjtObj.mjOBJ_SITE,
        mujoco.mjtObj.mjOBJ_ACTUATOR,
    )
    base = _need(model, body, profile.base_body, "base_body", profile)
    robot_bodies = subtree_bodies(model, base)
    robot_geoms = tuple(
        g
        for g in range(model.ngeom)
        if model.geom_bodyid[g] in robot_bodies and (model.geom_contype[g] or model.geom_conaffinity[g])
    )
    hand_sites: dict[str, int] = {}
    hand_bodies: dict[str, tuple[int, ...]] = {}
    arm_joints: dict[str, tuple[int, ...]] = {}
    grippers: dict[str, tuple[int, ...]] = {}
    for side, arm in profile.arms.items():
        site_name = arm.hand.site or f"executive_{side}_hand"
        hand_sites[side] = _need(model, site, site_name, f"{side} hand site", profile)
        hand_bodies[side] = subtree_bodies(
            model, _need(model, body, arm.hand_body, f"{side} hand_body", profile)
        )
        arm_joints[side] = tuple(_need(model, joint, j, f"{side} arm joint", profile) for j in arm.joints)
        grippers[side] = tuple(
            _need(model, act, a, f"{side} gripper actuator", profile) for a in arm.gripper.actuators
        )
    feet: dict[str, tuple[int, ...]] = {}
    for side, foot in profile.feet.items():
        foot_body = _need(model, body, foot.body, f"{side} foot body", profile)
        if foot.geoms:
            feet[side] = tuple(_need(model, geom, g, f"{side} foot geom", profile) for g in foot.geoms)
        else:
            feet[side] = tuple(g for g in robot_geoms if model.geom_bodyid[g] == foot_body)
    for names, what in ((profile.waist_joints, "waist joint"),):
        for name in names:
            _need(model, joint, name, what, profile)
    for side, legs in profile.leg_joints.items():
        for name in legs:
            _need(model, joint, name, f"{side} leg joint", profile)
    objects = {b.name: _need(model, body, b.name, "object", profile) for b in scenario.scene.objects}
    return WorldIds(
        base_body=base,
        torso_body=_need(model, body, profile.torso_body, "torso_body", profile),
        head_body=_need(model, body, profile.head_body, "head_body", profile) if profile.head_body else None,
        robot_bodies=robot_bodies,
        robot_geoms=robot_geoms,
        floor_geom=int(mujoco.mj_name2id(model, geom, floor_name)) if floor_name else -1,
        table_geoms=tuple(int(mujoco.mj_name2id(model, geom, n)) for n in table_names),
        object_bodies=objects,
        object_geoms={b.name: int(mujoco.mj_name2id(model, geom, b.name)) for b in scenario.scene.objects},
        object_qpos={
            b.name: int(model.jnt_qposadr[mujoco.mj_name2id(model, joint, f"{b.name}_free")])
            for b in scenario.scene.objects
        },
        obstacle_geoms={
            b.name: int(mujoco.mj_name2id(model, geom, b.name)) for b in scenario.scene.obstacles
        },
        hand_sites=hand_sites,
        hand_bodies=hand_bodies,
        foot_geoms=feet,
        arm_joints=arm_joints,
        gripper_actuators=grippers,
        keyframe=int(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, profile.keyframe)),
    )
