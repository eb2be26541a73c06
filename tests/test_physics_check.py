"""Risk checked in physics before the robot moves: dry runs and rollouts in MuJoCo."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from executive.decision.assessment import assess_task
from executive.decision.physics_check import check_alternatives, estimate_scenario, run_job, with_rollouts
from executive.runtime.mission import Executive
from executive.scenario import load, loads
from executive.schema.catalog import scenario_path
from executive.schema.types import Scenario
from executive.world.model import build


def _heavy_box(tmp_path: Path) -> Path:
    """book_transfer with a 4 kg box: the giving arm sags under it and the receiver closes on air."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["name"] = "heavy_box"
    doc["robot"] = "humanoid"
    book = doc["scene"]["objects"][0]
    book.update(size=[0.14, 0.10, 0.10], mass=4.0)
    doc["risk"]["threshold"] = 0.001  # every alternative needs approval: the prompt shows the checks
    doc["risk"]["rollouts"] = {"budget_s": 3600}  # the rounds the stopping rule asks for, at any speed
    path = tmp_path / "heavy_box.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _lines(folder: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (folder / "decisions.jsonl").read_text().splitlines()]


def test_an_alternative_whose_dry_run_fails_is_never_executed(tmp_path: Path) -> None:
    """The heavy box's handover plans, but fails in physics with truth = estimate; the executive
    marks it infeasible with the detector's verdict and runs a one-arm alternative. Planned inside
    the tick (``background=False``): the robot does not stand in physics for as long as planning
    takes in wall time, so the run is the same on any machine."""
    executive = Executive(
        _heavy_box(tmp_path), approval="auto", truth="exact", out=tmp_path / "run", background=False
    )
    executive.run()
    lines = _lines(tmp_path / "run")
    dry = {e["name"]: e for e in lines if e["kind"] == "dry_run"}
    assert set(dry) == {"left", "right", "left_to_right"}
    assert dry["left"]["ok"] and dry["right"]["ok"]
    handover = dry["left_to_right"]
    assert not handover["ok"] and handover["outcome"] == "drop"
    assert handover["reason"].startswith("fails in simulation with the scene as estimated: ")
    assert "does not hold" in handover["reason"]
    plan = next(e for e in lines if e["kind"] == "plan" and e["name"] == "left_to_right")
    assert not plan["feasible"] and plan["reason"] == handover["reason"]
    executed = [e["alternative"] for e in lines if e["kind"] == "execute"]
    assert executed and "left_to_right" not in executed
    assert executive.outcome == "success"
    # the operator sees the dry run's verdict and the rollouts
    request = next(e for e in lines if e["kind"] == "approval_request")["request"]
    rows = {r["name"]: r for r in request["alternatives"]}
    assert not rows["left_to_right"]["feasible"] and rows["left_to_right"]["reason"] == handover["reason"]
    # two to four rollouts: the minimum, more while the choice or the approval is unsure
    assert re.match(r"dry run: ok; [234] rollouts: ", rows["left"]["physics"])
    from executive.decision.approval import AlternativeRisk as Row
    from executive.decision.approval import ApprovalRequest, request_table

    table = request_table(
        ApprovalRequest(**{**request, "alternatives": tuple(Row(**r) for r in request["alternatives"])})
    )
    assert (
        re.search(r"dry run: ok; [234] rollouts", table)
        and "fails in simulation with the scene as estimated" in table
    )


def _one_alternative(count: int) -> tuple[Scenario, dict[str, Any], dict[str, Any]]:
    scenario = with_rollouts(load("book_transfer"), count)
    scenario = dataclasses.replace(
        scenario, mission=(dataclasses.replace(scenario.mission[0], alternatives=("left_to_right",)),)
    )
    world = build(scenario)
    (alt,) = assess_task(world, scenario.mission[0])
    assert alt.plan is not None and alt.risk is not None
    return estimate_scenario(world), {alt.name: alt.plan}, {alt.name: alt.risk}


def test_rollouts_are_seeded_and_fused_with_their_counts() -> None:
    """Same seed, same truths, same counts; the fused risk is the posterior of those counts."""
    scenario, plans, analytic = _one_alternative(3)
    rollouts = dataclasses.replace(scenario.risk.rollouts, min_count=3)
    scenario = dataclasses.replace(scenario, risk=dataclasses.replace(scenario.risk, rollouts=rollouts))
    runs = [
        check_alternatives(plans, analytic, scenario, lambda jobs: [run_job(j) for j in jobs])
        for _ in range(2)
    ]
    first, second = (r.alternatives["left_to_right"] for r in runs)
    assert first.counts == second.counts and sum(first.counts.values()) == 3
    # One alternative: nothing to choose between, but its approval is unsure (expected loss ~0.15
    # against the threshold 0.3 with a prior of 10 trials): it goes on to the cap.
    assert runs[0].stopped == "count" and first.stopped == "count"
    cfg = scenario.risk.rollouts
    w, n = cfg.prior_weight, 3
    drops = first.counts.get("drop", 0)
    # The prior is the analytic risk as the dry run refined it (its measured end errors and
    # placement): the rollouts' counts update that.
    assert first.measured is not None and first.prior is first.measured
    p_a = first.prior.components["drop"].probability
    assert first.risk.components["drop"].probability == pytest.approx((w * p_a + drops) / (w + n))
    assert first.measured.components["collision"] is first.analytic.components["collision"]  # no update


def test_bad_rollout_settings_are_located() -> None:
    text = scenario_path("book_transfer").read_text()
    from executive.errors import ScenarioError

    with pytest.raises(ScenarioError, match=r"risk\.rollouts.*min_count"):
        loads(
            text.replace("  threshold: 0.3\n", "  threshold: 0.3\n  rollouts: {count: 4, min_count: 8}\n"),
            source="x.yaml",
        )
    with pytest.raises(ScenarioError, match=r"risk\.rollouts\.confidence"):
        loads(
            text.replace("  threshold: 0.3\n", "  threshold: 0.3\n  rollouts: {confidence: 1.5}\n"),
            source="x.yaml",
        )


def test_where_the_analytic_models_and_physics_disagree_the_ranking_follows_physics(tmp_path: Path) -> None:
    """The bundled scene with a 1.5 kg book.

    The analytic models rank the right hand last (its approach leaves the jaws the least room);
    its rollouts in physics have the fewest failures. The counts move every fused estimate from
    its prior (the analytic value as the dry run refined it) towards the observed frequency, and
    the ranking follows them.
    """
    from executive.decision.physics_check import RolloutPool

    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["robot"] = "humanoid"
    doc["scene"]["objects"][0]["mass"] = 1.5
    # All 8 rollouts each, whatever the machine's speed: no wall-time budget, no early stop.
    doc["risk"]["rollouts"] = {"count": 8, "min_count": 8, "budget_s": 3600}
    scenario = loads(yaml.safe_dump(doc), source="heavy_book.yaml")
    world = build(scenario)
    results = assess_task(world, scenario.mission[0])
    plans = {a.name: a.plan for a in results if a.plan is not None}
    analytic = {a.name: a.risk for a in results if a.risk is not None}
    ordering = scenario.risk.ordering
    assert max(analytic, key=lambda n: analytic[n].value(ordering)) == "right"  # the models' last
    pool = RolloutPool(2)
    try:
        verdict = check_alternatives(plans, analytic, estimate_scenario(world), pool)
    finally:
        pool.close()
    checked = verdict.alternatives
    failures = {n: r.rollouts - r.counts["success"] for n, r in checked.items()}
    print(
        {n: (dict(r.counts), r.analytic.value(ordering), r.risk.value(ordering)) for n, r in checked.items()}
    )
    assert failures["right"] < min(failures["left"], failures["left_to_right"])  # physics' first
    for r in checked.values():  # each fused probability lies between its prior and k / n
        for mode, report in r.risk.components.items():
            p_a, k = r.prior.components[mode].probability, report.details["failures"]
            low, high = sorted((p_a, k / r.rollouts))
            assert low - 1e-12 <= report.probability <= high + 1e-12
    assert min(checked, key=lambda n: checked[n].risk.value(ordering)) == "right"
