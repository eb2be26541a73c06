"""Campaigns that decide per trial (``--decide``): each trial's records carry the numbers the
executive decides with on that trial's estimate, and its choice.

Reference: the ``executive plan`` path (every alternative planned and assessed on the estimate,
then the physics check in its own pool of worker processes), run here on the trial's estimate
with the trial's seed; and, for the scoring, the regret and the per-mode scores computed
directly from hand-made records.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from executive.decision.physics_check import with_rollouts
from executive.errors import ExecutiveError
from executive.scenario import load
from executive.schema.types import Scenario
from executive.validation.campaign import read_trials, run_campaign
from executive.validation.campaign_scoring import decision_scores, scored_trials
from executive.validation.regret import regret, trial_table
from executive.validation.stats import expected_calibration_error, roc_auc

ALTERNATIVES = ["left", "left_to_right"]
TRIALS = 2


def scenario() -> Scenario:
    """book_transfer (its scene varied per trial) with one rollout per alternative."""
    return with_rollouts(load("book_transfer"), 1)


@pytest.fixture(scope="module")
def decided(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("decide") / "campaign"
    result = run_campaign(scenario(), trials=TRIALS, out=folder, alternatives=ALTERNATIVES, decide=True)
    assert result.summary["complete"] and not result.interrupted
    return folder


@pytest.mark.slow
def test_records_carry_the_decision_executive_plan_makes_on_the_trials_estimate(decided: Path) -> None:
    from executive.decision.assessment import assess_task
    from executive.decision.physics_check import PhysicsCheck
    from executive.decision.planning_job import ranked
    from executive.validation.campaign import trial_scene
    from executive.validation.campaign_predictions import risk_fields
    from executive.world.model import build

    records = read_trials(decided / "trials.jsonl")
    assert [(r["trial"], r["alternative"]) for r in records] == [
        (i, a) for i in range(TRIALS) for a in ALTERNATIVES
    ]
    base = scenario()
    index = 1
    mine = {r["alternative"]: r for r in records if r["trial"] == index}
    seed = base.trials.seed + index
    # what `executive plan` computes on the trial's estimate, its rollouts seeded by the trial's seed
    estimate, _, shifts = trial_scene(base, seed)
    assert mine["left"]["scene"] == shifts
    task = estimate.mission[0].restricted(tuple(ALTERNATIVES))
    estimate = dataclasses.replace(
        estimate, mission=(task,), trials=dataclasses.replace(estimate.trials, seed=seed)
    )
    world = build(estimate)
    analytic = assess_task(world, task)
    physics = PhysicsCheck(1)
    try:
        checked, verdict = physics.check(world, analytic)
    finally:
        physics.close()
    ordering = estimate.risk.ordering
    for alt in analytic:
        r = mine[alt.name]
        result = verdict.alternatives[alt.name]
        assert result.dry_run_ok and r["physics"]["dry_run"] == "success"
        assert r["physics"]["rollouts"] == result.rollouts == 1
        assert r["physics"]["outcomes"] == dict(result.counts)
        assert alt.risk is not None and result.fused is not None
        expected_analytic = {**risk_fields(alt.risk), "value": alt.risk.value(ordering)}
        expected_fused = {**risk_fields(result.fused), "value": result.fused.value(ordering)}
        assert r["predicted"]["analytic"] == pytest.approx(expected_analytic, rel=1e-12, abs=1e-15)
        assert {k: v for k, v in r["predicted"].items() if k != "analytic"} == pytest.approx(
            expected_fused, rel=1e-12, abs=1e-15
        )
        # a rollout's failure moves the fused probability off the analytic one
        if r["physics"]["outcomes"].get("success") != 1:
            assert r["predicted"]["combined"] != pytest.approx(r["predicted"]["analytic"]["combined"])
    chosen = ranked(checked, ordering)[0].name
    assert all(r["decision"]["chosen"] == chosen for r in mine.values())
    assert mine[chosen]["decision"]["value"] == pytest.approx(mine[chosen]["predicted"]["value"])
    # every alternative that planned was executed on the trial's truth
    assert all(r["outcome"] not in ("infeasible", "error") and r["sim_time_s"] > 0 for r in mine.values())


@pytest.mark.slow
def test_the_summary_scores_the_decisions_and_the_analytic_models_on_the_same_trials(decided: Path) -> None:
    summary = json.loads((decided / "summary.json").read_text())
    records = read_trials(decided / "trials.jsonl")
    assert summary["predictions"].startswith("each trial's decision")
    d = summary["decision"]
    assert d["decisions"] == TRIALS and d["trials"] == len(scored_trials(records))
    any_fused = np.array([r["predicted"]["combined"] for r in scored_trials(records)])
    any_analytic = np.array([r["predicted"]["analytic"]["combined"] for r in scored_trials(records)])
    failed = np.array([r["outcome"] != "success" for r in scored_trials(records)])
    assert d["fused"]["any"]["ece"] == pytest.approx(expected_calibration_error(any_fused, failed))
    assert d["analytic"]["any"]["ece"] == pytest.approx(expected_calibration_error(any_analytic, failed))
    assert summary["ece"]["any"] == pytest.approx(d["fused"]["any"]["ece"])
    chosen = {r["trial"]: r["decision"]["chosen"] for r in records}
    assert summary["regret"]["choice"]["chosen"] == {a: list(chosen.values()).count(a) for a in ALTERNATIVES}
    text = (decided / "table.md").read_text()
    assert "Fused vs analytic predictions on the same" in text and "executive's choice per trial" in text


@pytest.mark.slow
def test_a_cut_decide_campaign_resumes_to_the_same_file(decided: Path, tmp_path: Path) -> None:
    """Trial 1 cut after its first alternative: resume decides it again and runs the rest."""
    out = tmp_path / "cut"
    out.mkdir()
    shutil.copy(decided / "campaign.json", out / "campaign.json")
    lines = (decided / "trials.jsonl").read_bytes().splitlines(keepends=True)
    (out / "trials.jsonl").write_bytes(b"".join(lines[: len(ALTERNATIVES) + 1]) + b'{"trial": 1, "alt')
    with pytest.raises(ExecutiveError, match="resume it with --decide"):
        run_campaign(scenario(), trials=TRIALS, out=out, resume=True, alternatives=ALTERNATIVES)
    with pytest.raises(ExecutiveError, match="decided with 1 rollouts"):
        run_campaign(with_rollouts(scenario(), 2), trials=TRIALS, out=out, resume=True,
                     alternatives=ALTERNATIVES, decide=True)  # fmt: skip
    result = run_campaign(
        scenario(), trials=TRIALS, out=out, resume=True, alternatives=ALTERNATIVES, decide=True
    )
    assert result.new_trials == len(ALTERNATIVES) * TRIALS - len(ALTERNATIVES) - 1
    assert (out / "trials.jsonl").read_bytes() == (decided / "trials.jsonl").read_bytes()


def _record(trial: int, alternative: str, failed: bool, value: float, **extra: Any) -> dict[str, Any]:
    predicted = {"collision": 0.1, "fall": 0.0, "drop": 0.1, "combined": value, "value": value}
    return {
        "trial": trial,
        "alternative": alternative,
        "outcome": "collision" if failed else "success",
        "predicted": {**predicted, "analytic": {**predicted, "combined": 0.5, "value": 1.0 - value}},
        **extra,
    }


def test_the_regret_scores_the_recorded_choice_not_the_lowest_value() -> None:
    """Hand-made: the decision chose ``b`` (which fails) where ``a`` has the lower value and
    succeeds; a decision that chose nothing counts as a failure."""
    names = ["a", "b"]
    records = []
    for t in range(4):
        chosen = "b" if t < 3 else None
        decision = {"chosen": chosen}
        records += [
            _record(t, "a", False, 0.1, decision=decision),
            _record(t, "b", True, 0.9, decision=decision),
        ]
    table = trial_table(records, names)
    assert table.chosen is not None and list(table.chosen) == [1, 1, 1, -1]
    r = regret(table)
    # every choice failed; the best fixed alternative (a, on either half) never did
    assert (r.choice_failures, r.best_failures, r.regret) == (4, 0, 1.0)
    assert r.chosen == {"a": 0, "b": 3, "(none)": 1}
    # without the recorded decision the lowest value is chosen: a, never failing
    plain = regret(trial_table([{k: v for k, v in x.items() if k != "decision"} for x in records], names))
    assert (plain.choice_failures, plain.regret) == (0, 0.0)


def test_decision_scores_leave_out_failed_dry_runs_and_score_both_on_the_rest() -> None:
    ok = {"dry_run": "success"}
    records = [
        _record(0, "a", True, 0.8, physics=ok, decision={"chosen": "a", "above_threshold": True}),
        _record(0, "b", False, 0.2, physics={"dry_run": "collision"}, decision={"chosen": "a"}),
        _record(1, "a", False, 0.3, physics=ok, decision={"chosen": "b"}),
        _record(1, "b", True, 0.6, physics=ok, decision={"chosen": "b"}),
    ]
    kept = [records[0], records[2], records[3]]
    assert scored_trials(records) == kept
    d = decision_scores(records)
    assert (d["trials"], d["dry_run_failed"], d["decisions"], d["above_threshold"]) == (3, 1, 2, 1)
    y = np.array([True, False, True])
    fused = np.array([0.8, 0.3, 0.6])
    assert d["fused"]["any"]["auc"] == pytest.approx(roc_auc(fused, y)) == 1.0
    assert d["fused"]["any"]["ece"] == pytest.approx(expected_calibration_error(fused, y))
    assert d["analytic"]["any"]["ece"] == pytest.approx(expected_calibration_error(np.full(3, 0.5), y))


def test_the_command_resumes_a_campaign_only_the_way_it_was_made(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from executive.cli.main import main
    from executive.validation.campaign_folder import campaign_config

    base = load("book_transfer")
    names = list(base.mission[0].alternatives)
    config = campaign_config(base, base.trials.seed, 0, names, 1, decide=False)
    (tmp_path / "campaign.json").write_text(json.dumps(config))
    assert (
        main(["campaign", "book_transfer", "--trials", "1", "--decide", "--resume", "--out", str(tmp_path)])
        == 2
    )
    assert "predicts on the estimate; resume it without --decide" in capsys.readouterr().err
    config = campaign_config(base, base.trials.seed, 0, names, 1, decide=True)
    (tmp_path / "campaign.json").write_text(json.dumps(config))
    args = ["campaign", "book_transfer", "--trials", "1", "--decide", "--rollouts", "2", "--resume"]
    assert main([*args, "--out", str(tmp_path)]) == 2
    assert "decided with 4 rollouts per alternative; this run asks for 2" in capsys.readouterr().err
