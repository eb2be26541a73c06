"""Reproduce a push that ends with the hand on the block: pick_place_push's push suite, one trial.

Draws variant ``K`` of pick_place_push as ``executive fidelity`` does (seed 0, the bundled
variation ranges), takes trial ``I``'s estimate and truth, plans the push with hand ``SIDE``
on the estimate and runs it on the truth (:func:`executive.execution.runner.execute_plan`'s
loop), logging every 0.1 s of the push's legs: the hand site's planned and actual position,
the block's height and tilt, and each contact between the hand's geoms and the block (the geom,
the contact point in the block's frame in mm, the normal from the block to the hand, the force
on the hand in N). Then per push leg the planned hand's rise over the leg's start, its swing
across the push, and the face model's numbers (:mod:`executive.risk.push_contact`).

Run: ``python benchmarks/push_climb.py [K I SIDE]`` (default ``5 0 left``: the hand ends 50 mm
above its planned end, on the block's top). Findings: docs/risk_models.md, "A push's stall".
"""

from __future__ import annotations

import sys
from pathlib import Path

import mujoco
import numpy as np
import py_trees

from executive.schema.types import Scenario

__all__ = ["main", "variant_scenario"]

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
TASK = 3  # pick_place_push's push


def variant_scenario(index: int, seed: int = 0) -> Scenario:
    """Variant ``index`` of pick_place_push as ``executive fidelity --seed SEED`` draws it."""
    from executive.scenario import from_dict, load
    from executive.validation.variants import base_document, make_variant
    from executive.validation.variation_ranges import load_ranges

    base = load(SCENARIOS / "pick_place_push.yaml")
    ranges = load_ranges(SCENARIOS / "variation" / "pick_place_push.yaml")
    variant = make_variant(base, base_document(base), seed, index, ranges)
    return from_dict(variant.document, f"variant {index}")


def _contacts(model: mujoco.MjModel, data: mujoco.MjData, hand: set[int], block: int) -> list[str]:
    rows = []
    for i in range(data.ncon):
        c = data.contact[i]
        if block not in (c.geom1, c.geom2):
            continue
        other = c.geom2 if c.geom1 == block else c.geom1
        if int(model.geom_bodyid[other]) not in hand:
            continue
        force = np.zeros(6)
        mujoco.mj_contactForce(model, data, i, force)
        sign = 1.0 if c.geom1 == block else -1.0  # the frame's normal points from geom1 to geom2
        frame = c.frame.reshape(3, 3)
        point = data.geom_xmat[block].reshape(3, 3).T @ (c.pos - data.geom_xpos[block])
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, other)
        rows.append(
            f"    {name}: at {np.round(point * 1000, 1)} mm, normal {np.round(sign * frame[0], 2)}, "
            f"force on the hand {np.round(sign * frame.T @ force[:3], 1)} N"
        )
    return rows


def main(index: int = 5, trial: int = 0, side: str = "left") -> None:
    """Plan, run and log trial ``trial`` of variant ``index`` with hand ``side``."""
    from behaviours.restance import install_replanner
    from behaviours.robot_access import install
    from executive.execution.runner import hold_from_start
    from executive.execution.simulated import SimulatedRobot
    from executive.monitoring.detectors import FailureDetector
    from executive.planning.plan import held_at_start
    from executive.planning.restance import LocalReplanner
    from executive.risk.push_contact import face_contact
    from executive.tasks.registry import get as task_kind
    from executive.validation.campaign_predictions import predict
    from executive.validation.campaign_trials import trial_scene
    from executive.world.model import build
    from executive.world.observation import SimulatedSensor

    scenario = variant_scenario(index)
    seed = scenario.trials.seed + trial
    estimate, perturbation, _ = trial_scene(scenario, seed)
    plan = predict(estimate, TASK, side).plan
    if plan is None:
        print(f"variant {index}, {side}: does not plan")
        return
    contact = face_contact(build(estimate), plan, estimate.uncertainty)
    print(f"variant {index} trial {trial} {side}: {contact}")
    for step in plan.steps:
        if step.kind == "push" and step.force is not None:
            path = np.asarray(plan.trajectories[step.name].hand_paths[side])
            print(f"  {step.name}: planned hand rises {(path[:, 2].max() - path[0, 2]) * 1000:.0f} mm")
    truth = build(estimate, perturbation, kind="truth")
    model, data = truth.model, truth.data
    robot = SimulatedRobot(
        truth,
        control_dt=0.02,
        detector=FailureDetector(truth, distance_stride=0),
        sensor=SimulatedSensor(truth, seed),
    )
    install(robot)
    install_replanner(LocalReplanner(truth.scenario))
    hold_from_start(robot, held_at_start(plan.steps))
    root = task_kind(estimate.mission[TASK].kind).subtree(plan)
    tree = py_trees.trees.BehaviourTree(root)
    tree.setup()
    hand, block = set(truth.ids.hand_bodies[side]), truth.ids.object_geoms["block"]
    body, site, last = truth.ids.object_bodies["block"], truth.ids.hand_sites[side], -1.0
    while data.time < plan.duration + 10.0:
        tree.tick()
        if root.status != py_trees.common.Status.RUNNING:
            break
        robot.advance()
        tip = root.tip()
        name = tip.name if tip else ""
        if ".push" not in name or data.time - last < 0.1:
            continue
        last = data.time
        tilt = np.degrees(np.arccos(min(1.0, float(data.xmat[body][8]))))
        print(
            f"t {data.time:.2f} {name}: hand {np.round(data.site_xpos[site] * 1000, 1)} mm, "
            f"block z {data.xpos[body][2] * 1000:.1f} mm tilted {tilt:.1f} deg"
        )
        for row in _contacts(model, data, hand, block):
            print(row)
    tip = root.tip()
    print(f"end: {root.status.name} at {tip.name if tip else ''}: {tip.feedback_message if tip else ''}")


if __name__ == "__main__":
    args = sys.argv[1:]
    main(int(args[0]), int(args[1]), args[2]) if args else main()
