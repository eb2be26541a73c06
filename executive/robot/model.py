"""What the scenario checks read from a robot's MJCF model: its reach and its parts.

Used while a scenario is loaded (:mod:`executive.scenario`, :mod:`executive.scenario.checks`), before
any world is built. The facts come from the robot alone at the profile's standing keyframe:

* :func:`robot_facts`: the base (pelvis) position, per arm the shoulder position and the arm's
  length, and the reach: the longest path along the kinematic chain from the base through
  every joint axis point (waist, shoulder, elbow, wrist) to the hand frame. No hand can be
  farther than that from the base while the feet stay put (triangle inequality);
* the body-part labels ``severity.body_parts`` may name (:attr:`RobotFacts.body_parts`).

Results are cached per (MJCF file, profile file and their modification times).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from executive.robot.profile_types import RobotProfile

__all__ = ["BODY_PART_LABELS", "RobotFacts", "robot_facts"]


@dataclass(frozen=True)
class RobotFacts:
    """A robot's reach and part names, measured in its MJCF at the standing keyframe.

    base: the base body's position (m). shoulders: side -> (x, y, z) of the arm's first joint.
    arm_lengths: side -> shoulder-to-hand-frame length along the arm's joints (m).
    reach: side -> base-to-hand-frame length along the whole chain (m).
    bodies: the names of the robot's bodies.
    """

    base: tuple[float, float, float]
    shoulders: dict[str, tuple[float, float, float]]
    arm_lengths: dict[str, float]
    reach: dict[str, float]
    bodies: tuple[str, ...]

    @property
    def max_reach(self) -> float:
        return max(self.reach.values())

    def describe(self) -> str:
        """``shoulders at 1.35 m, arms 0.62 m long, 0.95 m from the base at (0, 0, 1.0)``."""
        z = max(p[2] for p in self.shoulders.values())
        arm = max(self.arm_lengths.values())
        bx, by, bz = self.base
        return (
            f"the robot reaches at most {self.max_reach:.2f} m from its base "
            f"at ({bx:.2f}, {by:.2f}, {bz:.2f}) "
            f"(shoulders {z:.2f} m high, arms {arm:.2f} m long, measured in its MJCF at the keyframe)"
        )


#: The labels ``severity.body_parts`` knows besides the robot's body names (the collision model's
#: parts: the head body's subtree, the hands' subtrees, the forearm bodies). A label the robot has no
#: part for (``head`` on a robot whose profile names no head) matches nothing.
BODY_PART_LABELS: tuple[str, ...] = ("head", "hand", "forearm")


def robot_facts(mjcf: Path, profile: RobotProfile) -> RobotFacts | None:
    """The robot's facts, or None when its model does not load (the world builder says why)."""
    try:
        stamp = (mjcf.stat().st_mtime_ns, profile.source.stat().st_mtime_ns if profile.source else 0)
    except OSError:
        return None
    return _facts(str(mjcf), str(profile.source), stamp, profile)


_CACHE: dict[tuple[str, str, tuple[int, int], str], RobotFacts | None] = {}


def _facts(mjcf: str, source: str, stamp: tuple[int, int], profile: RobotProfile) -> RobotFacts | None:
    key = (mjcf, source, stamp, repr(profile))
    if key not in _CACHE:
        _CACHE[key] = _measure(mjcf, profile)
    return _CACHE[key]


def _measure(mjcf: str, profile: RobotProfile) -> RobotFacts | None:
    """Load the robot alone, pose it at the keyframe and measure its chains."""
    try:
        model = mujoco.MjModel.from_xml_path(mjcf)
    except Exception:
        return None
    data = mujoco.MjData(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, profile.keyframe)
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, profile.base_body)
    if key < 0 or base < 0:
        return None
    mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_forward(model, data)
    shoulders, arms, reach = {}, {}, {}
    for side, arm in profile.arms.items():
        hand = _hand_point(model, data, profile, side)
        first = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, arm.joints[0])
        if hand is None or first < 0:
            return None
        chain = _chain_points(model, data, base, hand[1])
        shoulder = data.xanchor[first]
        shoulders[side] = (float(shoulder[0]), float(shoulder[1]), float(shoulder[2]))
        after = [p for j, p in chain if j >= 0 and _is_at_or_below(model, model.jnt_bodyid[j], first)]
        arms[side] = _path_length([shoulder, *after, hand[0]])
        reach[side] = _path_length([data.xpos[base], *(p for _, p in chain), hand[0]])
    names = tuple(model.body(b).name for b in range(1, model.nbody) if model.body(b).name)
    bx, by, bz = (float(v) for v in data.xpos[base])
    return RobotFacts((bx, by, bz), shoulders, arms, reach, names)


def _is_at_or_below(model: mujoco.MjModel, body: int, joint: int) -> bool:
    top = int(model.jnt_bodyid[joint])
    while body > 0:
        if body == top:
            return True
        body = int(model.body_parentid[body])
    return False


def _hand_point(
    model: mujoco.MjModel, data: mujoco.MjData, profile: RobotProfile, side: str
) -> tuple[np.ndarray, int] | None:
    """The hand frame's world position and the body it is attached to."""
    arm = profile.arms[side]
    if arm.hand.site is not None:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, arm.hand.site)
        if site < 0:
            return None
        return data.site_xpos[site].copy(), int(model.site_bodyid[site])
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, arm.hand.body or arm.hand_body)
    if body < 0:
        return None
    offset = data.xmat[body].reshape(3, 3) @ np.asarray(arm.hand.offset, dtype=float)
    return data.xpos[body] + offset, body


def _chain_points(
    model: mujoco.MjModel, data: mujoco.MjData, base: int, body: int
) -> list[tuple[int, np.ndarray]]:
    """The joint axis points from the base down to ``body``, base first (hinge and slide joints)."""
    points: list[tuple[int, np.ndarray]] = []
    while body > 0 and body != base:
        start, count = int(model.body_jntadr[body]), int(model.body_jntnum[body])
        for j in reversed(range(start, start + count)):
            if model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
                points.append((j, data.xanchor[j].copy()))
        body = int(model.body_parentid[body])
    points.reverse()
    return points


def _path_length(points: list[np.ndarray]) -> float:
    return float(sum(math.dist(a, b) for a, b in itertools.pairwise(points)))
