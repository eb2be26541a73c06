"""Grasp risk: the seed's logistic in the pre-grasp error, tolerance probabilities, grasp matrix.

:func:`assess_grasp` scores closing a hand on an object: the probability that the object's
pose error puts it outside the hand's tolerances (or in the way of the jaws' approach) and the
seed's expected logistic risk (Long et al. 2018, eq. 2). :func:`grasp_quality` measures a grasp
by its grasp matrix; :func:`shake_test` checks a grasp in physics. Each formula's source is on
the function that computes it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, NamedTuple

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError
from scipy.special import expit

from executive.planning.timing import Trajectory
from executive.risk.gaussian import (
    exceed_probability,
    gauss_hermite_normal,
    independent_union,
    normal_cdf,
    union_bounds,
)
from executive.risk.hand_span import hand_span
from executive.risk.report import RiskReport
from executive.schema.types import GraspRiskConfig, RiskConfig, Uncertainty
from executive.world.model import World

__all__ = [
    "CONTACT_MODELS",
    "ApproachEnvelope",
    "GraspError",
    "GraspQuality",
    "GraspTolerance",
    "ShakeResult",
    "approach_envelope",
    "approach_miss_probability",
    "assess_grasp",
    "expected_seed_risk",
    "grasp_error",
    "grasp_from_physics",
    "grasp_matrix",
    "grasp_quality",
    "grasp_tolerance",
    "half_extent",
    "hand_pose_at",
    "has_slide_jaws",
    "logistic_risk",
    "seed_grasp_risk",
    "shake_test",
    "skew",
    "tolerance_probabilities",
]

FloatArray = NDArray[np.float64]
ContactModel = Literal["frictionless", "hard_finger", "point_with_friction", "soft_finger"]
#: Columns of the contact-frame wrench (f_n, f_t, f_o, m_n, m_t, m_o) each contact model transmits.
CONTACT_MODELS: dict[str, tuple[int, ...]] = {
    "frictionless": (0,),
    "hard_finger": (0, 1, 2),
    "point_with_friction": (0, 1, 2),  # the Handbook's name for the hard-finger model
    "soft_finger": (0, 1, 2, 3),
}


# --- the seed's logistic --------------------------------------------------------------------


def logistic_risk(error: float, scale: float, x_max: float, steepness: float) -> float:
    """Seed eq. 2 for one error: 1 / (1 + exp(-a d / (x_max - d) + b)), guarded.

    d = |error|; b = steepness; a = b (x_max - scale) / scale (risk 1/2 at d = scale).
    d >= x_max (including inf) gives 1 (the limit of the formula as d -> x_max). Needs
    0 < scale < x_max and steepness > 0. Long et al. 2018, eq. 2; note that its form gives
    1 / (1 + e^b) > 0 at zero error.
    """
    if not (0.0 < scale < x_max) or not steepness > 0.0 or not np.isfinite(x_max):
        raise ValueError(
            f"logistic_risk: need 0 < scale < x_max < inf and steepness > 0, got scale={scale}, "
            f"x_max={x_max}, steepness={steepness}"
        )
    if np.isnan(error):
        raise ValueError("logistic_risk: the error is NaN")
    d = abs(float(error))
    if d >= x_max:
        return 1.0
    a = steepness * (x_max - scale) / scale
    z = a * d / (x_max - d) - steepness  # x_max - d > 0 here; may be huge near x_max
    return float(expit(z))


def seed_grasp_risk(position_error: float, angle_error: float, config: GraspRiskConfig) -> float:
    """The seed's weighted sum of the positional (m) and angular (rad) logistic risks, in [0, 1]."""
    total = config.position_weight + config.angle_weight
    if config.position_weight < 0.0 or config.angle_weight < 0.0 or total <= 0.0:
        raise ValueError(
            f"seed_grasp_risk: weights must be >= 0 with a positive sum, got "
            f"{config.position_weight}, {config.angle_weight}"
        )
    rp = logistic_risk(position_error, config.position_scale, config.position_max, config.steepness)
    ra = logistic_risk(angle_error, config.angle_scale_rad, config.angle_max_rad, config.steepness)
    return float(np.clip((config.position_weight * rp + config.angle_weight * ra) / total, 0.0, 1.0))


# --- pre-grasp error and tolerances ---------------------------------------------------------


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


def half_extent(model: mujoco.MjModel, geom: int, axis_local: FloatArray) -> float:
    """Half the extent of a geom along a unit axis of its own frame (box, sphere, cylinder; else rbound)."""
    size = model.geom_size[geom]
    kind = int(model.geom_type[geom])
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return float(np.abs(axis_local) @ size)
    if kind == mujoco.mjtGeom.mjGEOM_SPHERE:
        return float(size[0])
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:  # axis z, radius size[0], half length size[1]
        return float(size[0] * np.hypot(axis_local[0], axis_local[1]) + size[1] * abs(axis_local[2]))
    return float(model.geom_rbound[geom])


def _is_axisymmetric(model: mujoco.MjModel, geom: int, rotation: FloatArray) -> bool:
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
    (open - closed) when they drive slide joints measured from touching pads (the bundled
    humanoid: 2 x 0.085 m); for any other hand (the G1's Dex3) the free span between its
    open thumb and fingers across the site, measured on the model
    (:func:`executive.risk.hand_span.hand_span`).
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
    if _is_axisymmetric(model, geom, rot):
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


def expected_seed_risk(
    error: GraspError, config: GraspRiskConfig, position_sigma: float, yaw_sigma: float, order: int = 32
) -> float:
    """E[seed risk] over the object pose error (Gauss-Hermite in closing, lateral and yaw)."""
    z, w = gauss_hermite_normal(order)
    closing = error.closing + position_sigma * z
    lateral = error.lateral + position_sigma * z
    yaw = error.yaw + yaw_sigma * z
    pos_risk = np.array(
        [
            [
                logistic_risk(
                    float(np.hypot(c, lat)), config.position_scale, config.position_max, config.steepness
                )
                for lat in lateral
            ]
            for c in closing
        ]
    )
    ang_risk = np.array(
        [logistic_risk(float(a), config.angle_scale_rad, config.angle_max_rad, config.steepness) for a in yaw]
    )
    total = config.position_weight + config.angle_weight
    expected = (
        config.position_weight * float(w @ pos_risk @ w) + config.angle_weight * float(w @ ang_risk)
    ) / total
    return float(np.clip(expected, 0.0, 1.0))


@dataclass(frozen=True)
class ApproachEnvelope:
    """Where a hand's collision geoms pass beside an object on their way down to grasp it.

    Coordinates are in the object's planned (estimated) horizontal frame, m: x along its
    lateral axis (across the jaws' closing direction), y along its closing axis. Only the
    corners of geoms that are below the object's top face at a knot are kept.

    Attributes:
        side_a: (n, 2) corners (x, y) with y > 0 (beside the object's +y face).
        side_b: (m, 2) corners with y <= 0 (beside its -y face).
        half_width: the object's half extent b along its closing axis.
    """

    side_a: FloatArray
    side_b: FloatArray
    half_width: float

    def clearances(self, yaw: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Largest u = c - l tan t that keeps off each face, for object yaw errors t (rad).

        A box of half-width b turned by t about its centre (c along the jaws, l across them)
        has its face at y = c + b / cos t + tan t (x - l), so a pad corner (x, y) outside it
        is hit iff u > y - x tan t - b / cos t (plane geometry; Ericson, "Real-Time Collision
        Detection", 2005, 4.4: a convex polygon meets a half-plane iff one of its vertices does).

        Returns (hi, lo): the approach misses the object iff lo < u < hi; hi is +inf (lo -inf)
        when no geom goes below the top on that side.
        """
        t = np.atleast_1d(np.asarray(yaw, dtype=float))
        tan, sec = np.tan(t), 1.0 / np.cos(t)
        hi = np.full(t.shape, np.inf)
        lo = np.full(t.shape, -np.inf)
        if len(self.side_a):
            hi = np.min(self.side_a[:, 1][None, :] - np.outer(tan, self.side_a[:, 0]), axis=1)
        if len(self.side_b):
            lo = np.max(self.side_b[:, 1][None, :] - np.outer(tan, self.side_b[:, 0]), axis=1)
        return hi - self.half_width * sec, lo + self.half_width * sec


def _hand_collision_geoms(world: World, side: str) -> list[int]:
    model = world.model
    bodies = set(world.ids.hand_bodies[side])
    return [
        g
        for g in range(model.ngeom)
        if int(model.geom_bodyid[g]) in bodies and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]


def _geom_corners(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> FloatArray:
    """World corners (8, 3) of a geom's local bounding box (the box itself for a box geom)."""
    centre, half = model.geom_aabb[geom, :3], model.geom_aabb[geom, 3:]
    signs = np.array([[i, j, k] for i in (-1.0, 1.0) for j in (-1.0, 1.0) for k in (-1.0, 1.0)])
    rot = data.geom_xmat[geom].reshape(3, 3)
    return np.asarray(data.geom_xpos[geom] + (centre + signs * half) @ rot.T, dtype=float)


def _mesh_vertices(model: mujoco.MjModel, data: mujoco.MjData, geom: int) -> FloatArray:
    """World positions (n, 3) of a mesh geom's vertices (MuJoCo stores them in the geom's frame)."""
    mesh = int(model.geom_dataid[geom])
    start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    local = np.asarray(model.mesh_vert[start : start + count], dtype=float)
    return np.asarray(data.geom_xpos[geom] + local @ data.geom_xmat[geom].reshape(3, 3).T, dtype=float)


def _below(model: mujoco.MjModel, data: mujoco.MjData, geom: int, top: float) -> FloatArray:
    """The points of a hand geom below ``top`` that can meet the object's side on the way down.

    A mesh (a dexterous hand's finger) gives its vertices below the top; a primitive gives all
    its bounding box's corners when its lowest corner is below the top (none otherwise).
    """
    if model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_MESH:
        verts = _mesh_vertices(model, data, geom)
        return verts[verts[:, 2] < top]
    pts = _geom_corners(model, data, geom)
    return pts if float(pts[:, 2].min()) < top else np.zeros((0, 3))


def _extreme_points(points: FloatArray) -> FloatArray:
    """The vertices of the 2-D convex hull of ``points`` (all of them when there are few or they are
    degenerate): a linear function's minimum over the points is attained at one of them."""
    if len(points) <= 64:
        return points
    try:
        return np.asarray(points[ConvexHull(points).vertices], dtype=float)
    except QhullError:
        return points


def approach_envelope(
    world: World,
    side: str,
    obj: str,
    qpos_path: ArrayLike,
    *,
    closing_axis_object: ArrayLike = (0.0, 1.0, 0.0),
) -> ApproachEnvelope:
    """The corners of the ``side`` hand's geoms beside ``obj`` over a path of robot poses.

    Args:
        world: the estimate; the object's pose is taken from ``world.data``.
        side: the grasping arm.
        obj: the object to be grasped (a box; other shapes use their extent along the axes).
        qpos_path: (k, nq) full-model poses the hand passes through on its way to the grasp
            (e.g. the knots of the pre-grasp and approach trajectories).
        closing_axis_object: the object-frame axis the jaws close along.

    Returns:
        The envelope; its corners are those of geoms whose lowest corner is below the
        object's top face at that pose.
    """
    model = world.model
    geom = world.ids.object_geoms[obj]
    rot = world.data.geom_xmat[geom].reshape(3, 3)
    c_axis = np.asarray(closing_axis_object, dtype=float).reshape(3)
    c_axis = c_axis / np.linalg.norm(c_axis)
    y_world = rot @ c_axis
    y_world[2] = 0.0
    y_world /= np.linalg.norm(y_world)
    x_world = np.array([y_world[1], -y_world[0], 0.0])
    centre = world.data.geom_xpos[geom].copy()
    top = float(centre[2] + half_extent(model, geom, rot.T @ np.array([0.0, 0.0, 1.0])))
    data = mujoco.MjData(model)
    geoms = _hand_collision_geoms(world, side)
    corners: list[FloatArray] = []
    for q in np.asarray(qpos_path, dtype=float).reshape(-1, model.nq):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        for g in geoms:
            pts = _below(model, data, g, top)
            if len(pts):
                rel = pts - centre
                corners.append(np.column_stack([rel @ x_world, rel @ y_world]))
    flat = np.concatenate(corners) if corners else np.zeros((0, 2))
    width = half_extent(model, geom, c_axis)
    # Beyond the object's circumradius along its lateral axis a point passes its end at any yaw
    # (e.g. a hand starting at the robot's hip, below the table top, far to one side).
    reach = float(np.hypot(width, half_extent(model, geom, np.cross(c_axis, [0.0, 0.0, 1.0]))))
    flat = flat[np.abs(flat[:, 0]) <= reach]
    side_a, side_b = flat[flat[:, 1] > 0.0], flat[flat[:, 1] <= 0.0]
    return ApproachEnvelope(_extreme_points(side_a), _extreme_points(side_b), float(width))


def approach_miss_probability(
    envelope: ApproachEnvelope, position_sigma: float, yaw_sigma: float, order: int = 32
) -> tuple[float, float, float]:
    """P(a hand geom meets the object's side on the way down) for a Gaussian object pose error.

    The object's horizontal position error is N(0, position_sigma^2) per axis and its yaw
    error N(0, yaw_sigma^2), independent. Given the yaw t, u = c - l tan t is
    N(0, position_sigma^2 / cos^2 t) and the approach misses the object iff lo(t) < u < hi(t)
    (:meth:`ApproachEnvelope.clearances`); the yaw is integrated by Gauss-Hermite quadrature
    of ``order`` nodes. Valid while the pads pass beside the object's long faces (the yaw
    does not bring a face's end under them).

    Returns:
        (probability, p_a, p_b): the total and the parts from the +y and -y faces.
    """
    if position_sigma < 0.0 or yaw_sigma < 0.0:
        raise ValueError(f"approach_miss_probability: sigmas must be >= 0, got {position_sigma}, {yaw_sigma}")
    z, w = gauss_hermite_normal(order) if yaw_sigma > 0.0 else (np.zeros(1), np.ones(1))
    t = np.clip(yaw_sigma * z, -1.5, 1.5)
    hi, lo = envelope.clearances(t)
    if position_sigma > 0.0:
        s = position_sigma / np.cos(t)
        p_a, p_b = normal_cdf(-hi / s), normal_cdf(lo / s)
    else:
        p_a, p_b = (hi <= 0.0).astype(float), (lo >= 0.0).astype(float)
    p = np.where(lo >= hi, 1.0, np.minimum(1.0, p_a + p_b))
    return float(w @ p), float(w @ p_a), float(w @ p_b)


def hand_pose_at(
    world: World, trajectory: Trajectory, side: str, knot: int = -1
) -> tuple[FloatArray, FloatArray]:
    """The ``side`` hand site's world position and rotation at a knot of a trajectory (default the last)."""
    data = mujoco.MjData(world.model)
    data.qpos[:] = trajectory.qpos[knot]
    mujoco.mj_kinematics(world.model, data)
    site = world.ids.hand_sites[side]
    return data.site_xpos[site].copy(), data.site_xmat[site].reshape(3, 3).copy()


def assess_grasp(
    world: World,
    side: str,
    obj: str,
    hand_pose: tuple[ArrayLike, ArrayLike],
    risk_config: RiskConfig,
    uncertainty: Uncertainty,
    *,
    object_pose: tuple[ArrayLike, ArrayLike] | None = None,
    tolerance: GraspTolerance | None = None,
    closing_axis_object: ArrayLike = (0.0, 1.0, 0.0),
    approach: ApproachEnvelope | None = None,
) -> RiskReport:
    """Grasp risk of closing the ``side`` hand at ``hand_pose`` (site position, 3x3 rotation) on ``obj``.

    object_pose: (position, quaternion w x y z) of the object; None takes its pose in
    ``world.data``. Pass the truth pose with a zero ``Uncertainty()`` to score a known error
    (probability 0 or 1); with the estimate's pose and the scenario's uncertainty, the
    object's position (per horizontal axis) and yaw are Gaussian about it.
    probability: 1 - prod(1 - p_axis) over the closing, lateral and yaw tolerances
    (independent axes), bounds max p <= P <= min(1, sum p); seed_score: the expected seed
    risk (eq. 2 weighted sum); severity: ``risk_config.severity.drop``.

    approach: the hand's path down to the grasp (:func:`approach_envelope`). Given, the
    closing and yaw tolerances are replaced by the joint event that a hand geom meets the
    object's side anywhere on that path (:func:`approach_miss_probability`, offset and yaw
    together); its union with the lateral failure is taken as independent.
    """
    err = _object_error(world, obj, hand_pose, object_pose, closing_axis_object)
    tol = tolerance or grasp_tolerance(world, side, obj, closing_axis_object=closing_axis_object)
    p_axes = tolerance_probabilities(err, tol, uncertainty.object_position, uncertainty.object_yaw_rad)
    extra: dict[str, float] = {}
    if approach is not None:
        p_axes, extra = _with_approach(approach, p_axes, uncertainty)
    lower, upper = union_bounds(p_axes)
    cfg = risk_config.grasp
    return RiskReport(
        mode="grasp",
        probability=float(np.clip(independent_union(p_axes), lower, upper)),
        probability_bounds=(lower, upper),
        severity=float(risk_config.severity.drop),
        seed_score=expected_seed_risk(err, cfg, uncertainty.object_position, uncertainty.object_yaw_rad),
        details=_grasp_details(side, obj, err, tol, p_axes, approach is not None, cfg) | extra,
    )


def _object_error(
    world: World,
    obj: str,
    hand_pose: tuple[ArrayLike, ArrayLike],
    object_pose: tuple[ArrayLike, ArrayLike] | None,
    closing_axis_object: ArrayLike,
) -> GraspError:
    """:func:`grasp_error` of the hand at ``hand_pose`` on ``obj`` at ``object_pose`` (position,
    quaternion w x y z; None: its pose in ``world.data``)."""
    if object_pose is None:
        position, quat = world.object_pose(obj)
    else:
        position = np.asarray(object_pose[0], dtype=float).reshape(3)
        quat = np.asarray(object_pose[1], dtype=float).reshape(4)
    rotation = np.zeros(9)
    mujoco.mju_quat2Mat(rotation, quat / np.linalg.norm(quat))
    rotation_m = rotation.reshape(3, 3)
    geom = world.ids.object_geoms[obj]
    return grasp_error(
        hand_pose[0],
        hand_pose[1],
        position,
        rotation_m,
        closing_axis_object=closing_axis_object,
        axisymmetric=_is_axisymmetric(world.model, geom, rotation_m),
    )


def _with_approach(
    approach: ApproachEnvelope, p_axes: FloatArray, uncertainty: Uncertainty
) -> tuple[FloatArray, dict[str, float]]:
    """The failure probabilities with the approach's miss probability in place of the closing
    and yaw ones ([approach, lateral]), and the approach's details for the report."""
    p_jaws, p_a, p_b = approach_miss_probability(
        approach, uncertainty.object_position, uncertainty.object_yaw_rad
    )
    hi, lo = approach.clearances(0.0)
    extra = {"p_approach": p_jaws, "p_approach_a": p_a, "p_approach_b": p_b}
    extra |= {"approach_window_lo": float(lo[0]), "approach_window_hi": float(hi[0])}
    return np.array([p_jaws, p_axes[1]]), extra


def _grasp_details(
    side: str,
    obj: str,
    err: GraspError,
    tol: GraspTolerance,
    p_axes: FloatArray,
    approached: bool,
    cfg: GraspRiskConfig,
) -> dict[str, float | str]:
    """The grasp report's details: the errors, the tolerances and the per-axis probabilities
    (``p_axes[0]`` is the approach's when ``approached``, and there is no yaw term)."""
    return {
        "side": side,
        "object": obj,
        "closing_error": err.closing,
        "lateral_error": err.lateral,
        "yaw_error": err.yaw,
        "translational_error": err.translational,
        "seed_risk_nominal": seed_grasp_risk(err.translational, err.yaw, cfg),
        "closing_tolerance": tol.closing,
        "lateral_tolerance": tol.lateral,
        "yaw_tolerance": tol.yaw,
        "p_closing": float(p_axes[0]),
        "p_lateral": float(p_axes[1]),
        "p_yaw": float(p_axes[2]) if not approached else 0.0,
    }


# --- grasp matrix ---------------------------------------------------------------------------


def skew(v: ArrayLike) -> FloatArray:
    """S(v) with S(v) x = v x x."""
    x, y, z = np.asarray(v, dtype=float).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def grasp_matrix(
    contact_points: ArrayLike,
    contact_frames: ArrayLike,
    object_centre: ArrayLike,
    model: ContactModel = "hard_finger",
) -> FloatArray:
    """Grasp matrix G (6 x m): object wrench about the centre = G @ stacked contact wrenches.

    contact_frames[i] is R_i, columns (normal into the object, tangent, tangent) in the world;
    G_i = [[R_i, 0], [S(p_i - c) R_i, R_i]] with the contact model's columns kept: frictionless
    point [f_n], hard finger = point contact with friction [f_n, f_t, f_o], soft finger
    [f_n, f_t, f_o, m_n]. Prattichizzo & Trinkle, Springer Handbook of Robotics, 2nd ed., ch. 38
    "Grasping" (ch. 28 in the 1st ed.); Murray, Li & Sastry 1994, ch. 5.
    """
    if model not in CONTACT_MODELS:
        raise ValueError(
            f"grasp_matrix: contact model must be one of {sorted(CONTACT_MODELS)}, got {model!r}"
        )
    points = np.asarray(contact_points, dtype=float).reshape(-1, 3)
    frames = np.asarray(contact_frames, dtype=float).reshape(-1, 3, 3)
    if len(points) != len(frames):
        raise ValueError(f"grasp_matrix: {len(points)} points but {len(frames)} frames")
    centre = np.asarray(object_centre, dtype=float).reshape(3)
    cols = list(CONTACT_MODELS[model])
    blocks = []
    for p, rot in zip(points, frames, strict=True):
        full = np.zeros((6, 6))
        full[:3, :3] = rot
        full[3:, :3] = skew(p - centre) @ rot
        full[3:, 3:] = rot
        blocks.append(full[:, cols])
    return np.hstack(blocks) if blocks else np.zeros((6, 0))


@dataclass(frozen=True)
class GraspQuality:
    """A grasp's contacts, its grasp matrix and the singular-value measures of it."""

    points: FloatArray  # (n, 3)
    frames: FloatArray  # (n, 3, 3), columns normal (into the object), tangents
    matrix: FloatArray  # (6, m)
    singular_values: FloatArray  # (6,), descending, zero-padded when m < 6
    sigma_min: float
    isotropy: float  # sigma_min / sigma_max (0 for no contacts)

    @property
    def contacts(self) -> int:
        return len(self.points)


def grasp_quality(
    contact_points: ArrayLike,
    contact_frames: ArrayLike,
    object_centre: ArrayLike,
    model: ContactModel = "hard_finger",
) -> GraspQuality:
    """Grasp matrix and its measures: sigma_min(G) (Li & Sastry 1988) and the isotropy
    sigma_min / sigma_max (Kim et al. 2004; the inverse of the condition number the seed's Q
    relates to)."""
    points = np.asarray(contact_points, dtype=float).reshape(-1, 3)
    frames = np.asarray(contact_frames, dtype=float).reshape(-1, 3, 3)
    g = grasp_matrix(points, frames, object_centre, model)
    sv = np.zeros(6)
    if g.shape[1]:
        s = np.linalg.svd(g, compute_uv=False)
        sv[: len(s)] = s
    sigma_max = float(sv[0])
    return GraspQuality(
        points=points,
        frames=frames,
        matrix=g,
        singular_values=sv,
        sigma_min=float(sv[-1]),
        isotropy=float(sv[-1] / sigma_max) if sigma_max > 0.0 else 0.0,
    )


def grasp_from_physics(
    world: World, data: mujoco.MjData, side: str, obj: str, model: ContactModel = "hard_finger"
) -> GraspQuality:
    """Grasp quality of the current contacts between the ``side`` hand's geoms and ``obj``'s geom.

    MuJoCo's contact frame rows are (normal, tangent, tangent) with the normal pointing from
    geom1 to geom2; it is flipped (with one tangent, keeping a right-handed frame) so the
    normal points into the object. The centre is the object's centre of mass (data.xipos).
    """
    hand = set(world.ids.hand_bodies[side])
    obj_geom = world.ids.object_geoms[obj]
    gbody = world.model.geom_bodyid
    points, frames = [], []
    for i in range(data.ncon):
        g1, g2 = int(data.contact.geom[i][0]), int(data.contact.geom[i][1])
        if g2 == obj_geom and int(gbody[g1]) in hand:
            sign = 1.0
        elif g1 == obj_geom and int(gbody[g2]) in hand:
            sign = -1.0
        else:
            continue
        rows = data.contact.frame[i].reshape(3, 3)
        rot = np.column_stack([sign * rows[0], sign * rows[1], rows[2]])
        points.append(data.contact.pos[i].copy())
        frames.append(rot)
    centre = data.xipos[world.ids.object_bodies[obj]]
    return grasp_quality(np.array(points).reshape(-1, 3), np.array(frames).reshape(-1, 3, 3), centre, model)


# --- shake validation -----------------------------------------------------------------------


class ShakeResult(NamedTuple):
    """Outcome of :func:`shake_test`: whether the object stayed in the hand, and its largest drift (m)."""

    held: bool
    drift_m: float


def _actuator_of(model: mujoco.MjModel, joint: int) -> int:
    for a in range(model.nu):
        if (
            model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT
            and int(model.actuator_trnid[a, 0]) == joint
        ):
            return a
    name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
    raise ValueError(f"shake_test: joint '{name}' has no actuator")


def shake_test(
    world: World,
    side: str,
    obj: str,
    *,
    amplitude_rad: float,
    frequency_hz: float,
    duration_s: float,
    tolerance: float = 0.02,
    joints: tuple[str, ...] | None = None,
) -> ShakeResult:
    """Shake a grasped object by oscillating the wrist servos' targets (the seed's sinusoidal
    excitation); steps ``world.data``.

    The caller has the object grasped in ``world.data``. Each joint's position actuator
    target becomes q0 + amplitude sin(2 pi f t) (clipped to its ctrlrange) for
    ``duration_s``; drift_m is the largest displacement of the object's centre in the hand
    site's frame from where it was at the start; held = drift_m <= tolerance. joints None:
    the arm's last two joints (the wrist). Targets are restored at the end.
    """
    if amplitude_rad < 0.0 or frequency_hz <= 0.0 or duration_s <= 0.0 or tolerance <= 0.0:
        raise ValueError(
            "shake_test: need amplitude >= 0, frequency > 0, duration > 0 and tolerance > 0, got "
            f"{amplitude_rad}, {frequency_hz}, {duration_s}, {tolerance}"
        )
    model, data = world.model, world.data
    names = joints if joints is not None else world.profile.arms[side].joints[-2:]
    acts = []
    for name in names:
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise ValueError(f"shake_test: no joint '{name}' in the model")
        acts.append(_actuator_of(model, int(j)))
    act_idx = np.array(acts, dtype=int)
    ctrl0 = data.ctrl[act_idx].copy()
    lo, hi = model.actuator_ctrlrange[act_idx, 0], model.actuator_ctrlrange[act_idx, 1]
    limited = model.actuator_ctrllimited[act_idx].astype(bool)
    site = world.ids.hand_sites[side]
    body = world.ids.object_bodies[obj]
    mujoco.mj_forward(model, data)

    def in_hand() -> FloatArray:
        rot = data.site_xmat[site].reshape(3, 3)
        return np.asarray(rot.T @ (data.xpos[body] - data.site_xpos[site]), dtype=float)

    reference = in_hand()
    t0 = float(data.time)
    steps = round(duration_s / model.opt.timestep)
    drift = 0.0
    try:
        for _ in range(steps):
            target = ctrl0 + amplitude_rad * np.sin(2.0 * np.pi * frequency_hz * (data.time - t0))
            data.ctrl[act_idx] = np.where(limited, np.clip(target, lo, hi), target)
            mujoco.mj_step(model, data)
            drift = max(drift, float(np.linalg.norm(in_hand() - reference)))
            if not np.isfinite(drift):
                break
    finally:
        data.ctrl[act_idx] = ctrl0
    return ShakeResult(held=bool(np.isfinite(drift) and drift <= tolerance), drift_m=float(drift))
