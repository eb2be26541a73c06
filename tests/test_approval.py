"""Approval channels (executive/approval.py); the prompt is driven through a real pseudo-terminal."""

from __future__ import annotations

import json
import os
import pty
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from executive.approval import (
    AlternativeRisk,
    ApprovalDecision,
    ApprovalRequest,
    CallbackChannel,
    HostChannel,
    PendingApproval,
    PolicyChannel,
    TerminalChannel,
    make_channel,
)
from executive.audit import now_iso
from executive.registry import scenario_path

REQUEST = ApprovalRequest(
    task="task0: transfer book to (0.52, -0.26)",
    alternatives=(
        AlternativeRisk(
            "left_to_right", True, {"collision": 0.0, "combined": 0.0031, "expected_loss": 0.41}, 0.41
        ),
        AlternativeRisk("left", True, {"collision": 0.0248, "combined": 0.0277, "expected_loss": 0.52}, 0.52),
        AlternativeRisk("right", False, {}, None, reason="right hand cannot reach"),
    ),
    recommended="left_to_right",
    threshold=0.3,
    ordering="expected_loss",
    reason="lowest expected_loss 0.41 (left_to_right) is above the threshold 0.3",
)


def _decision(kind: str = "approve", alt: str | None = "left", by: str = "test") -> ApprovalDecision:
    return ApprovalDecision(kind, alt, by=by, at=now_iso())  # type: ignore[arg-type]


def test_policies() -> None:
    auto, deny = PendingApproval(REQUEST, None), PendingApproval(REQUEST, None)
    PolicyChannel("auto").submit(auto)
    PolicyChannel("deny").submit(deny)
    assert auto.decision is not None and auto.decision.decision == "approve"
    assert auto.decision.alternative == "left_to_right" and auto.decision.by == "policy:auto"
    assert (
        deny.decision is not None and deny.decision.decision == "abort" and deny.decision.by == "policy:deny"
    )
    with pytest.raises(ValueError, match="auto or deny"):
        PolicyChannel("maybe")


def test_callback_now_or_later_and_the_first_answer_wins() -> None:
    now = PendingApproval(REQUEST, None)
    CallbackChannel(lambda r: _decision(alt="left")).submit(now)
    assert now.decision is not None and now.decision.alternative == "left"
    later = PendingApproval(REQUEST, None)
    CallbackChannel(lambda r: None).submit(later)
    assert later.decision is None
    assert later.answer(_decision("replan", None))
    assert not later.answer(_decision("abort", None))  # too late: the first answer stands
    assert later.decision is not None and later.decision.decision == "replan"


def test_host_channel_keeps_requests_until_answered() -> None:
    host = HostChannel("cell-controller")
    pending = PendingApproval(REQUEST, None)
    host.submit(pending)
    assert host.pending == [pending]
    host.approve(pending)
    assert host.pending == []
    assert pending.decision is not None and pending.decision.by == "host:cell-controller"


def test_only_a_feasible_alternative_named_in_the_request_can_be_approved() -> None:
    pending = PendingApproval(REQUEST, None)
    with pytest.raises(ValueError, match="feasible: left_to_right, left"):
        pending.answer(_decision(alt="right"))
    with pytest.raises(ValueError):
        pending.answer(_decision(alt="jump"))
    assert pending.decision is None


def test_timeout_resolves_to_abort_and_cancel_too() -> None:
    clock = [100.0]
    pending = PendingApproval(REQUEST, 60.0, clock=lambda: clock[0])
    clock[0] = 159.9
    assert pending.decision is None and pending.remaining_s == pytest.approx(0.1)
    clock[0] = 160.0
    assert pending.decision is not None and pending.decision.decision == "abort"
    assert pending.decision.by == "timeout"
    other = PendingApproval(REQUEST, None)
    other.cancel(by="halt")
    assert other.decision is not None and other.decision.by == "halt"


def test_make_channel() -> None:
    assert make_channel("prompt", interactive=False, fallback="auto").name == "policy:auto"
    assert isinstance(make_channel("prompt", interactive=True), TerminalChannel)
    assert make_channel("deny").name == "policy:deny"
    with pytest.raises(ValueError, match="prompt, auto, deny"):
        make_channel("ask")


# --- the terminal prompt, typed into through a pseudo-terminal -----------------------------------

DRIVER = f"""
import json, sys, time
sys.path.insert(0, {str(Path(__file__).parent)!r})
from test_approval import REQUEST
from executive.approval import PendingApproval, TerminalChannel
pending = PendingApproval(REQUEST, float(sys.argv[1]) if len(sys.argv) > 1 else None)
TerminalChannel(operator="tester").submit(pending)
while pending.decision is None:
    time.sleep(0.01)
print("DECISION " + json.dumps(pending.decision.as_dict()), flush=True)
"""


class Terminal:
    """A child process on a pseudo-terminal: read what it shows, type into it."""

    def __init__(self, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
        os.close(slave)
        self.screen = ""

    def expect(self, text: str, timeout: float = 120.0) -> str:
        deadline = time.monotonic() + timeout
        while text not in self.screen:
            left = deadline - time.monotonic()
            assert left > 0, f"{text!r} never appeared; screen:\n{self.screen[-3000:]}"
            ready, _, _ = select.select([self.master], [], [], min(left, 0.5))
            if ready:
                try:
                    chunk = os.read(self.master, 65536)
                except OSError:  # the child closed the terminal
                    chunk = b""
                if not chunk:
                    assert text in self.screen, f"{text!r} never appeared; screen:\n{self.screen[-3000:]}"
                self.screen += chunk.decode(errors="replace")
        return self.screen

    def type(self, line: str) -> None:
        os.write(self.master, (line + "\n").encode())

    def close(self) -> int:
        try:
            code = self.proc.wait(timeout=120)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
            os.close(self.master)
        return code


def _drive(answers: list[str], timeout: str | None = None) -> tuple[dict[str, object], str]:
    term = Terminal([sys.executable, "-c", DRIVER, *([timeout] if timeout else [])])
    try:
        term.expect("abort [q] > ", timeout=30)
        for answer in answers:
            mark = len(term.screen)
            term.type(answer)
            term.expect("\n", timeout=10)
            del mark
        screen = term.expect("DECISION ", timeout=30)
        screen = term.expect("}", timeout=10)
    finally:
        term.close()
    line = screen[screen.index("DECISION ") :].splitlines()[0]
    return json.loads(line.removeprefix("DECISION ")), screen


def test_prompt_shows_every_alternative_and_enter_approves_the_recommended() -> None:
    decision, screen = _drive([""])
    assert "APPROVAL NEEDED" in screen and "above the threshold 0.3" in screen
    for name in ("left_to_right", "left", "right"):
        assert name in screen
    row = next(line for line in screen.splitlines() if " left_to_right " in line and "0.0031" in line)
    assert row.split()[:3] == ["*", "1", "left_to_right"]  # the recommended row is marked
    assert "infeasible: right hand cannot reach" in screen
    assert decision["decision"] == "approve" and decision["alternative"] == "left_to_right"
    assert decision["by"] == "operator:tester"


def test_prompt_reasks_after_nonsense_and_takes_a_name() -> None:
    decision, screen = _drive(["maybe later", "left"])
    assert "not understood: 'maybe later'" in screen
    assert decision["decision"] == "approve" and decision["alternative"] == "left"


def test_prompt_refuses_an_infeasible_choice_then_takes_a_row_number() -> None:
    decision, screen = _drive(["3", "2"])
    assert "right is infeasible and cannot be approved" in screen
    assert decision["alternative"] == "left"


def test_prompt_replan_and_abort() -> None:
    assert _drive(["r"])[0]["decision"] == "replan"
    assert _drive(["q"])[0]["decision"] == "abort"


def test_prompt_times_out_to_abort_when_nobody_types() -> None:
    decision, _ = _drive([], timeout="0.5")
    assert decision["decision"] == "abort" and decision["by"] == "timeout"


@pytest.mark.slow
def test_executive_run_prompts_on_a_terminal_and_the_operator_aborts(tmp_path: Path) -> None:
    """`executive run --approve prompt` on a real pseudo-terminal: the operator types, the run aborts."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["risk"]["threshold"] = 0.001
    risky = tmp_path / "risky.yaml"
    risky.write_text(yaml.safe_dump(doc, sort_keys=False))
    script = Path(sys.executable).parent / "executive"
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "executive.cli"]
    out = tmp_path / "run"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "TERM": "xterm"}
    term = Terminal([*cmd, "run", str(risky), "--approve", "prompt", "--exact", "--out", str(out)], env=env)
    try:
        term.expect("abort [q] > ", timeout=300)
        assert "left_to_right" in term.screen and "APPROVAL NEEDED" in term.screen
        term.type("what")
        term.expect("not understood", timeout=30)
        term.type("q")
        term.expect("run folder", timeout=120)
    finally:
        code = term.close()
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted"
    approval = summary["tasks"][0]["approval"]
    assert approval["decision"] == "abort" and approval["by"].startswith("operator:")
