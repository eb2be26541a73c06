"""The push-contact model against MuJoCo, and a planned push leg keeping to its line.

The physics grid is :mod:`benchmarks.bench_push_contact`'s (a servoed finger pushing a block
three legs, swinging up or across mid-leg), on cells away from the model's boundaries (the
benchmark runs the long grid, boundaries included: docs/risk_models.md, "A push's stall").
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
import yaml

from benchmarks.bench_push_contact import predicted_loss, run_push
from executive.planning.planner import Planner
from executive.risk.gaussian import normal_cdf
from executive.risk.push_contact import loss_probability
from executive.scenario.loader import load
from executive.tasks.steps import plan_alternative
from executive.world.model import build

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"

SWINGS = [(0.0, 0.0), (0.03, 0.0), (0.045, 0.0), (0.085, 0.0), (0.0, 0.02), (0.0, 0.055), (0.0, 0.065)]


@pytest.mark.parametrize(("mass", "friction"), list(itertools.product((0.3, 1.2), (0.5, 1.1))))
def test_the_model_calls_which_swings_lose_the_block(mass: float, friction: float) -> None:
    for rise, lateral in SWINGS:
        run = run_push(mass, friction, rise, lateral)
        p = predicted_loss(rise, lateral)
        assert (p > 0.5) == run.lost, (mass, friction, rise, lateral, p, run.along, run.across)
        assert p < 0.01 or p > 0.99  # the grid's cells are clear of the boundaries


def test_the_loss_probability_is_the_face_interval_and_the_top() -> None:
    # Offsets 0..30 mm on a 40 mm half face, 10 mm object error: the object must lie in [-10, 40].
    p = loss_probability((0.0, 0.03), 0.04, -0.05, 0.01, 0.003)
    assert p == pytest.approx(1.0 - float(normal_cdf(4.0) - normal_cdf(-1.0)), abs=1e-12)
    # A swing wider than the face leaves it whatever the object's offset.
    assert loss_probability((-0.05, 0.05), 0.04, -0.05, 0.01, 0.003) == 1.0
    # Fingertips 6 mm over the top with a 3 mm height spread: Phi(2).
    assert loss_probability((0.0, 0.0), 0.04, 0.006, 0.0, 0.003) == pytest.approx(float(normal_cdf(2.0)))


def test_a_push_leg_goes_straight_where_a_free_move_would_hop_a_neighbour(tmp_path: Path) -> None:
    # pick_place_push's push alone, the box moved beside the block's line: the right hand's
    # world-aligned box (its 22 cm palm across the push) overlaps the box's, which a free move
    # hops (via points 4 cm over its top); the push's legs keep to the line behind the block.
    doc = yaml.safe_load((SCENARIOS / "pick_place_push.yaml").read_text())
    box = next(o for o in doc["scene"]["objects"] if o["name"] == "box")
    box["position"] = [0.45, -0.27]
    doc["mission"] = [doc["mission"][3]]
    path = tmp_path / "beside.yaml"
    path.write_text(yaml.safe_dump(doc))
    scenario = load(path)
    world = build(scenario)
    plan = plan_alternative(Planner(world), world, scenario.mission[0], "right")
    legs = [s for s in plan.steps if s.kind == "push" and s.force is not None]
    assert legs and all(s.straight for s in legs)
    assert not any(s.straight for s in plan.steps if s not in legs)
    start = plan.trajectories[legs[0].name].hand_paths["right"][0]
    rise = max(float(np.max(plan.trajectories[s.name].hand_paths["right"][:, 2])) for s in legs) - start[2]
    assert rise < 0.03  # the block is 8 cm tall, the fingertips 1.5 cm over the table
    free = Planner(world).move(
        plan.trajectories[legs[0].name].qpos[0],
        list(legs[0].targets),
        name="free",
        carried=legs[0].carried,
        allow_contact=legs[0].allow_contact,
    )
    assert float(np.max(free.hand_paths["right"][:, 2])) - start[2] > 0.05
