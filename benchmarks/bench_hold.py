"""The hold risk against physics: a heavy box instead of book_transfer's book, sampled truths.

For each alternative of the heavy-box variant of ``book_transfer`` (the book replaced by a box
of the given size and mass, same place), prints the predicted drop probability (grasp, hold
and their union, :func:`executive.decision.assessment.assess_plan`) and the outcome of ``count``
truths drawn by the truth sampler and run in physics (``executive.execution.runner.run_alternative``),
with the failures counted by kind: the receiver closing on nothing, an object lost from a hand,
a misplaced object, anything else. Per handover trial, also the model's critical mass at the
trial's own lateral offset and yaw error against the trial's mass.

Run: ``python benchmarks/bench_hold.py [count] [length width height mass]``
(defaults: 20 trials, a 0.16 x 0.10 x 0.10 m box of 2.5 kg).
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

from executive.decision.assessment import assess_plan
from executive.execution.runner import run_alternative
from executive.planning.planner import Planner
from executive.risk.collision import CollisionModel
from executive.risk.hold import critical_mass, hold_problem
from executive.scenario import loads
from executive.schema.types import Scenario
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build, sample_perturbation

__all__ = ["heavy_box_scenario", "main"]

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def heavy_box_scenario(size: tuple[float, float, float], mass: float) -> Scenario:
    """book_transfer with its book replaced by a box of ``size`` (m) and ``mass`` (kg)."""
    text = (SCENARIOS / "book_transfer.yaml").read_text()
    text = text.replace("size: [0.22, 0.11, 0.05]", f"size: [{size[0]}, {size[1]}, {size[2]}]")
    return loads(text.replace("mass: 0.6", f"mass: {mass}"), base_dir=SCENARIOS)


def _kind(message: str) -> str:
    if "closed but does not hold" in message:
        return "receiver closed on nothing" if "right" in message else "grasp closed on nothing"
    if "from the" in message and "hand site" in message:
        return "lost from a hand"
    if "rests" in message:
        return "misplaced"
    return message.split(":")[0] if message else "other"


def _trial_critical_mass(world: World, plan: object, seed: int) -> tuple[float, float]:
    """The trial's mass and the model's critical mass at its own offset and yaw error."""
    scenario = world.scenario
    obj = scenario.mission[0].object
    pert = sample_perturbation(scenario, np.random.default_rng(seed))
    problem = hold_problem(world, plan)
    span = problem.spans[0][0]
    x_site = span.grasp_rotation.T[:, 0]  # the site's x in the object frame at the grasp
    yaw0 = next(b for b in scenario.scene.objects if b.name == obj).orientation_rad[2]
    c, s = np.cos(yaw0), np.sin(yaw0)
    x_world = (c * x_site[0] - s * x_site[1], s * x_site[0] + c * x_site[1])  # the object's yaw
    dx, dy, dyaw = pert.object_offsets[obj]
    offset = np.array([dx * x_world[0] + dy * x_world[1]])  # the object moved; the hand did not
    crit, _ = critical_mass(world, problem, offset, 1.0, np.array([dyaw]))
    return problem.mass * pert.object_mass_scale[obj], float(crit[0])


def main(count: int, size: tuple[float, float, float], mass: float) -> None:
    scenario = heavy_box_scenario(size, mass)
    world = build(scenario)
    task = scenario.mission[0]
    planner = Planner(world)
    model = CollisionModel(world, scenario.risk, uncertainty=scenario.uncertainty)
    print(f"box {size} m, {mass} kg; {count} sampled truths per alternative")
    for alt in task.alternatives:
        plan = plan_alternative(planner, world, task, alt)
        drop = assess_plan(world, plan, model).components["drop"]
        grasp, hold = float(drop.details["grasp_probability"]), float(drop.details["hold_probability"])
        print(f"{alt}: predicted drop {drop.probability:.3f} (grasp {grasp:.3f}, hold {hold:.3f})")
        exact = run_alternative(scenario, alt, exact=True)
        print(f"  truth = estimate: {exact.outcome} {exact.message[:100]}")
        kinds: Counter[str] = Counter()
        agree = 0
        for seed in range(count):
            run = run_alternative(scenario, alt, seed=seed)
            kinds["success" if run.success else _kind(run.message)] += 1
            if plan.steps and sum(s.kind == "grasp" for s in plan.steps) > 1:
                m, crit = _trial_critical_mass(world, plan, seed)
                missed = "closed on nothing" in _kind(run.message) or "lost" in _kind(run.message)
                agree += int((m >= crit) == missed)
        print(f"  sampled truths: {dict(kinds)}")
        if agree:
            verdict = "the hold model's verdict (m >= critical mass) agrees with physics"
            print(f"  per trial, {verdict}: {agree}/{count}")


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    dims = tuple(float(v) for v in sys.argv[2:5]) if len(sys.argv) >= 5 else (0.16, 0.10, 0.10)
    main(n, (dims[0], dims[1], dims[2]), float(sys.argv[5]) if len(sys.argv) > 5 else 2.5)
