"""Validation campaigns: seeded, parallel, resumable trials executed in real physics.

One tiny reference campaign (2 trials of two alternatives, one job) is shared by the
tests of this module; the others compare against it byte for byte.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from executive.cli.main import main
from executive.scenario import load
from executive.schema import catalog as registry
from executive.schema.types import Scenario, TrialsConfig
from executive.validation.campaign import observed_outcomes, read_trials, run_campaign
from executive.validation.stats import clopper_pearson
from executive.world.model import build, sample_perturbation

ALTERNATIVES = ["left", "left_to_right"]
TRIALS = 2


def fixed_estimate() -> Scenario:
    """book_transfer without its scene variation: one estimate, planned once per alternative."""
    scenario = load("book_transfer")
    return dataclasses.replace(scenario, trials=TrialsConfig(scenario.trials.count, scenario.trials.seed))


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("campaign") / "jobs1"
    scenario = fixed_estimate()
    result = run_campaign(scenario, trials=TRIALS, jobs=1, out=folder, alternatives=ALTERNATIVES)
    assert result.summary["complete"] and not result.interrupted
    return folder


def _records(folder: Path) -> list[dict[str, Any]]:
    return read_trials(folder / "trials.jsonl")


@pytest.mark.slow
def test_trials_are_the_seeded_truths_executed_in_physics(reference: Path) -> None:
    records = _records(reference)
    assert [(r["trial"], r["alternative"]) for r in records] == [
        (i, a) for i in range(TRIALS) for a in ALTERNATIVES
    ]
    scenario = fixed_estimate()
    for r in records:
        # the truth of trial i is the perturbation drawn with seed trials.seed + i, whatever the alternative
        assert r["seed"] == scenario.trials.seed + r["trial"]
        drawn = sample_perturbation(scenario, np.random.default_rng(r["seed"]))
        book = list(drawn.object_offsets["book"])
        assert r["truth"]["object_offsets"]["book"] == pytest.approx(book, abs=1e-8)
        assert r["truth"]["com_offset"] == pytest.approx(list(drawn.com_offset), abs=1e-8)
        assert r["outcome"] in ("success", *observed_outcomes())
        assert 0.0 <= r["predicted"]["collision"] <= 1.0 and 0.0 <= r["predicted"]["combined"] <= 1.0
        # physics really ran: a success ran the whole plan (tens of seconds of robot time), a
        # failure names the detector's mode and stops where it was detected
        if r["outcome"] == "success":
            assert r["sim_time_s"] > 10.0 and r["placement_error_m"] < 0.02
        else:
            assert r["failure"]["mode"] == r["outcome"] and 0.0 < r["failure"]["time"] <= r["sim_time_s"]
    # the predicted risk is the plan's on the estimate: the same in every trial of an alternative
    for a in ALTERNATIVES:
        predicted = {json.dumps(r["predicted"], sort_keys=True) for r in records if r["alternative"] == a}
        assert len(predicted) == 1


@pytest.mark.slow
def test_a_trial_reproduces_the_runner_on_its_sampled_truth(reference: Path) -> None:
    """Independent re-execution of one trial with the runner gives the recorded outcome."""
    from executive.execution.runner import execute_plan
    from executive.planning.planner import Planner
    from executive.tasks.steps import plan_alternative

    scenario = fixed_estimate()
    record = next(r for r in _records(reference) if r["alternative"] == "left_to_right")
    estimate = build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, scenario.mission[0], "left_to_right")
    perturbation = sample_perturbation(scenario, np.random.default_rng(record["seed"]))
    truth = build(scenario, perturbation, kind="truth")
    result = execute_plan(plan, truth, scenario.mission[0])
    assert (result.failure.mode if result.failure else "success") == record["outcome"]
    assert result.sim_time_s == pytest.approx(record["sim_time_s"], abs=1e-6)


@pytest.mark.slow
def test_summary_counts_and_intervals_come_from_the_trials(reference: Path) -> None:
    summary = json.loads((reference / "summary.json").read_text())
    records = _records(reference)
    for alt in summary["alternatives"]:
        mine = [r for r in records if r["alternative"] == alt["name"]]
        assert alt["trials"] == len(mine) == TRIALS
        for mode in observed_outcomes():
            assert alt["failures"][mode] == sum(r["outcome"] == mode for r in mine)
        k = sum(r["outcome"] != "success" for r in mine)
        assert alt["failures"]["any"] == k
        assert alt["failure_rate"]["value"] == k / TRIALS
        assert alt["failure_rate"]["ci95"] == pytest.approx(list(clopper_pearson(k, TRIALS)))
        assert alt["predicted"]["collision"] == pytest.approx(mine[0]["predicted"]["collision"])
    for key in ("auc", "brier", "ece", "spearman"):
        assert key in summary
    # ranking the alternatives by their observed rates is the best any per-alternative constant
    # prediction can do (Neyman-Pearson: order groups by likelihood ratio, monotone in the rate)
    for mode, auc in summary["auc"].items():
        if auc is not None:
            assert auc <= summary["auc_ceiling_per_alternative"][mode] + 1e-12
    assert (reference / "reliability.png").read_bytes()[:4] == b"\x89PNG"
    assert "| left_to_right |" in (reference / "table.md").read_text()


@pytest.mark.slow
def test_two_jobs_write_the_same_trials_file(reference: Path, tmp_path: Path) -> None:
    scenario = fixed_estimate()
    result = run_campaign(scenario, trials=TRIALS, jobs=2, out=tmp_path / "jobs2", alternatives=ALTERNATIVES)
    assert result.summary["complete"]
    assert (tmp_path / "jobs2" / "trials.jsonl").read_bytes() == (reference / "trials.jsonl").read_bytes()
    assert not (tmp_path / "jobs2" / ".predictions.pkl").exists()


@pytest.mark.slow
def test_a_killed_campaign_keeps_its_trials_and_resume_completes_it(reference: Path, tmp_path: Path) -> None:
    """SIGKILL the command once a trial is on disk; --resume then gives the reference file."""
    out = tmp_path / "killed"
    yaml = tmp_path / "book_transfer_fixed.yaml"
    text = registry.scenario_path("book_transfer").read_text()
    yaml.write_text(re.sub(r"\n  scene_variation:.*(\n    .*)*", "", text))  # the block, all its lines
    assert fixed_estimate().trials == load(yaml).trials
    cmd = [sys.executable, "-m", "executive.cli.main", "campaign", str(yaml), "--trials", str(TRIALS)]
    cmd += ["--alternatives", ",".join(ALTERNATIVES), "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    trials = out / "trials.jsonl"
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if trials.exists() and trials.read_bytes().count(b"\n") >= 1:
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the campaign ended before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    kept = read_trials(trials)
    assert 1 <= len(kept) < TRIALS * len(ALTERNATIVES)
    reference_lines = (reference / "trials.jsonl").read_bytes().splitlines(keepends=True)
    # what was kept is exactly the reference's first lines (a cut-short last line is dropped)
    assert [json.dumps(r, sort_keys=True) for r in kept] == [
        json.dumps(json.loads(line), sort_keys=True) for line in reference_lines[: len(kept)]
    ]
    # a line cut short by the kill is repaired on resume
    with trials.open("ab") as f:
        f.write(b'{"trial": 1, "altern')
    args = ["campaign", str(yaml), "--trials", str(TRIALS), "--alternatives", ",".join(ALTERNATIVES)]
    code = main([*args, "--out", str(out), "--resume"])
    assert code == 0
    assert trials.read_bytes() == (reference / "trials.jsonl").read_bytes()


def test_bad_campaign_input_exits_2_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["campaign", "book_transfer", "--resume"]) == 2
    assert "--resume needs --out" in capsys.readouterr().err
    assert main(["campaign", "book_transfer", "--alternatives", "left,juggle", "--out", str(tmp_path)]) == 2
    assert "no alternative juggle" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["campaign", "book_transfer", "--trials", "0"])
    assert exc.value.code == 2
    assert "must be at least 1" in capsys.readouterr().err
    # a folder that already holds trials is not overwritten
    (tmp_path / "trials.jsonl").write_text('{"trial": 0, "alternative": "left"}\n')
    assert main(["campaign", "book_transfer", "--out", str(tmp_path)]) == 2
    assert "already holds trials" in capsys.readouterr().err
    # resume with another seed than the campaign was made with
    (tmp_path / "campaign.json").write_text(json.dumps({"scenario": "book_transfer", "seed": 0}))
    assert main(["campaign", "book_transfer", "--out", str(tmp_path), "--resume", "--seed", "5"]) == 2
    assert "was made with" in capsys.readouterr().err
    # a corrupt line in the middle is named, not skipped
    (tmp_path / "trials.jsonl").write_text('{"trial": 0, "alternative": "left"}\nnot json\n{"trial": 1}\n')
    with pytest.raises(Exception, match=r"trials.jsonl:2: not valid JSON"):
        read_trials(tmp_path / "trials.jsonl")


@pytest.mark.slow
def test_ray_backend_gives_the_same_trials(reference: Path, tmp_path: Path) -> None:
    """One trial as a Ray task (a local Ray instance) equals the local process's line."""
    ray = pytest.importorskip("ray")
    scenario = fixed_estimate()
    try:
        result = run_campaign(
            scenario, trials=1, jobs=1, out=tmp_path / "ray", alternatives=["left_to_right"], backend="ray"
        )
    finally:
        ray.shutdown()
    assert result.summary["backend"] == "ray"
    expected = [r for r in _records(reference) if r["trial"] == 0 and r["alternative"] == "left_to_right"]
    assert _records(tmp_path / "ray") == expected


@pytest.mark.slow
def test_a_varied_scene_is_planned_and_predicted_per_trial(reference: Path, tmp_path: Path) -> None:
    """With trials.scene_variation each trial plans on its own shifted scene."""
    from executive.schema.types import SceneVariation
    from executive.validation.campaign import predict, trial_scene

    base = load("book_transfer")
    variation = SceneVariation(object_position=0.02, object_yaw_rad=np.radians(5), obstacle_position=0.02)
    scenario = dataclasses.replace(base, trials=TrialsConfig(count=1, seed=7, scene_variation=variation))
    result = run_campaign(scenario, out=tmp_path / "varied", alternatives=["left_to_right"])
    (record,) = result.records
    estimate, perturbation, shifts = trial_scene(scenario, 7)
    assert record["scene"] == shifts
    # the shift is a draw of the variation, applied to the scene the robot plans on
    dx, dy, dyaw = shifts["object_offsets"]["book"]
    assert 0 < np.hypot(dx, dy) < 5 * 0.02 and abs(dyaw) < 5 * np.radians(5)
    book = next(b for b in estimate.scene.objects if b.name == "book")
    nominal = next(b for b in base.scene.objects if b.name == "book")
    assert book.position[:2] == pytest.approx((nominal.position[0] + dx, nominal.position[1] + dy))
    # the truth's error is drawn after the variation, from the same trial generator
    assert record["truth"]["object_offsets"]["book"] == pytest.approx(
        list(perturbation.object_offsets["book"]), abs=1e-8
    )
    # the prediction is the plan's on the varied scene, not the fixed estimate's
    varied = predict(estimate, 0, "left_to_right")
    assert record["predicted"] == pytest.approx({**varied.risk, "value": varied.value})
    fixed = next(r for r in _records(reference) if r["alternative"] == "left_to_right")["predicted"]
    assert record["predicted"] != fixed


def test_perception_scale_draws_each_trials_sigmas_and_its_truth_from_them() -> None:
    """trials.scene_variation.perception_scale: a log-uniform factor per trial on the pose sigmas.

    Reference: the truth's errors divided by the trial's own sigmas are standard normal
    (checked over 4000 trials: mean 0, variance 1 within 5 standard errors), and the factor's
    logarithm is uniform on [log low, log high] (its mean and variance in closed form).
    """
    from executive.schema.types import SceneVariation
    from executive.validation.campaign import trial_scene

    base = load("book_transfer")
    low, high = 0.5, 2.0
    variation = SceneVariation(object_position=0.01, perception_scale=(low, high))
    scenario = dataclasses.replace(base, trials=TrialsConfig(count=1, seed=0, scene_variation=variation))
    n = 4000
    factors, z_obj, z_obs, z_yaw = [], [], [], []
    for seed in range(n):
        estimate, truth, shifts = trial_scene(scenario, seed)
        assert shifts is not None
        f = shifts["perception_scale"]
        factors.append(f)
        u = estimate.uncertainty
        assert u.object_position == pytest.approx(base.uncertainty.object_position * f, rel=1e-8)
        assert u.obstacle_position == pytest.approx(base.uncertainty.obstacle_position * f, rel=1e-8)
        assert u.object_yaw_rad == pytest.approx(base.uncertainty.object_yaw_rad * f, rel=1e-8)
        assert (u.com, u.object_mass, u.friction) == (
            base.uncertainty.com,
            base.uncertainty.object_mass,
            base.uncertainty.friction,
        )
        dx, dy, dyaw = truth.object_offsets["book"]
        z_obj += [dx / u.object_position, dy / u.object_position]
        z_yaw.append(dyaw / u.object_yaw_rad)
        z_obs += [v / u.obstacle_position for v in truth.obstacle_offsets["book_stack"]]
    log_f = np.log(factors)
    assert log_f.min() >= np.log(low) and log_f.max() <= np.log(high)
    width = np.log(high) - np.log(low)
    assert log_f.mean() == pytest.approx((np.log(low) + np.log(high)) / 2, abs=5 * width / np.sqrt(12 * n))
    assert log_f.var() == pytest.approx(width**2 / 12, rel=0.1)
    for z in (np.array(z_obj), np.array(z_obs), np.array(z_yaw)):
        assert abs(z.mean()) < 5 / np.sqrt(len(z))
        assert z.var() == pytest.approx(1.0, abs=5 * np.sqrt(2 / len(z)))
    # without the range no factor is drawn: the generator's stream is the one of before
    plain = dataclasses.replace(
        scenario, trials=TrialsConfig(count=1, seed=0, scene_variation=SceneVariation(object_position=0.01))
    )
    estimate, _, shifts = trial_scene(plain, 3)
    assert shifts is not None and "perception_scale" not in shifts
    assert estimate.uncertainty == base.uncertainty
