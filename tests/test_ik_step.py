"""The planner's IK step is mink's: its QP, assembled and solved on the unfrozen dofs with the
joint range and velocity limits as simple bounds (``JointBounds.solve``), has the solution of
``mink.solve_ik`` with the same tasks, those two limits as mink's rows and the frozen dofs as an
equality (mink 0.0.x, ``solver="daqp"``). Reference: mink itself, step after step of a reach.
"""

from __future__ import annotations

import mink
import numpy as np
import pytest

from executive.planning.planner import Planner
from executive.scenario import load
from executive.world.model import World, build


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("book_transfer"))


def test_the_planners_ik_step_is_mink_solve_ik(world: World) -> None:
    planner = Planner(world)
    cfg = planner.config
    model = world.model
    conf = planner.configuration
    conf.update(world.home_qpos())
    for foot in planner.feet:
        foot.set_target_from_configuration(conf)
    planner.posture.set_target(world.home_qpos())
    planner.com.set_target(conf.data.subtree_com[1].copy())
    hand = planner.hands["left"]
    start = conf.get_transform_frame_to_world("left_hand", "site")
    goal = mink.SE3.from_rotation_and_translation(
        start.rotation(), start.translation() + np.array([0.15, -0.20, 0.05])
    )
    hand.set_target(goal)
    tasks = [planner.com, planner.posture, hand]
    velocities = {name: v / cfg.velocity_scale for name, v in planner.velocity_limits.items()}
    reference_limits = [planner.joints.config, mink.VelocityLimit(model, velocities), planner.tilt]
    worst = 0.0
    for _ in range(30):
        ours = planner.joints.solve(conf, tasks, cfg.ik_dt, cfg.damping, [planner.tilt], planner.feet)
        theirs = mink.solve_ik(
            conf,
            tasks,
            cfg.ik_dt,
            solver="daqp",
            damping=cfg.damping,
            limits=reference_limits,
            constraints=[*planner.feet, planner.freeze],
        )
        scale = max(1.0, float(np.abs(theirs).max()))
        worst = max(worst, float(np.abs(ours - theirs).max()) / scale)
        conf.integrate_inplace(theirs, cfg.ik_dt)
    moved = np.linalg.norm(
        conf.get_transform_frame_to_world("left_hand", "site").translation() - start.translation()
    )
    print(
        f"30 IK steps: largest difference to mink.solve_ik {worst:.2e} (relative); hand moved {moved:.3f} m"
    )
    assert moved > 0.05  # the steps did something
    assert worst < 1e-6
