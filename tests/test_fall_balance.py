"""What the stepping balance leaves of a CoM error, and the CoM of a robot that carries an object.

* The residual of a CoM model error after the balance's pelvis shift (two lags in series,
  executive/planning/balance_law.py) against a fine integration of its equations and against a
  humanoid standing on its balance in MuJoCo with a known CoM offset.
* The fall model's gains along a planned walk (executive/risk/fall_balance.py): the whole bias
  where the walk starts, the residual on two feet, the law's CoP on one.
* The CoM of the robot and the object its hand carries (executive/planning/loaded_com.py)
  against MuJoCo's subtree CoM of a model with the object welded to the hand, its Jacobian against
  finite differences; a step that carries a heavy object keeps that CoM over the stance sole.

Numbers in docs/stepping.md ("Falls").
"""

from __future__ import annotations

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import yaml

from executive.execution.simulated import SimulatedRobot
from executive.planning.balance_law import STEPPING_GAINS, BalanceGains, residual_fractions
from executive.planning.loaded_com import LoadedCoM
from executive.planning.planner import Planner
from executive.planning.stepping import Foothold, StepPlanner
from executive.planning.timing import concatenate
from executive.risk.fall_balance import knot_gains, shift_ratio, shrink_polygons, walk_phases
from executive.risk.fall_batch import KnotPolygons
from executive.risk.fall_bias import support_probability
from executive.risk.fall_support import fall_knots
from executive.scenario import loads
from executive.tasks.steps import plan_alternative
from executive.world import model_cache
from executive.world.model import Perturbation, World, build

FALL_STEPS = Path(__file__).resolve().parents[1] / "scenarios" / "fall_steps.yaml"


def _walk_scene(goal: tuple[float, float] = (0.15, 0.0), book_mass: float | None = None) -> str:
    """scenarios/fall_steps.yaml walking to ``goal``; its book weighs ``book_mass`` kg when given."""
    data = yaml.safe_load(FALL_STEPS.read_text())
    data["mission"] = [{"step": {"to": list(goal)}}]
    if book_mass is not None:
        data["scene"]["objects"][0]["mass"] = book_mass
    return yaml.safe_dump(data)


@pytest.fixture(scope="module")
def humanoid() -> World:
    return build(loads(_walk_scene(), source="fall_steps.yaml"))


# --- the residual after the pelvis shift --------------------------------------------------------


def test_the_residual_is_two_lags_in_series() -> None:
    """The closed form against a fine Euler integration of the estimate (b' = c (e - b)) and the
    pelvis shift (u' = a (b - u) on two feet, held on one), over two feet, one foot, two feet."""
    omega, beta = 3.1, 0.87
    a, c = beta * STEPPING_GAINS.integral * omega, STEPPING_GAINS.estimate_rate * omega
    phases = [(0.0, 2.5, True), (2.5, 6.0, False), (6.0, 9.0, True)]
    times = np.array([0.0, 0.8, 2.5, 4.0, 6.0, 7.3, 9.0, 10.0])
    closed = residual_fractions(times, phases, omega, STEPPING_GAINS, beta)
    dt, b, u, t = 1e-5, 0.0, 0.0, 0.0
    euler = []
    for target in times:
        while t < target - 1e-12:
            two_feet = any(start <= t < end for start, end, on_two in phases if on_two)
            b, u = b + dt * c * (1.0 - b), u + (dt * a * (b - u) if two_feet else 0.0)
            t += dt
        euler.append(1.0 - u)
    assert closed[0] == 1.0
    assert np.allclose(closed, euler, atol=2e-4), (closed, euler)
    assert closed[3] == pytest.approx(closed[2])  # held on one foot
    # The same law with an instant estimate is one exponential; with a == c the double root.
    instant = residual_fractions(np.array([2.0]), [(0.0, 5.0, True)], omega, STEPPING_GAINS, beta)
    assert instant[0] == pytest.approx((c * math.exp(-2 * a) - a * math.exp(-2 * c)) / (c - a))
    same = BalanceGains(integral=1.0 / beta)  # a == c
    assert residual_fractions(np.array([1.0]), [(0.0, 5.0, True)], omega, same, beta)[0] == pytest.approx(
        (1.0 + omega) * math.exp(-omega)
    )


def test_a_robot_standing_on_its_balance_leaves_the_closed_form_residual(humanoid: World) -> None:
    """The humanoid stands on its balance (both feet, the CoM held at its model's standing CoM)
    with the truth's CoM 5 cm forward and 3 cm to the left, which it does not know: sideways the
    true CoM error left after 0.5 to 3 s is the closed form's within 0.015 of the offset; forward,
    where both ankles' pitch also acts on two feet, it is no more."""
    offset = np.array([0.05, 0.03])
    truth = build(humanoid.scenario, Perturbation(com_offset=(0.05, 0.03)), kind="truth")
    robot = SimulatedRobot(truth)
    data = mujoco.MjData(humanoid.model)
    data.qpos[:] = humanoid.home_qpos()
    mujoco.mj_kinematics(humanoid.model, data)
    mujoco.mj_comPos(humanoid.model, data)
    base = humanoid.ids.base_body
    planned = data.subtree_com[base].copy()
    omega = math.sqrt(9.81 / planned[2])
    checks = {0.5: None, 1.0: None, 1.5: None, 2.0: None, 2.5: None, 3.0: None}
    while robot.time < 3.0 - 1e-9:
        robot.set_balance(("left", "right"), com=planned)
        robot.advance()
        for t in checks:
            if checks[t] is None and robot.time >= t - 1e-9:
                checks[t] = (truth.data.subtree_com[base][:2] - planned[:2]) / offset
    times = np.array(list(checks))
    model = residual_fractions(times, [(0.0, 10.0, True)], omega, STEPPING_GAINS, shift_ratio(humanoid))
    measured = np.array(list(checks.values()))
    print("t", times, "model", np.round(model, 3), "measured x, y", np.round(measured.T, 3))
    assert np.all(np.abs(measured[:, 1] - model) < 0.015), (measured[:, 1], model)
    assert np.all(measured[:, 0] < model + 0.01), (measured[:, 0], model)
    assert model[-1] < 0.2  # most of the error is gone in 3 s


def test_a_walks_knots_take_the_whole_bias_then_the_residual_then_the_laws_cop(humanoid: World) -> None:
    """On fall_steps' walk (planned by the executive): gain 1 at the walk's first knot, the
    residual on two feet (falling), (1 + convergence) times it on one foot, constant while the
    foot is up; a knot outside any walk keeps gain 1."""
    task = humanoid.scenario.mission[0]
    plan = plan_alternative(Planner(humanoid), humanoid, task, "right_first")
    whole = concatenate(plan.ordered_trajectories(), plan.name)
    phases = walk_phases(plan)
    assert phases[0].start == 0.0 and phases[-1].end == pytest.approx(whole.duration)
    assert [p.feet for p in phases[:5]] == [2, 1, 1, 1, 2]
    knots = fall_knots(humanoid, whole)
    gains = knot_gains(humanoid, knots, phases)
    assert gains[0] == 1.0
    first_shift = knots.times <= phases[0].end
    assert np.all(np.diff(gains[first_shift]) < 0.0)
    on_one = (knots.times > phases[1].start + 1e-6) & (knots.times <= phases[3].end)
    lift = gains[first_shift][-1]
    assert np.allclose(gains[on_one], STEPPING_GAINS.cop_gain * lift)
    assert 0.15 < lift < 0.35  # a 2.5 s weight shift
    assert np.array_equal(knot_gains(humanoid, knots, ()), np.ones(len(knots.times)))


def test_a_polygon_shrunk_by_a_gain_is_the_bias_through_the_gain() -> None:
    """e with gain G outside a polygon is e outside the polygon scaled by 1 / G: the same probability
    as the bias's sigma times G in the polygon as it is; a gain below 1 widens."""
    square = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    polygons = KnotPolygons({4: (np.array([0, 1]), np.stack([square, square]))})
    mus = np.zeros((2, 2))
    cov = 0.03**2 * np.eye(2)
    for gain in (2.0, 0.4):
        shrunk = shrink_polygons(polygons, mus, np.array([1.0, gain]))
        assert np.array_equal(shrunk.groups[4][1][0], square)
        p_shrunk, _, _ = support_probability(
            KnotPolygons({4: (np.array([0]), shrunk.groups[4][1][1:])}), mus[:1], cov
        )
        p_scaled, _, _ = support_probability(
            KnotPolygons({4: (np.array([0]), square[None])}), mus[:1], gain**2 * cov
        )
        assert np.isclose(p_shrunk, p_scaled)


# --- the CoM with a carried object --------------------------------------------------------------


def _welded(world: World, side: str, name: str, relative: np.ndarray) -> mujoco.MjModel:
    """The world's robot alone with a copy of object ``name`` welded to ``side``'s hand body at
    ``relative`` (its position in the hand body's frame)."""
    model = world.model
    spec = model_cache.robot_spec(world.scenario.robot.mjcf)
    hand = mujoco.mj_id2name(
        model, mujoco.mjtObj.mjOBJ_BODY, int(model.site_bodyid[world.ids.hand_sites[side]])
    )
    geom = world.ids.object_geoms[name]
    body = spec.body(hand).add_body(name="welded", pos=list(relative))
    body.add_geom(
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=list(model.geom_size[geom]),
        mass=float(model.body_mass[world.ids.object_bodies[name]]),
    )
    return spec.compile()


def test_the_loaded_com_is_the_subtree_com_with_the_object_welded_to_the_hand(humanoid: World) -> None:
    """The book (made 5 kg) held 8 cm in front of the left hand's body, the arm turned out: the
    robot-and-book CoM is MuJoCo's subtree CoM of the robot with the book welded to that hand, and
    its Jacobian the welded model's (and finite differences of it)."""
    world = build(loads(_walk_scene(book_mass=5.0), source="fall_steps.yaml"))
    model, data = world.model, world.data
    relative = np.array([0.08, 0.02, -0.03])
    q = world.home_qpos()
    shoulder = model.joint(world.profile.arms["left"].joints[0])
    q[model.jnt_qposadr[shoulder.id]] += 0.6
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    hand = int(model.site_bodyid[world.ids.hand_sites["left"]])
    adr = int(model.jnt_qposadr[model.body_jntadr[world.ids.object_bodies["book"]]])
    data.qpos[adr : adr + 3] = data.xpos[hand] + data.xmat[hand].reshape(3, 3) @ relative
    data.qpos[adr + 3 : adr + 7] = data.xquat[hand]
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    loaded = LoadedCoM(world, ("left", "book"))
    assert loaded.mass == pytest.approx(model.body_subtreemass[world.ids.base_body] + 5.0)
    welded = _welded(world, "left", "book", relative)
    wdata = mujoco.MjData(welded)
    nq = welded.nq
    wdata.qpos[:] = q[:nq]
    mujoco.mj_kinematics(welded, wdata)
    mujoco.mj_comPos(welded, wdata)
    reference = wdata.subtree_com[1].copy()
    robot_only = data.subtree_com[world.ids.base_body]
    assert np.linalg.norm(reference - robot_only) > 0.005  # 5 kg a forearm out: the CoM moves
    assert np.allclose(loaded.position(data), reference, atol=1e-9)
    jac = loaded.jacobian(data, np.zeros((3, model.nv)))
    wjac = np.zeros((3, welded.nv))
    mujoco.mj_jacSubtreeCom(welded, wdata, wjac, 1)
    assert np.allclose(jac[:, : welded.nv], wjac, atol=1e-9)
    assert not jac[:, welded.nv :].any()  # the object's own free joint: it moves with the hand
    # And against finite differences of the welded subtree CoM along a few of the robot's dofs.
    for dof in (6, 10, int(model.jnt_dofadr[shoulder.id])):
        step = np.zeros(welded.nv)
        step[dof] = 1e-6
        moved = q[:nq].copy()
        mujoco.mj_integratePos(welded, moved, step, 1.0)
        wdata.qpos[:] = moved
        mujoco.mj_kinematics(welded, wdata)
        mujoco.mj_comPos(welded, wdata)
        assert np.allclose((wdata.subtree_com[1] - reference) / 1e-6, jac[:, dof], atol=1e-4)


def test_a_step_carrying_a_heavy_object_balances_the_robot_and_the_object() -> None:
    """The humanoid steps 10 cm forward holding the book (made 15 kg) in its left hand: the CoM the
    plan keeps over the stance sole and records is the robot's and the book's together, and the
    robot's own CoM alone sits off it by the book's share."""
    world = build(loads(_walk_scene(book_mass=15.0), source="fall_steps.yaml"))
    model = world.model
    q = world.home_qpos()
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_kinematics(model, data)
    hand = int(model.site_bodyid[world.ids.hand_sites["left"]])
    adr = int(model.jnt_qposadr[model.body_jntadr[world.ids.object_bodies["book"]]])
    q[adr : adr + 3] = data.xpos[hand] + data.xmat[hand].reshape(3, 3) @ np.array([0.0, 0.0, -0.06])
    q[adr + 3 : adr + 7] = data.xquat[hand]
    carried = ("left", "book")
    planner = StepPlanner(world, carried=carried)
    start = planner.footholds(q)["right"]
    plan = planner.plan_step(q, "right", Foothold("right", start.x + 0.10, start.y, start.yaw))
    loaded = LoadedCoM(world, carried)
    planner.footholds(q)
    sole = planner.sole_polygon(("left",))
    book = model.body_mass[world.ids.object_bodies["book"]]
    for phase in plan.phases[1:4]:
        trajectory = phase.trajectory
        for k in (0, len(trajectory.times) // 2, len(trajectory.times) - 1):
            data.qpos[:] = trajectory.qpos[k]
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            com = loaded.position(data)
            assert np.allclose(trajectory.com_path[k], com, atol=1e-9)
            assert sole.margin(com) >= plan.sole_margin - 1e-3, phase.name
            own = data.subtree_com[world.ids.base_body]
            share = book / loaded.mass * (data.xipos[world.ids.object_bodies["book"]] - own)
            assert np.allclose(com - own, share, atol=1e-9)
    assert np.linalg.norm(share[:2]) > 0.02  # the book's share is no rounding error
