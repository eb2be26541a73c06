"""Rollouts spent where the choice is unclear, and each run ending at its outcome (real MuJoCo)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import yaml

from executive.decision.assessment import assess_task
from executive.decision.physics_check import check_alternatives, estimate_scenario, run_job
from executive.decision.rollout_allocation import CLEAR, COUNT, GOING, allocate
from executive.execution.runner import execute_plan
from executive.risk.fusion import Choice, Contention
from executive.scenario import load, loads
from executive.schema.catalog import scenario_path
from executive.schema.types import RolloutConfig
from executive.world.model import build


def _view(best: str, confidence: float, rivals: dict[str, float], above: float = 0.0) -> Contention:
    return Contention(Choice(best, confidence, 0.0), rivals, above)


def test_the_allocation_keeps_the_minimum_the_cap_and_the_contenders() -> None:
    cfg = RolloutConfig(count=6, min_count=2, batch=2, confidence=0.95)
    # Three alternatives: b is close to the best a, c clearly worse; P(clear) 0.80 < 0.95.
    view = _view("a", 0.80, {"a": 0.0, "b": 0.19, "c": 0.001})
    assert allocate(view, {"a": 2, "b": 2, "c": 2}, cfg) == {"a": GOING, "b": GOING, "c": CLEAR}
    assert allocate(view, {"a": 2, "b": 2, "c": 1}, cfg)["c"] == GOING  # the minimum first
    assert allocate(view, {"a": 6, "b": 6, "c": 2}, cfg) == {"a": COUNT, "b": COUNT, "c": CLEAR}
    # the share is (1 - confidence) / (m - 1) = 0.025 of 3 alternatives
    assert allocate(_view("a", 0.97, {"a": 0.0, "b": 0.024, "c": 0.0}), {"a": 2, "b": 2, "c": 2}, cfg) == {
        "a": CLEAR,
        "b": CLEAR,
        "c": CLEAR,
    }
    # a choice that is clear, but whose best may need approval: only the best goes on
    unsure = _view("a", 0.99, {"a": 0.0, "b": 0.0}, above=0.5)
    assert allocate(unsure, {"a": 2, "b": 2}, cfg) == {"a": GOING, "b": CLEAR}
    assert allocate(_view("a", 1.0, {"a": 0.0}, above=0.5), {"a": 6}, cfg) == {"a": COUNT}
    assert allocate(_view("a", 1.0, {"a": 0.0}, above=0.99), {"a": 2}, cfg) == {"a": CLEAR}


def test_a_clearly_decided_pair_gets_fewer_rollouts_and_none_past_the_cap() -> None:
    """Real plans and physics: picking the book of pick_place_push with the left or the right
    hand, both with a risk near 0 (well within the indifference of each other and under the
    threshold). After the minimum the choice is clear: neither goes on to the cap."""
    base = load("pick_place_push")
    rollouts = dataclasses.replace(base.risk.rollouts, count=6, min_count=2, batch=2, budget_s=3600.0)
    scenario = dataclasses.replace(base, risk=dataclasses.replace(base.risk, rollouts=rollouts))
    world = build(scenario)
    results = assess_task(world, scenario.mission[0])
    plans = {a.name: a.plan for a in results if a.plan is not None}
    analytic = {a.name: a.risk for a in results if a.risk is not None}
    assert set(plans) == {"left", "right"}
    verdict = check_alternatives(
        plans, analytic, estimate_scenario(world), lambda jobs: [run_job(j) for j in jobs]
    )
    got = {name: r.rollouts for name, r in verdict.alternatives.items()}
    assert all(2 <= n <= 6 for n in got.values())  # the minimum and the cap
    assert sum(got.values()) < 2 * 6  # a fixed count would have spent 12
    assert verdict.stopped == CLEAR and verdict.confidence is not None and verdict.confidence >= 0.95
    assert all(r.stopped == CLEAR for r in verdict.alternatives.values())
    assert verdict.as_dict()["allocation"] == got and verdict.rollouts_total == sum(got.values())
    # the steps counted are those of the runs: dry run and rollouts of both, each a whole pick
    runs = len(plans) + verdict.rollouts_total
    assert verdict.physics_steps > runs * min(p.duration for p in plans.values()) / world.model.opt.timestep


def test_a_run_simulates_nothing_after_its_outcome(tmp_path: Path) -> None:
    """A 4 kg box: the handover's receiver closes on air (a behaviour's drop verdict), the left
    hand succeeds. Each run stops on the tick its outcome is known: every physics step is one of
    the control periods before that tick, and the failure is within the last of them."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["robot"] = "humanoid"
    doc["scene"]["objects"][0].update(size=[0.14, 0.10, 0.10], mass=4.0)
    doc["mission"][0]["transfer"]["alternatives"] = ["left", "left_to_right"]
    scenario = loads(yaml.safe_dump(doc), source="heavy_box.yaml")
    world = build(scenario)
    plans = {a.name: a.plan for a in assess_task(world, scenario.mission[0]) if a.plan is not None}
    estimate = estimate_scenario(world)
    outcomes = {}
    for name, plan in plans.items():
        truth = build(estimate)
        dt, step = 0.02, truth.model.opt.timestep
        result = execute_plan(plan, truth, plan.task, control_dt=dt)
        outcomes[name] = result.outcome
        periods = result.ticks - 1  # the last tick saw the outcome and advanced nothing
        assert result.physics_steps == round(periods * dt / step)
        assert result.sim_time_s == pytest.approx(periods * dt, abs=step / 2)
        if result.failure is not None:
            assert result.sim_time_s - dt - 1e-9 <= result.failure.time <= result.sim_time_s + 1e-9
    assert outcomes == {"left": "success", "left_to_right": "failed"}


def test_the_old_fixed_count_is_a_setting() -> None:
    """min_count = count: every alternative gets the count, as before the allocation."""
    cfg = dataclasses.replace(load("book_transfer").risk.rollouts, count=4, min_count=4, batch=4)
    view = _view("a", 0.5, {"a": 0.0, "b": 0.0})
    assert allocate(view, {"a": 0, "b": 0}, cfg) == {"a": GOING, "b": GOING}
    assert allocate(view, {"a": 4, "b": 4}, cfg) == {"a": CLEAR, "b": CLEAR}
