"""Tests of the whole-body planner (executive/planning/planner.py) on the book_transfer scene.

Every number is re-computed from the returned qpos with MuJoCo itself
(mj_kinematics, mj_comPos, mj_geomDistance) on a fresh MjData, not taken from
the planner's own records. The support polygon is rebuilt here from the sole
boxes' corners (both soles are axis-aligned boxes side by side, so their hull
is the rectangle spanned by the corners).
"""

from __future__ import annotations

from collections.abc import Sequence

import mink
import mujoco
import numpy as np
import pytest

from executive.planning.planner import (
    HandTarget,
    Planner,
    PlannerConfig,
    PlanningError,
    Trajectory,
    hand_top_down_quat,
)
from executive.scenario import load
from executive.world.model import World, build

TABLE_Z = 0.80
BOOK_XY = np.array([0.48, 0.26])
TARGET_XY = np.array([0.48, -0.26])
# The hand site 3.5 cm above the table: the fingertips (2 cm below the site) 1.5 cm above it,
# inside the book's 5 cm; above the robot's clearance to the table (PlannerConfig.table_distance).
GRASP_Z = TABLE_Z + 0.035
TOP_DOWN = hand_top_down_quat((0.0, 1.0, 0.0))
SHRINK = 0.02
GEOM = mujoco.mjtObj.mjOBJ_GEOM
BODY = mujoco.mjtObj.mjOBJ_BODY


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("book_transfer"))


@pytest.fixture(scope="module")
def planner(world: World) -> Planner:
    return Planner(world)


@pytest.fixture(scope="module")
def left_pick(planner: Planner, world: World) -> dict[str, Trajectory]:
    """Same-side pick with the left hand: pre-grasp, grasp, lift (carrying)."""
    q0 = world.home_qpos()
    pre = planner.move(q0, [_target("left", [*BOOK_XY, GRASP_Z + 0.10])], name="left.pregrasp")
    grasp = planner.move(
        pre.qpos[-1], [_target("left", [*BOOK_XY, GRASP_Z])], name="left.grasp", allow_contact=("book",)
    )
    lift = planner.move(
        grasp.qpos[-1],
        [_target("left", [*BOOK_XY, GRASP_Z + 0.12])],
        name="left.lift",
        carried=("left", "book"),
        allow_contact=("book",),
    )
    return {"pregrasp": pre, "grasp": grasp, "lift": lift}


# ----------------------------------------------------------------------------- helpers


def _target(side: str, position: Sequence[float] | np.ndarray, quat: np.ndarray = TOP_DOWN) -> HandTarget:
    return HandTarget(side, np.array(position, dtype=float), quat)


def _gid(world: World, name: str) -> int:
    return int(mujoco.mj_name2id(world.model, GEOM, name))


def _kin(world: World, q: np.ndarray) -> mujoco.MjData:
    data = mujoco.MjData(world.model)
    data.qpos[:] = q
    mujoco.mj_kinematics(world.model, data)
    mujoco.mj_comPos(world.model, data)
    return data


def _support_rectangle(world: World, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    corners = []
    for side in ("left", "right"):
        g = _gid(world, f"{side}_sole")
        rot = data.geom_xmat[g].reshape(3, 3)
        for sx in (-1, 1):
            for sy in (-1, 1):
                corners.append(
                    data.geom_xpos[g] + rot @ (np.array([sx, sy, -1.0]) * world.model.geom_size[g])
                )
    pts = np.array(corners)[:, :2]
    return pts.min(axis=0), pts.max(axis=0)


def _com_margin(world: World, data: mujoco.MjData, lo: np.ndarray, hi: np.ndarray) -> float:
    """Distance of the robot's CoM xy to the nearest edge of the (unshrunk) support rectangle."""
    com = data.subtree_com[mujoco.mj_name2id(world.model, BODY, "pelvis")][:2]
    return float(min(np.min(com - lo), np.min(hi - com)))


def _arm_geoms(world: World, side: str) -> list[int]:
    names = [
        "upper_arm_geom",
        "forearm_geom",
        "palm_geom",
        "finger_a_geom",
        "finger_b_geom",
        "pad_a",
        "pad_b",
    ]
    return [_gid(world, f"{side}_{n}") for n in names]


def _distance(world: World, data: mujoco.MjData, g1: int, g2: int) -> float:
    return float(mujoco.mj_geomDistance(world.model, data, g1, g2, 1.0, None))


def _site_error(world: World, q: np.ndarray, target: HandTarget) -> tuple[float, float]:
    data = _kin(world, q)
    site = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_SITE, f"{target.side}_hand")
    pos = float(np.linalg.norm(data.site_xpos[site] - target.position))
    want = np.empty(9)
    mujoco.mju_quat2Mat(want, target.quat)
    rel = want.reshape(3, 3).T @ data.site_xmat[site].reshape(3, 3)
    ang = float(np.degrees(np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))))
    return pos, ang


def _check_trajectory(
    world: World,
    planner: Planner,
    traj: Trajectory,
    allow: Sequence[str] = (),
) -> list[float]:
    """Feet, balance, limits, speed and clearance at every knot; returns the CoM margins."""
    model, cfg = world.model, planner.config
    assert traj.times[0] == 0.0 and np.all(np.diff(traj.times) > 0)
    assert traj.qpos.shape == (len(traj.times), model.nq) and len(traj.times) <= 300
    assert np.max(np.diff(traj.times)) <= 0.02 + 1e-9 or len(traj.times) == 300
    start = _kin(world, traj.qpos[0])
    feet = [mujoco.mj_name2id(model, BODY, f"{s}_foot") for s in ("left", "right")]
    lo, hi = _support_rectangle(world, start)
    # The robot keeps table_distance from the table (a top-down grasp comes close to it) and
    # min_distance from the obstacles.
    env = {_gid(world, "table_top"): cfg.table_distance, _gid(world, "book_stack"): cfg.min_distance}
    allowed = {_gid(world, n) for n in allow}
    arms = [g for s in ("left", "right") for g in _arm_geoms(world, s)]
    margins = []
    for q in traj.qpos:
        data = _kin(world, q)
        for f in feet:
            assert np.linalg.norm(data.xpos[f] - start.xpos[f]) < 1e-3
            assert np.abs(data.xmat[f] - start.xmat[f]).max() < 2e-3
        com = data.subtree_com[mujoco.mj_name2id(model, BODY, "pelvis")][:2]
        assert np.all(com >= lo + SHRINK - 1e-9) and np.all(com <= hi - SHRINK + 1e-9), com
        margins.append(_com_margin(world, data, lo, hi))
        for j in range(model.njnt):
            if model.jnt_limited[j] and model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
                qj = q[model.jnt_qposadr[j]]
                assert model.jnt_range[j, 0] - 1e-6 <= qj <= model.jnt_range[j, 1] + 1e-6
        for a in arms:
            for e, clearance in env.items():
                if a in allowed or e in allowed:
                    continue
                assert _distance(world, data, a, e) > clearance - 0.002
    # Joint speeds by finite differences of the knots.
    dt = np.diff(traj.times)
    for name, limit in planner.velocity_limits.items():
        adr = model.jnt_qposadr[model.joint(name).id]
        speed = np.abs(np.diff(traj.qpos[:, adr])) / dt
        assert np.max(speed) <= limit * (1 + 1e-6), (name, float(np.max(speed)), limit)
    # Hand paths and CoM path agree with the qpos (recomputed).
    end = _kin(world, traj.qpos[-1])
    for side in ("left", "right"):
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{side}_hand")
        assert np.allclose(traj.hand_paths[side][-1], end.site_xpos[site], atol=1e-9)
    return margins


# ----------------------------------------------------------------------------- 1. same-side pick


def test_left_grasp_via_pregrasp(world: World, planner: Planner, left_pick: dict[str, Trajectory]) -> None:
    for key, target_z, allow in (("pregrasp", GRASP_Z + 0.10, ()), ("grasp", GRASP_Z, ("book",))):
        traj = left_pick[key]
        pos, ang = _site_error(world, traj.qpos[-1], _target("left", [*BOOK_XY, target_z]))
        margins = _check_trajectory(world, planner, traj, allow)
        print(
            f"{traj.name}: {len(traj.times)} knots over {traj.duration:.2f} s; final error "
            f"{pos * 1000:.2f} mm {ang:.2f} deg; min CoM margin {min(margins) * 1000:.1f} mm"
        )
        assert pos < 0.003 and ang < 2.0
    # The idle right arm holds its joint angles (so it moves only with the torso).
    pre = left_pick["pregrasp"]
    arm = [world.model.jnt_qposadr[j] for j in world.ids.arm_joints["right"]]
    drift = np.abs(pre.qpos[:, arm] - pre.qpos[0, arm]).max()
    moved = np.linalg.norm(pre.hand_paths["right"][-1] - pre.hand_paths["right"][0])
    print(f"idle right arm: joints within {np.degrees(drift):.1f} deg, hand moved {moved * 1000:.0f} mm")
    assert drift < np.radians(5.0) and moved < 0.08
    # Smooth start and stop: the first and last knot steps are tiny compared with the largest.
    steps = np.linalg.norm(np.diff(left_pick["grasp"].hand_paths["left"], axis=0), axis=1)
    assert steps[0] < 0.05 * steps.max() and steps[-1] < 0.05 * steps.max()


# ----------------------------------------------------------------------------- 2. cross-body moves


def test_cross_body_moves(world: World, planner: Planner, left_pick: dict[str, Trajectory]) -> None:
    model = world.model
    lift = left_pick["lift"]
    carry = planner.move(
        lift.qpos[-1],
        [_target("left", [*TARGET_XY, 0.90])],
        name="left.carry",
        carried=("left", "book"),
    )
    assert carry.carried == ("left", "book")
    pos, ang = _site_error(world, carry.qpos[-1], _target("left", [*TARGET_XY, 0.90]))
    assert pos < 0.003 and ang < 2.0
    carry_margins = _check_trajectory(world, planner, carry)

    # The book moves rigidly with the hand and keeps clear of the stack.
    book = mujoco.mj_name2id(model, BODY, "book")
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "left_hand")
    book_geom, stack = _gid(world, "book"), _gid(world, "book_stack")
    rel0 = None
    min_stack = np.inf
    for q in carry.qpos:
        data = _kin(world, q)
        rot = data.site_xmat[site].reshape(3, 3)
        rel = np.concatenate(
            [
                rot.T @ (data.xpos[book] - data.site_xpos[site]),
                (rot.T @ data.xmat[book].reshape(3, 3)).ravel(),
            ]
        )
        rel0 = rel if rel0 is None else rel0
        assert np.abs(rel - rel0).max() < 1e-6
        min_stack = min(min_stack, _distance(world, data, book_geom, stack))
    assert min_stack > planner.config.min_distance - 0.002
    crossed = carry.hand_paths["left"][:, 1]
    assert crossed[0] > 0.2 and crossed[-1] < -0.2

    q0 = world.home_qpos()
    reach = planner.move(q0, [_target("right", [*BOOK_XY, GRASP_Z + 0.10])], name="right.pregrasp")
    pos, ang = _site_error(world, reach.qpos[-1], _target("right", [*BOOK_XY, GRASP_Z + 0.10]))
    assert pos < 0.003 and ang < 2.0
    reach_margins = _check_trajectory(world, planner, reach)
    # Reaching all the way down to the grasp, the book itself allowed.
    grasp = planner.move(
        reach.qpos[-1], [_target("right", [*BOOK_XY, GRASP_Z])], name="right.grasp", allow_contact=("book",)
    )
    grasp_margins = _check_trajectory(world, planner, grasp, ("book",))

    same = _check_trajectory(world, planner, left_pick["pregrasp"])
    print(
        f"min CoM margin to the support polygon edge: same-side pregrasp {min(same) * 1000:.1f} mm, "
        f"final {same[-1] * 1000:.1f} mm; left carry across {min(carry_margins) * 1000:.1f} mm, final "
        f"{carry_margins[-1] * 1000:.1f} mm; right reach across {min(reach_margins) * 1000:.1f} mm, final "
        f"{reach_margins[-1] * 1000:.1f} mm; right grasp across final {grasp_margins[-1] * 1000:.1f} mm; "
        f"book-stack clearance min {min_stack * 1000:.1f} mm"
    )
    assert min(carry_margins) < min(same) and min(reach_margins) < min(same)


# ----------------------------------------------------------------------------- 3. handover


def test_handover_side_by_side(world: World, planner: Planner) -> None:
    """Both hands top-down on the book's two ends, the book's long side across the body.

    The hands close along world x (across the book's 11 cm width), so each forearm
    comes in from its own side, and the palms (22 cm along the closing axis, 8 cm
    across) sit side by side with a gap between them.
    """
    q0 = world.home_qpos()
    left = _target("left", [0.30, 0.06, 1.0], hand_top_down_quat((1.0, 0.0, 0.0)))
    right = _target("right", [0.30, -0.06, 1.0], hand_top_down_quat((-1.0, 0.0, 0.0)))
    traj = planner.move(q0, [left, right], name="handover")
    for target in (left, right):
        pos, ang = _site_error(world, traj.qpos[-1], target)
        assert pos < 0.003 and ang < 2.0
    margins = _check_trajectory(world, planner, traj)
    gap = min(
        _distance(world, _kin(world, q), a, b)
        for q in traj.qpos
        for a in _arm_geoms(world, "left")
        for b in _arm_geoms(world, "right")
    )
    print(
        f"handover: min hand-hand distance {gap * 1000:.1f} mm, min CoM margin {min(margins) * 1000:.1f} mm"
    )
    assert gap > planner.config.min_distance - 0.002


def test_handover_in_line_is_infeasible(world: World, planner: Planner) -> None:
    """Left hand at (0.30, 0, 1.0) and right hand 12 cm ahead, both closing along y, is not reachable.

    At z = 1.0 the front hand's fingers would be inside the book stack (x from
    0.41, top at 1.10), and with both forearms coming from behind, the front
    forearm must pass through the rear hand's 22 cm-wide palm.
    """
    q0 = world.home_qpos()
    with pytest.raises(PlanningError) as info:
        planner.move(
            q0,
            [_target("left", [0.30, 0.0, 1.0]), _target("right", [0.42, 0.0, 1.0])],
            name="handover.inline",
        )
    assert info.value.position_error > planner.config.position_tolerance


# ----------------------------------------------------------------------------- 4. unreachable


class _TorsoTilt(mink.Limit):
    """The torso's z axis within ``max_tilt`` of the vertical, its Jacobian by finite differences.

    Row: ``-grad(z_z) dq <= 0.5 (z_z - cos max_tilt)``, ``z_z`` the world-z component of the
    torso's z axis, its gradient by central differences of ``mj_kinematics`` (independent of
    the planner's analytic TiltLimit).
    """

    def __init__(self, model: mujoco.MjModel, max_tilt: float, eps: float = 1e-6) -> None:
        self.model, self.eps = model, eps
        self.min_cos = float(np.cos(max_tilt))
        self.torso = int(mujoco.mj_name2id(model, BODY, "torso"))
        self.scratch = mujoco.MjData(model)

    def _zz(self, q: np.ndarray) -> float:
        self.scratch.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.scratch)
        return float(self.scratch.xmat[self.torso][8])

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> mink.Constraint:
        model, q = self.model, configuration.q
        grad = np.zeros(model.nv)
        dq = np.zeros(model.nv)
        for i in range(model.nv):
            dq[i] = self.eps
            plus, minus = q.copy(), q.copy()
            mujoco.mj_integratePos(model, plus, dq, 1.0)
            mujoco.mj_integratePos(model, minus, -dq, 1.0)
            grad[i] = (self._zz(plus) - self._zz(minus)) / (2 * self.eps)
            dq[i] = 0.0
        return mink.Constraint(G=-grad[None, :], h=np.array([0.5 * (self._zz(q) - self.min_cos)]))


def _reference_reach(world: World, target: np.ndarray, max_tilt_deg: float) -> float:
    """Closest the left hand site gets to ``target`` (any orientation), feet fixed, CoM at the polygon's edge.

    Plain mink (as in tests/test_humanoid_model.py), no collision avoidance: the hand
    goal moves at most 5 cm ahead of the hand per step (so the stretched body does not
    fold up), a stiff ComTask holds the CoM at the front edge of the support
    rectangle shrunk by 2 cm, the furthest the planner may lean, and the torso may tilt
    at most ``max_tilt_deg`` from the vertical, as the planner's.
    """
    model = world.model
    conf = mink.Configuration(model)
    conf.update(world.home_qpos())
    feet = []
    for s in ("left", "right"):
        task = mink.FrameTask(f"{s}_foot", "body", position_cost=1.0, orientation_cost=1.0)
        task.set_target_from_configuration(conf)
        feet.append(task)
    lo, hi = _support_rectangle(world, conf.data)
    com = mink.ComTask(cost=[100.0, 100.0, 0.0])
    com.set_target(np.array([hi[0] - SHRINK, 0.5 * (lo[1] + hi[1]), 0.0]))
    hand = mink.FrameTask("left_hand", "site", position_cost=1.0, orientation_cost=0.0)
    posture = mink.PostureTask(model, cost=1e-2)
    posture.set_target(world.home_qpos())
    frozen = mink.DofFreezingTask(model, dof_indices=list(range(model.nv - 6, model.nv)))  # the book
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "left_hand")
    tilt = _TorsoTilt(model, np.radians(max_tilt_deg))
    best = np.inf
    for _ in range(400):
        here = conf.data.site_xpos[site].copy()
        step = target - here
        goal = here + step * min(1.0, 0.05 / float(np.linalg.norm(step)))
        hand.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(wxyz=TOP_DOWN), goal))
        vel = mink.solve_ik(
            conf,
            [com, hand, posture],
            0.02,
            solver="daqp",
            damping=1e-3,
            limits=[mink.ConfigurationLimit(model), tilt],
            constraints=[*feet, frozen],
        )
        conf.integrate_inplace(vel, 0.02)
        best = min(best, float(np.linalg.norm(conf.data.site_xpos[site] - target)))
    return best


def test_unreachable_target_raises(world: World, planner: Planner) -> None:
    target = np.array([1.8, 0.0, 0.9])
    with pytest.raises(PlanningError) as info:
        planner.move(world.home_qpos(), [_target("left", target)], name="left.far")
    err = info.value
    reference = _reference_reach(world, target, planner.config.max_torso_tilt_deg)
    print(
        f"unreachable: planner {err.position_error:.3f} m short, "
        f"reference best reach {reference:.3f} m; {err}"
    )
    assert err.side == "left" and err.name == "left.far"
    assert "left hand" in str(err) and "'left.far'" in str(err)
    assert err.position_error > 0.5
    assert abs(err.position_error - reference) <= 0.2 * reference


# ----------------------------------------------------------------------------- 5. determinism and API


def test_deterministic(world: World) -> None:
    targets = [_target("right", [*BOOK_XY, GRASP_Z + 0.10])]
    a = Planner(world).move(world.home_qpos(), targets, name="r")
    b = Planner(world).move(world.home_qpos(), targets, name="r")
    assert np.array_equal(a.times, b.times) and np.array_equal(a.qpos, b.qpos)
    assert np.array_equal(a.com_path, b.com_path)


def test_sample_and_top_down_quat(world: World, left_pick: dict[str, Trajectory]) -> None:
    traj = left_pick["pregrasp"]
    assert np.array_equal(traj.sample(-1.0), traj.qpos[0]) or np.allclose(traj.sample(-1.0), traj.qpos[0])
    assert np.allclose(traj.sample(traj.duration + 5.0), traj.qpos[-1])
    mid = 0.5 * (traj.times[3] + traj.times[4])
    q = traj.sample(mid)
    assert np.allclose(q[7:40], 0.5 * (traj.qpos[3, 7:40] + traj.qpos[4, 7:40]))
    assert abs(np.linalg.norm(q[3:7]) - 1.0) < 1e-12
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, hand_top_down_quat((0.0, 2.0, 0.3)))
    assert np.allclose(rot.reshape(3, 3), [[-1, 0, 0], [0, 1, 0], [0, 0, -1]], atol=1e-12)
    # Vectorised sampling (the behaviours' look-ahead): the knots at the knot times, the knots'
    # mean (quaternions renormalised) halfway between, the ends beyond the ends.
    mids = 0.5 * (traj.times[:-1] + traj.times[1:])
    many = traj.sample_many(np.concatenate([traj.times, mids, [-1.0, traj.duration + 1.0]]))
    k = len(traj.times)
    assert np.allclose(many[:k], traj.qpos, rtol=0.0, atol=1e-12)
    mean = 0.5 * (traj.qpos[:-1] + traj.qpos[1:])
    for a in traj.free_quat_adr:
        mean[:, a : a + 4] /= np.linalg.norm(mean[:, a : a + 4], axis=1, keepdims=True)
    assert np.allclose(many[k:-2], mean, rtol=0.0, atol=1e-12)
    assert np.allclose(many[-2:], traj.qpos[[0, -1]], rtol=0.0, atol=1e-12)
    assert np.allclose(np.linalg.norm(many[:, 3:7], axis=1), 1.0, atol=1e-15)
    with pytest.raises(PlanningError):
        # An iteration budget too small for the move: a PlanningError, never an approximation.
        Planner(world, PlannerConfig(max_iterations=2)).move(
            world.home_qpos(), [_target("left", [*BOOK_XY, GRASP_Z])], name="budget", allow_contact=("book",)
        )
