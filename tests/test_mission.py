"""The risk-gated executive end to end: `executive run`, the Executive API, the audit log.

Outcomes are read from the run folder the command leaves (decisions.jsonl,
summary.json) and, in process, from the truth world's MuJoCo data.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from executive.decision.approval import ApprovalDecision, ApprovalRequest, CallbackChannel
from executive.decision.audit import now_iso
from executive.decision.physics_check import with_rollouts
from executive.runtime.mission import Executive
from executive.scenario import load
from executive.schema.catalog import scenario_path

SCRIPT = Path(sys.executable).parent / "executive"
CMD = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main"]
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}


def _risky_scenario(tmp_path: Path, threshold: float = 0.001) -> Path:
    """book_transfer with a threshold below every alternative's risk: approval is always needed.
    No rollouts (the dry runs still run): the gate is the subject, not the risk's numbers."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["name"] = "book_transfer_risky"
    doc["risk"]["threshold"] = threshold
    doc["risk"]["rollouts"] = {"count": 0}
    doc["robot"] = "humanoid"
    path = tmp_path / "risky.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _lines(folder: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in (folder / "decisions.jsonl").read_text().splitlines()]


def _check_gate(entries: list[dict[str, Any]], threshold: float) -> None:
    """No alternative above the threshold executes without an earlier approval line naming it."""
    approved: set[tuple[str, str]] = set()
    for e in entries:
        if e["kind"] == "approval" and e["decision"] == "approve":
            approved.add((e["task"], e["alternative"]))
        if e["kind"] == "execute" and e["value"] > threshold:
            assert (e["task"], e["alternative"]) in approved, e


@pytest.mark.slow
def test_run_chooses_the_handover_and_places_the_book(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = subprocess.run(
        [*CMD, "run", "book_transfer", "--approve", "auto", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        env=ENV,
    )
    print(proc.stdout[-3000:], proc.stderr[-2000:])
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenario"] == "book_transfer" and summary["outcome"] == "success"
    (task,) = summary["tasks"]
    assert task["chosen"] == "left_to_right" and task["outcome"] == "success" and task["failure"] is None
    assert task["approval"] is None  # below the threshold: no approval needed
    assert set(task["risk"]) >= {"collision", "fall", "drop", "combined", "expected_loss"}
    assert summary["placement"][0]["error_m"] < 0.02
    entries = _lines(out)
    kinds = [e["kind"] for e in entries]
    assert kinds[0] == "run" and kinds[-1] == "end"
    assert kinds.count("plan") == 3 and "selection" in kinds and "execute" in kinds and "placed" in kinds
    assert [e["seq"] for e in entries] == list(range(len(entries)))
    _check_gate(entries, summary["threshold"])
    # The detectors' near-miss record rides on the outcome line: nothing touched, the closest
    # forbidden pair within the detector's 0.2 m horizon (a hand and the scene).
    (outcome,) = [e for e in entries if e["kind"] == "outcome"]
    call = outcome["closest_call"]
    assert 0.0 < call["distance"] < 0.2 and len(call["bodies"]) == 2 and "mm" in call["summary"]
    assert (out / "task0" / "left_to_right_com.png").is_file()
    assert (out / "task0" / "left_to_right_distance.png").is_file()
    assert "left_to_right" in proc.stdout and "success" in proc.stdout


@pytest.mark.slow
def test_deny_above_threshold_aborts_without_moving_the_arms(tmp_path: Path) -> None:
    scenario = load(str(_risky_scenario(tmp_path)))
    executive = Executive(scenario, approval="deny", truth="exact", out=tmp_path / "run")
    assert executive.truth is not None
    data, model = executive.truth.data, executive.truth.model
    arm = [model.jnt_qposadr[j] for joints in executive.truth.ids.arm_joints.values() for j in joints]
    start = data.qpos[arm].copy()
    summary = executive.run()
    moved = float(np.max(np.abs(data.qpos[arm] - start)))
    print(f"deny: {summary['outcome']}; arm joints moved at most {np.degrees(moved):.3f} deg")
    assert summary["outcome"] == "aborted"
    (task,) = summary["tasks"]
    assert task["approval"]["decision"] == "deny" and task["approval"]["by"] == "policy:deny"
    assert task["outcome"] == "aborted" and task["failure"]["mode"] == "denied"
    assert task["chosen"] is None
    assert moved < np.radians(0.5)
    kinds = [e["kind"] for e in _lines(tmp_path / "run")]
    assert "approval_request" in kinds and "approval" in kinds and "execute" not in kinds


@pytest.mark.slow
def test_cli_deny_exits_1_and_auto_runs_with_an_approval_record(tmp_path: Path) -> None:
    risky = _risky_scenario(tmp_path)
    deny = subprocess.run(
        [
            *CMD,
            "run",
            str(risky),
            "--approve",
            "deny",
            "--exact",
            "--rollouts",
            "0",
            "--out",
            str(tmp_path / "deny"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=ENV,
    )
    assert deny.returncode == 1, deny.stderr
    assert json.loads((tmp_path / "deny" / "summary.json").read_text())["outcome"] == "aborted"

    auto = subprocess.run(
        [
            *CMD,
            "run",
            str(risky),
            "--approve",
            "auto",
            "--exact",
            "--rollouts",
            "0",
            "--out",
            str(tmp_path / "auto"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
        env=ENV,
    )
    print(auto.stdout[-2000:])
    assert auto.returncode == 0, auto.stderr
    summary = json.loads((tmp_path / "auto" / "summary.json").read_text())
    (task,) = summary["tasks"]
    assert task["approval"]["decision"] == "approve" and task["approval"]["by"] == "policy:auto"
    assert task["approval"]["alternative"] == task["chosen"] == "left_to_right"
    entries = _lines(tmp_path / "auto")
    _check_gate(entries, summary["threshold"])
    kinds = [e["kind"] for e in entries]
    assert kinds.index("approval") < kinds.index("execute")


@pytest.mark.slow
def test_a_host_may_approve_another_alternative_and_the_log_records_it(tmp_path: Path) -> None:
    """A callback approves `left` (not the recommended one): it runs, with the approval on record."""
    scenario = load(str(_risky_scenario(tmp_path)))

    def pick_left(request: ApprovalRequest) -> ApprovalDecision:
        assert request.recommended == "left_to_right"
        assert {a.name for a in request.alternatives} == {"left", "right", "left_to_right"}
        return ApprovalDecision("approve", "left", by="callback:test", at=now_iso())

    executive = Executive(scenario, approval=CallbackChannel(pick_left), truth="exact", out=tmp_path / "r")
    summary = executive.run()
    assert summary["outcome"] == "success"
    assert summary["tasks"][0]["chosen"] == "left"
    _check_gate(_lines(tmp_path / "r"), scenario.risk.threshold)


def test_the_gate_refuses_to_execute_above_threshold_without_approval(tmp_path: Path) -> None:
    """The invariant is enforced in the selector itself, not only by the channels."""
    from executive.errors import ExecutiveError

    scenario = load(str(_risky_scenario(tmp_path)))
    scenario = dataclasses.replace(
        scenario, mission=(dataclasses.replace(scenario.mission[0], alternatives=("left",)),)
    )
    executive = Executive(scenario, approval="deny", truth="exact", background=False)
    selector = executive.selectors[0]
    executive.tick()  # plans (in the tick, background=False), escalates, the deny policy answers
    assert selector.ranking and selector.ranking[0].name == "left"
    with pytest.raises(ExecutiveError, match="above the threshold without approval"):
        selector._start("left")
    executive.stop("test over")


@pytest.mark.slow
def test_a_killed_run_leaves_only_complete_json_lines(tmp_path: Path) -> None:
    out = tmp_path / "killed"
    proc = subprocess.Popen(
        [*CMD, "run", "book_transfer", "--approve", "auto", "--exact", "--rollouts", "0", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=ENV,
    )
    log = out / "decisions.jsonl"
    deadline = time.monotonic() + 300
    try:
        while time.monotonic() < deadline:
            if log.exists() and '"kind": "execute"' in log.read_text():
                break
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.05)
        time.sleep(0.5)  # mid-way through the motion
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = log.read_text()
    assert text.endswith("\n")
    entries = [json.loads(line) for line in text.splitlines()]  # every line parses
    kinds = [e["kind"] for e in entries]
    print(f"killed after {len(entries)} lines: {kinds}")
    assert "execute" in kinds and "end" not in kinds
    assert not (out / "summary.json").exists()


@pytest.mark.slow
def test_the_worker_process_plans_and_the_ticks_only_swap_its_results_in(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The planning worker process plans, assesses and checks in physics (this process plans
    nothing); the ticks that follow build one subtree each from its plans and swap them in; the
    chosen alternative's guards have their planned knots from the worker: the ticks compute none
    while it executes."""
    import executive.decision.planning_job as planning_job
    import executive.tasks.base as kinds

    planned_here: list[int] = []
    built_at: list[int] = []
    real_assess, real_build = planning_job.assess_task, kinds.build_subtree

    def assess_spy(*args: Any, **kwargs: Any) -> Any:
        planned_here.append(1)
        return real_assess(*args, **kwargs)

    def build_spy(plan: Any, **kwargs: Any) -> Any:
        built_at.append(executive.ticks)
        return real_build(plan, **kwargs)

    monkeypatch.setattr(planning_job, "assess_task", assess_spy)
    monkeypatch.setattr(kinds, "build_subtree", build_spy)  # TaskKind.subtree's default
    # no rollouts: the worker still plans, assesses and dry-runs every alternative in physics
    executive = Executive(with_rollouts(load("book_transfer"), 0), approval="auto", truth="exact")
    monitor = executive.monitor
    assert monitor is not None and executive.planning is not None
    selector = executive.selectors[0]
    while not executive.done and selector.phase != "executing":
        executive.tick()
    assert not planned_here
    assert len(built_at) == len(selector.ranking) == len(set(built_at))  # one subtree per tick
    assert [child.name for child in selector.children] == [a.name for a in selector.ranking]
    assert monitor.knots_adopted > 0 and monitor.knots_computed == 0
    for _ in range(250):  # 5 s of the chosen alternative, its guards checking every tick
        executive.tick()
    assert selector.phase == "executing" and selector.chosen == selector.ranking[0].name
    assert monitor.knots_computed == 0
    executive.stop("test over")


_FREEZE_PROBE = """
import gc, time
import executive.cli.main, executive.runtime.mission as mission
ex = mission.Executive("book_transfer", approval="auto", truth="exact")
tracked = len(gc.get_objects())
t0 = time.perf_counter(); gc.collect(); before = time.perf_counter() - t0
frozen = mission.freeze_startup_heap()
again = mission.freeze_startup_heap()
t0 = time.perf_counter(); gc.collect(); after = time.perf_counter() - t0
print(tracked, frozen, again, len(gc.get_objects()), before, after)
"""


def test_freeze_startup_heap_takes_the_libraries_and_the_executive_out_of_full_collections() -> None:
    # In a fresh interpreter: freezing is for the whole process (the test process keeps its gc).
    proc = subprocess.run(
        [sys.executable, "-c", _FREEZE_PROBE], capture_output=True, text=True, env=ENV, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    tracked, frozen, again, left = (int(v) for v in proc.stdout.split()[:4])
    before, after = (float(v) for v in proc.stdout.split()[4:])
    print(
        f"{tracked} objects tracked, {frozen} frozen, {left} left; "
        f"full collection {before * 1e3:.1f} -> {after * 1e3:.2f} ms"
    )
    assert tracked > 50_000  # numpy, MuJoCo, scipy, mink, coal, py_trees and the executive
    assert frozen >= 0.95 * tracked and again == frozen  # once per process
    assert left < 0.01 * tracked
    assert after < 0.1 * before  # a full collection walks what is left only
