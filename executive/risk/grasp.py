"""Grasp risk: will closing a hand on an object, at its planned pose, grasp it?

:func:`assess_grasp` scores closing a hand on an object: the probability that the object's
pose error puts it outside the hand's tolerances (:mod:`executive.risk.grasp_tolerance`) or in
the way of the jaws' approach (:mod:`executive.risk.grasp_approach`), and the seed's expected
logistic risk (:mod:`executive.risk.grasp_seed`, Long et al. 2018, eq. 2). The grasp matrix
and the shake test (:mod:`executive.risk.grasp_quality`) measure a grasp once made; this
module keeps all their names importable.

Usage::

    report = assess_grasp(world, "left", "book", hand_pose_at(world, traj, "left"), risk_config, unc)
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from executive.planning.timing import Trajectory
from executive.risk.gaussian import independent_union, union_bounds
from executive.risk.grasp_approach import ApproachEnvelope, approach_envelope, approach_miss_probability
from executive.risk.grasp_quality import (
    CONTACT_MODELS,
    GraspQuality,
    ShakeResult,
    grasp_from_physics,
    grasp_matrix,
    grasp_quality,
    shake_test,
    skew,
)
from executive.risk.grasp_seed import expected_seed_risk, logistic_risk, seed_grasp_risk
from executive.risk.grasp_tolerance import (
    GraspError,
    GraspTolerance,
    closing_axis,
    grasp_error,
    grasp_tolerance,
    has_slide_jaws,
    is_axisymmetric,
    tolerance_probabilities,
)
from executive.risk.model_geometry import half_extent, site_pose_at
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
    "closing_axis",
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


def hand_pose_at(
    world: World, trajectory: Trajectory, side: str, knot: int = -1
) -> tuple[FloatArray, FloatArray]:
    """The ``side`` hand site's world position and rotation at a knot of a trajectory (default the last)."""
    return site_pose_at(world, trajectory.qpos[knot], side)


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
    hand: tuple[float, float] = (0.0, 0.0),
    hand_sigma: float = 0.0,
    lateral_probability: float | None = None,
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
    together); its union with the lateral failure is taken as independent. ``hand`` and
    ``hand_sigma``: the hand's execution error along the envelope's closing and lateral axes
    (mean, m) and its spread per axis (:func:`approach_miss_probability`).

    lateral_probability: the lateral failure's probability when the caller has it (a grasp
    whose placement adds the execution's spread, :mod:`executive.risk.placement_spread`);
    None: from ``tolerance.lateral``.
    """
    err = _object_error(world, obj, hand_pose, object_pose, closing_axis_object)
    tol = tolerance or grasp_tolerance(world, side, obj, closing_axis_object=closing_axis_object)
    p_axes = tolerance_probabilities(err, tol, uncertainty.object_position, uncertainty.object_yaw_rad)
    if lateral_probability is not None:
        p_axes[1] = lateral_probability
    extra: dict[str, float] = {}
    if approach is not None:
        p_axes, extra = _with_approach(approach, p_axes, uncertainty, hand, hand_sigma)
    lower, upper = union_bounds(p_axes)
    cfg = risk_config.grasp
    return RiskReport(
        mode="drop",  # the grasp model is one half of the drop mode (the hold model the other)
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
        axisymmetric=is_axisymmetric(world.model, geom, rotation_m),
    )


def _with_approach(
    approach: ApproachEnvelope,
    p_axes: FloatArray,
    uncertainty: Uncertainty,
    hand: tuple[float, float] = (0.0, 0.0),
    hand_sigma: float = 0.0,
) -> tuple[FloatArray, dict[str, float]]:
    """The failure probabilities with the approach's miss probability in place of the closing
    and yaw ones ([approach, lateral]), and the approach's details for the report."""
    p_jaws, p_a, p_b = approach_miss_probability(
        approach, uncertainty.object_position, uncertainty.object_yaw_rad, hand=hand, hand_sigma=hand_sigma
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
