"""Approval channels (executive/decision/approval.py); the prompt is driven through a real pseudo-terminal."""

from __future__ import annotations

import io
import json
import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from approval_driver import REQUEST  # tests/ is on sys.path (pytest's default prepend import mode)

from executive.decision.approval import (
    ApprovalDecision,
    CallbackChannel,
    HostChannel,
    PendingApproval,
    PolicyChannel,
    TerminalChannel,
    make_channel,
)
from executive.decision.audit import now_iso
from executive.schema.catalog import scenario_path
from tests.conftest import HANG_S

DRIVER = Path(__file__).with_name("approval_driver.py")
PROMPT = TerminalChannel.PROMPT


def _decision(kind: str = "approve", alt: str | None = "left", by: str = "test") -> ApprovalDecision:
    return ApprovalDecision(kind, alt, by=by, at=now_iso())  # type: ignore[arg-type]


def test_policies() -> None:
    auto, deny = PendingApproval(REQUEST, None), PendingApproval(REQUEST, None)
    PolicyChannel("auto").submit(auto)
    PolicyChannel("deny").submit(deny)
    assert auto.decision is not None and auto.decision.decision == "approve"
    assert auto.decision.alternative == "left_to_right" and auto.decision.by == "policy:auto"
    assert deny.decision is not None and deny.decision.decision == "deny"  # a deny, not an abort
    assert deny.decision.by == "policy:deny"
    with pytest.raises(ValueError, match="auto or deny"):
        PolicyChannel("maybe")


def test_callback_now_or_later_and_the_first_answer_wins() -> None:
    now = PendingApproval(REQUEST, None)
    CallbackChannel(lambda r: _decision(alt="left")).submit(now)
    assert now.decision is not None and now.decision.alternative == "left"
    later = PendingApproval(REQUEST, None)
    channel = CallbackChannel(lambda r: None, name="cell")
    channel.submit(later)
    assert later.decision is None and channel.submitted == [later]
    assert later.answer(_decision("replan", None, by=channel.name))
    assert not later.answer(_decision("abort", None))  # too late: the first answer stands
    assert later.decision is not None and later.decision.decision == "replan"
    assert later.decision.by == "callback:cell"


def test_host_channel_keeps_requests_until_answered() -> None:
    host = HostChannel("cell-controller")
    first, second, third = (PendingApproval(REQUEST, None) for _ in range(3))
    for pending in (first, second, third):
        host.submit(pending)
    assert host.pending == [first, second, third]
    host.approve(first)  # the recommended one
    host.approve(second, alternative="left", by="host:alice")
    assert host.pending == [third]
    host.abort(third)
    assert host.pending == []
    assert first.decision is not None and first.decision.alternative == "left_to_right"
    assert first.decision.by == "host:cell-controller"
    assert second.decision is not None and second.decision.alternative == "left"
    assert second.decision.by == "host:alice"
    assert third.decision is not None and third.decision.decision == "abort"


def test_request_and_decision_are_json_records() -> None:
    record = json.loads(json.dumps(REQUEST.as_dict()))
    assert [a["name"] for a in record["alternatives"]] == ["left_to_right", "left", "right"]
    assert record["recommended"] == "left_to_right" and record["threshold"] == 0.3
    assert record["alternatives"][2] == {
        "name": "right",
        "feasible": False,
        "risk": {},
        "value": None,
        "reason": "right hand cannot reach",
        "physics": "",
    }
    pending = PendingApproval(REQUEST, None)
    PolicyChannel("auto").submit(pending)
    assert pending.decision is not None
    decision = json.loads(json.dumps(pending.decision.as_dict()))
    assert decision["decision"] == "approve" and decision["at"].endswith("+00:00")


def test_only_a_feasible_alternative_named_in_the_request_can_be_approved() -> None:
    pending = PendingApproval(REQUEST, None)
    with pytest.raises(ValueError, match="feasible: left_to_right, left"):
        pending.answer(_decision(alt="right"))
    with pytest.raises(ValueError):
        pending.answer(_decision(alt="jump"))
    with pytest.raises(ValueError):
        pending.answer(_decision(alt=None))
    assert pending.decision is None


def test_timeout_resolves_to_abort_and_cancel_too() -> None:
    clock = [100.0]
    pending = PendingApproval(REQUEST, 60.0, clock=lambda: clock[0])
    clock[0] = 159.9
    assert pending.decision is None and pending.remaining_s == pytest.approx(0.1)
    clock[0] = 160.0
    assert pending.decision is not None and pending.decision.decision == "abort"
    assert pending.decision.by == "timeout" and pending.decision.alternative is None
    assert not pending.answer(_decision(alt="left"))  # too late: the timeout stands
    assert pending.decision.by == "timeout"
    other = PendingApproval(REQUEST, None)
    other.cancel(by="halt")
    assert other.decision is not None and other.decision.decision == "abort" and other.decision.by == "halt"
    answered = PendingApproval(REQUEST, None)
    answered.answer(_decision(alt="left"))
    answered.cancel(by="halt")  # a cancel after the answer changes nothing
    assert answered.decision is not None and answered.decision.decision == "approve"


def test_make_channel() -> None:
    assert make_channel("prompt", interactive=False, fallback="auto").name == "policy:auto"
    assert make_channel("prompt", interactive=False).name == "policy:deny"
    assert isinstance(make_channel("prompt", interactive=True), TerminalChannel)
    assert make_channel("deny").name == "policy:deny"
    assert make_channel("auto").name == "policy:auto"
    with pytest.raises(ValueError, match="prompt, auto, deny"):
        make_channel("ask")
    with pytest.raises(ValueError, match="auto, deny"):
        make_channel("prompt", interactive=False, fallback="prompt")


def _on_streams(text: str, timeout_s: float | None = None) -> tuple[PendingApproval, str]:
    """The prompt on in-memory streams (no terminal): typed ``text``, then end of input."""
    out = io.StringIO()
    channel = TerminalChannel(io.StringIO(text), out, operator="tester")
    pending = PendingApproval(REQUEST, timeout_s)
    channel.submit(pending)
    for thread in channel.threads:
        thread.join(timeout=10)
    return pending, out.getvalue()


def test_prompt_on_plain_streams_and_end_of_input_aborts() -> None:
    pending, out = _on_streams("what\n2\n")
    assert "not understood: 'what'" in out
    assert pending.decision is not None and pending.decision.alternative == "left"
    pending, out = _on_streams("")
    assert pending.decision is not None and pending.decision.decision == "abort"
    assert pending.decision.by == "operator:tester" and pending.decision.note == "end of input"


# --- the terminal prompt, typed into through a pseudo-terminal -----------------------------------


class Terminal:
    """A child process on a pseudo-terminal: read what it shows, type into it."""

    def __init__(self, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.master, slave = pty.openpty()
        self.proc = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
        os.close(slave)
        self.screen = ""

    def expect(self, text: str, timeout: float = 120.0, count: int = 1) -> str:
        """Read until ``text`` has appeared ``count`` times in all; the whole screen so far."""
        deadline = time.monotonic() + timeout
        while self.screen.count(text) < count:
            left = deadline - time.monotonic()
            assert left > 0, f"{text!r} never appeared; screen:\n{self.screen[-3000:]}"
            ready, _, _ = select.select([self.master], [], [], min(left, 0.5))
            if ready:
                try:
                    chunk = os.read(self.master, 65536)
                except OSError:  # the child closed the terminal
                    chunk = b""
                if not chunk:
                    assert self.screen.count(text) >= count, (
                        f"{text!r} never appeared; screen:\n{self.screen[-3000:]}"
                    )
                self.screen += chunk.decode(errors="replace")
        return self.screen

    def type(self, line: str, end: str = "\n") -> None:
        os.write(self.master, (line + end).encode())

    def close(self, timeout: float = 120.0) -> int:
        """Wait for the child to exit (killed after ``timeout``), read the rest of the screen."""
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        try:
            while select.select([self.master], [], [], 0.5)[0]:
                chunk = os.read(self.master, 65536)
                if not chunk:
                    break
                self.screen += chunk.decode(errors="replace")
        except OSError:  # EIO: every slave end is closed and the screen is read
            pass
        finally:
            os.close(self.master)
        return code


def _decisions(screen: str) -> list[dict[str, object]]:
    """The driver's ``DECISION {json}`` lines (the driver's main thread may print one right
    after a prompt the channel's thread is about to close, so not only at a line start)."""
    return [json.loads(found) for found in re.findall(r"DECISION (\{.*?\})\r?$", screen, re.MULTILINE)]


def _drive(answers: list[str], *args: str) -> tuple[dict[str, object], str]:
    """Start the driver on a pseudo-terminal, wait for the prompt, type each answer after
    the (next) prompt appears, and read the decision the driver prints."""
    term = Terminal([sys.executable, str(DRIVER), *args])
    try:
        term.expect(PROMPT, timeout=30)
        for i, answer in enumerate(answers):
            if i:  # a re-ask: the previous answer was refused
                term.expect(PROMPT, timeout=10, count=i + 1)
            term.type(answer)
        term.expect("DECISION ", timeout=30)
    finally:
        code = term.close(timeout=10)  # the driver exits after printing; close reads the rest
    assert code == 0, term.screen
    return _decisions(term.screen)[0], term.screen


def test_prompt_shows_every_alternative_and_enter_approves_the_recommended() -> None:
    decision, screen = _drive([""])
    assert "APPROVAL NEEDED for task0: transfer book to (0.52, -0.26)" in screen
    assert "above the threshold 0.3" in screen and "threshold 0.3" in screen
    rows = {m[2]: m for m in (re.match(r"([* ]) +(\d) (\S+) +(.*)", ln) for ln in screen.splitlines()) if m}
    assert {number: row[3] for number, row in rows.items()} == {
        "1": "left_to_right",
        "2": "left",
        "3": "right",
    }
    assert [row[1] for row in rows.values()] == ["*", " ", " "]  # only the recommended row is marked
    assert rows["2"][4].split() == ["0.0248", "0.0015", "0.0014", "0.0000", "0.0277", "0.5200"]
    assert rows["3"][4] == "infeasible: right hand cannot reach"
    assert decision["decision"] == "approve" and decision["alternative"] == "left_to_right"
    assert decision["by"] == "operator:tester"
    assert str(decision["at"]).endswith("+00:00")


def test_prompt_reasks_after_nonsense_and_takes_a_name() -> None:
    decision, screen = _drive(["maybe later", "left"])
    assert "not understood: 'maybe later'; valid:" in screen
    assert screen.count(PROMPT) == 2
    assert decision["decision"] == "approve" and decision["alternative"] == "left"
    assert decision["by"] == "operator:tester"


def test_prompt_refuses_an_infeasible_choice_then_takes_a_row_number() -> None:
    decision, screen = _drive(["right", "2"])
    assert "right is infeasible and cannot be approved" in screen
    assert decision["decision"] == "approve" and decision["alternative"] == "left"


def test_prompt_replan() -> None:
    decision, _ = _drive(["r"])
    assert decision["decision"] == "replan" and decision["alternative"] is None
    assert decision["by"] == "operator:tester"


def test_prompt_abort() -> None:
    decision, _ = _drive(["q"])
    assert decision["decision"] == "abort" and decision["by"] == "operator:tester"


def test_prompt_end_of_input_aborts() -> None:
    decision, _ = _drive(["\x04"])  # Ctrl-D at the start of a line
    assert decision["decision"] == "abort" and decision["note"] == "end of input"


def test_prompt_times_out_to_abort_when_nobody_types() -> None:
    decision, screen = _drive([], "--timeout", "0.5")  # _drive's own limits are hang guards only
    assert decision["decision"] == "abort" and decision["by"] == "timeout"
    assert "abort in 0.5 s without an answer" in screen


def test_a_timed_out_prompt_stops_and_leaves_the_next_line_to_the_next_prompt() -> None:
    term = Terminal([sys.executable, str(DRIVER), "--timeout", "0.5", "--twice"])
    try:
        term.expect(PROMPT, timeout=30)
        term.expect("abort by timeout", timeout=10)  # the first prompt gives up by itself
        term.expect(PROMPT, timeout=10, count=2)  # the second request's prompt
        term.type("2")
        term.expect("DECISION ", timeout=10, count=2)
    finally:
        code = term.close(timeout=10)
    assert code == 0, term.screen
    first, second = _decisions(term.screen)
    assert first["decision"] == "abort" and first["by"] == "timeout"
    assert second["decision"] == "approve" and second["alternative"] == "left"
    assert second["by"] == "operator:tester"


@pytest.mark.slow
def test_executive_run_prompts_on_a_terminal_and_the_operator_aborts(tmp_path: Path) -> None:
    """`executive run --approve prompt` on a real pseudo-terminal: the operator types, the run aborts."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["risk"]["threshold"] = 0.001
    risky = tmp_path / "risky.yaml"
    risky.write_text(yaml.safe_dump(doc, sort_keys=False))
    script = Path(sys.executable).parent / "executive"
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "executive.cli.main"]
    out = tmp_path / "run"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "TERM": "xterm"}
    term = Terminal(
        [*cmd, "run", str(risky), "--approve", "prompt", "--exact", "--rollouts", "0", "--out", str(out)],
        env=env,
    )
    try:
        term.expect("abort [q] > ", timeout=300)
        assert "left_to_right" in term.screen and "APPROVAL NEEDED" in term.screen
        term.type("what")
        term.expect("not understood", timeout=30)
        term.type("q")
        term.expect("run folder", timeout=HANG_S)
    finally:
        code = term.close()
    assert code == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted"
    approval = summary["tasks"][0]["approval"]
    assert approval["decision"] == "abort" and approval["by"].startswith("operator:")
