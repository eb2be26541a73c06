"""Runs and campaigns as people and machines break them: the approval prompt typed into on a
real pseudo-terminal, two runs on one folder, kill -9 at random moments, a campaign resumed
over a duplicated record.

Every run here is the bundled ``book_transfer`` made cheap (no rollouts, one physics worker)
and risky (a threshold of 0.001, so the gate always asks): a few seconds each.
"""

from __future__ import annotations

import json
import os
import pty
import random
import re
import select
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
import yaml

from executive.cli.main import main
from executive.decision.approval import TerminalChannel
from executive.decision.audit import AuditLog, RunFolderError
from executive.schema.catalog import scenario_path
from tests.conftest import HANG_S

SCRIPT = Path(sys.executable).parent / "executive"
CMD = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main"]
ENV = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "TERM": "xterm"}
PROMPT = TerminalChannel.PROMPT
ERASE_LINE = "\r\x1b[2K"
COUNTDOWN = re.compile(r"\x1b7\x1b\[1A\r\x1b\[2K(.*?)\x1b8")  # the line above the prompt, redrawn


def _scenario(
    folder: Path, alternatives: Sequence[str] = ("left", "right"), timeout_s: float = 60, name: str = "cheap"
) -> Path:
    """``book_transfer`` with no rollouts, one worker, a threshold every alternative is above."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["risk"]["threshold"] = 0.001
    doc["risk"]["rollouts"] = {"count": 0, "jobs": 1}
    doc["approval"]["timeout_s"] = timeout_s
    doc["mission"][0]["transfer"]["alternatives"] = list(alternatives)
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _lines(folder: Path) -> list[dict[str, Any]]:
    """Every line of the run's decisions.jsonl, parsed (a line that does not parse fails the test)."""
    text = (folder / "decisions.jsonl").read_text()
    assert text == "" or text.endswith("\n"), f"a cut last line in {folder}"
    return [json.loads(line) for line in text.splitlines()]


def _one_run(folder: Path) -> list[dict[str, Any]]:
    """The log is one run's: one run id, seq 0..n-1 once; the summary (if any) is whole and the same run's."""
    entries = _lines(folder)
    assert [e["seq"] for e in entries] == list(range(len(entries)))
    assert len({e["run_id"] for e in entries}) <= 1
    if (folder / "summary.json").exists():
        summary = json.loads((folder / "summary.json").read_text())
        assert entries and summary["run_id"] == entries[0]["run_id"]
    return entries


# --- the prompt on a pseudo-terminal ------------------------------------------------------------


class Pty:
    """``executive run`` on a pseudo-terminal that is its controlling terminal (so Ctrl-C is SIGINT)."""

    def __init__(self, argv: list[str]) -> None:
        pid, fd = pty.fork()
        if pid == 0:  # the child: the pty is its stdin, stdout, stderr and controlling terminal
            try:
                # Ctrl-C as at a terminal, even when the tests run in the background (a shell
                # starts background jobs with SIGINT ignored, and an exec keeps that).
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.execve(argv[0], argv, ENV)
            finally:
                os._exit(127)
        self.pid, self.fd, self.screen = pid, fd, ""
        self.code: int | None = None

    def _read(self, wait_s: float) -> None:
        if select.select([self.fd], [], [], wait_s)[0]:
            try:
                chunk = os.read(self.fd, 65536)
            except OSError:  # EIO: the child has closed the terminal
                chunk = b""
            self.screen += chunk.decode(errors="replace")
            if not chunk:
                time.sleep(wait_s)

    def expect(self, text: str, timeout: float = 60.0, count: int = 1) -> str:
        """Read until ``text`` has appeared ``count`` times; the screen since its last appearance."""
        deadline = time.monotonic() + timeout
        while self.screen.count(text) < count:
            assert time.monotonic() < deadline, f"{text!r} never appeared; screen:\n{self.screen[-3000:]}"
            self._read(0.2)
        return self.screen[self.screen.rindex(text) + len(text) :]

    def type(self, text: str) -> None:
        os.write(self.fd, text.encode())

    def kill(self) -> None:
        """Kill the child and its physics worker (a failed test must not leave them running)."""
        if self.code is None:
            try:
                os.killpg(self.pid, signal.SIGKILL)  # pty.fork made it a session (and group) leader
            except ProcessLookupError:
                pass
            self.close(timeout=10)

    def close(self, timeout: float = 60.0) -> int:
        """Read the rest while the child runs; its exit code (killed after ``timeout``)."""
        if self.fd < 0:  # closed already
            assert self.code is not None
            return self.code
        deadline = time.monotonic() + timeout
        while self.code is None:
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.code = os.waitstatus_to_exitcode(status)
                break
            if time.monotonic() > deadline:
                os.killpg(self.pid, signal.SIGKILL)
            self._read(0.1)
        for _ in range(20):
            if not select.select([self.fd], [], [], 0.05)[0]:
                break
            self._read(0.05)
        os.close(self.fd)
        self.fd = -1
        assert self.code is not None
        return self.code

    def __enter__(self) -> Pty:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()


def _prompted(
    tmp_path: Path, name: str, timeout_s: float = 60, alternatives: Sequence[str] = ("left", "right")
) -> tuple[Pty, Path]:
    """A run of the cheap scenario waiting at its approval prompt."""
    out = tmp_path / name
    scenario = _scenario(tmp_path, alternatives=alternatives, timeout_s=timeout_s, name=name)
    term = Pty([*CMD, "run", str(scenario), "--approve", "prompt", "--exact", "--out", str(out)])
    try:
        term.expect(PROMPT, timeout=HANG_S)
    except BaseException:
        term.kill()
        raise
    return term, out


def _not_erased(after_prompt: str) -> None:
    """Nothing written after the prompt erased or overwrote its line (the countdown redraws the
    line above it, cursor saved and restored)."""
    rest = COUNTDOWN.sub("", after_prompt)
    assert ERASE_LINE not in rest and "\r" not in rest.replace("\r\n", ""), repr(after_prompt)


def _after_prompt(screen: str) -> str:
    return screen[screen.rindex(PROMPT) + len(PROMPT) :]


def _approvals(entries: list[dict[str, Any]]) -> list[tuple[str, str]]:
    return [(e["decision"], e["by"]) for e in entries if e["kind"] == "approval"]


def test_prompt_stays_on_screen_counts_down_and_logs_garbage_replan_deny(tmp_path: Path) -> None:
    term, out = _prompted(tmp_path, "deny")
    with term:
        assert "60 s left to answer (then abort)" in term.screen  # the countdown, above the prompt
        term.expect("58 s left to answer", timeout=10)  # redrawn live while it waits
        _not_erased(_after_prompt(term.screen))
        assert "! lowest expected_loss" in term.screen
        assert "needs approval (approval prompt: an operator must approve it)" in term.screen
        assert not re.search(r"^\* [a-z_]+ ", term.screen, re.MULTILINE)  # no row marked as if it would run
        term.type("what\n")
        term.expect("not understood: 'what'", timeout=10)
        term.type("r\n")
        term.expect(PROMPT, timeout=120, count=3)  # the re-planned request's prompt
        term.expect("59 s left to answer", timeout=10, count=2)  # its countdown, live too
        _not_erased(_after_prompt(term.screen))
        term.type("d\n")
        code = term.close()
    assert code == 1, term.screen[-2000:]
    assert "Traceback" not in term.screen
    assert "book not moved: no alternative was executed" in term.screen and " rests " not in term.screen
    entries = _one_run(out)
    operator = [by for _, by in _approvals(entries)]
    assert [d for d, _ in _approvals(entries)] == ["replan", "deny"]
    assert all(by.startswith("operator:") for by in operator)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["tasks"][0]["approval"]["decision"] == "deny"
    assert summary["tasks"][0]["failure"]["mode"] == "denied"


@pytest.mark.parametrize("answer", ["", "2"])
def test_approve_or_choose_then_ctrl_c_while_it_moves(tmp_path: Path, answer: str) -> None:
    """Enter approves the recommended, a row number chooses; Ctrl-C (twice for the row) stops the
    motion, and the summary is whole."""
    term, out = _prompted(tmp_path, f"approve{answer}")
    with term:
        request = next(e for e in _lines(out) if e["kind"] == "approval_request")["request"]
        expected = request["alternatives"][1]["name"] if answer else request["recommended"]
        term.type(answer + "\n")
        term.expect(f"executing {expected}", timeout=30)
        time.sleep(0.5)
        term.type("\x03")
        if answer:
            time.sleep(0.05)
            term.type("\x03")  # a second Ctrl-C while the run stops
        code = term.close()
    assert code == 1, term.screen[-2000:]
    assert "Traceback" not in term.screen
    entries = _one_run(out)
    kinds = [e["kind"] for e in entries]
    assert _approvals(entries)[0][0] == "approve"
    assert next(e for e in entries if e["kind"] == "execute")["alternative"] == expected
    assert kinds[-2:] == ["stop", "end"] and "Ctrl-C" in entries[-2]["reason"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and summary["tasks"][0]["chosen"] == expected


@pytest.mark.parametrize(
    ("keys", "by", "note"),
    [
        ("\x03", "operator:interrupt", "Ctrl-C"),
        ("\x04", "operator:", "end of input"),
        (None, "timeout", "no answer"),
    ],
    ids=["ctrl-c", "ctrl-d", "timeout"],
)
def test_ctrl_c_ctrl_d_and_timeout_at_the_prompt_are_logged(
    tmp_path: Path, keys: str | None, by: str, note: str
) -> None:
    # one alternative: the answer, not the choice, is the subject
    term, out = _prompted(tmp_path, "abort", timeout_s=60 if keys else 3, alternatives=("left",))
    with term:
        if keys is None:
            assert re.search(r"[23] s left to answer", term.screen)
            term.expect("1 s left to answer", timeout=5)
        else:
            term.type(keys)
        code = term.close()
    assert code == 1, term.screen[-2000:]
    assert "Traceback" not in term.screen
    entries = _one_run(out)
    ((decision, who),) = _approvals(entries)
    assert decision == "abort" and who.startswith(by)
    approval = next(e for e in entries if e["kind"] == "approval")
    assert note in approval["note"]
    kinds = [e["kind"] for e in entries]
    if keys == "\x03":  # the answer is logged before the stop line
        assert kinds.index("approval") < kinds.index("stop")
    assert kinds[-1] == "end" and "execute" not in kinds
    assert json.loads((out / "summary.json").read_text())["tasks"][0]["approval"]["by"].startswith(by)


# --- one folder, one run ------------------------------------------------------------------------


def test_a_folder_is_claimed_by_exactly_one_of_many_logs(tmp_path: Path) -> None:
    results: list[str] = []

    def claim() -> None:
        try:
            log = AuditLog(tmp_path / "run")
            log.record("run", who=threading.current_thread().name)
            log.close()
            results.append("ok")
        except RunFolderError as exc:
            results.append(str(exc))

    threads = [threading.Thread(target=claim) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert results.count("ok") == 1
    assert all(f"run folder {tmp_path / 'run'} is already used" in r for r in results if r != "ok")
    assert len(_one_run(tmp_path / "run")) == 1
    with pytest.raises(RunFolderError, match="already used by another run"):
        AuditLog(tmp_path / "run")
    AuditLog(tmp_path / "run", resume=True).close()  # a resume may append


def test_two_runs_started_on_one_folder_one_is_refused(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "shared"
    argv = [*CMD, "run", str(scenario), "--approve", "deny", "--exact", "--out", str(out)]
    procs = [
        subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
        for _ in range(2)
    ]
    results = [(p.wait(timeout=HANG_S), *p.communicate()) for p in procs]
    codes = sorted(code for code, _, _ in results)
    assert codes == [1, 2], results  # one run (denied: exit 1), one refused (exit 2)
    refused = next(err for code, _, err in results if code == 2)
    assert f"run folder {out} is already used by another run" in refused and "Traceback" not in refused
    entries = _one_run(out)
    assert [e["kind"] for e in entries].count("run") == 1 and entries[-1]["kind"] == "end"
    again = subprocess.run(argv, capture_output=True, text=True, env=ENV, timeout=HANG_S)
    assert again.returncode == 2 and "already used by another run" in again.stderr
    assert "Traceback" not in again.stderr and _lines(out) == entries  # nothing appended


# --- kill -9 ------------------------------------------------------------------------------------


def _child_run(scenario: Path, out: Path) -> int:
    """Fork a process (its own process group) that runs the scenario into ``out``; its pid."""
    pid = os.fork()
    if pid == 0:
        code = 0
        try:
            os.setpgid(0, 0)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            from executive.runtime.mission import Executive

            with Executive(str(scenario), approval="deny", truth="exact", out=out) as executive:
                executive.run()
        except BaseException:
            code = 3
        finally:
            os._exit(code)
    try:
        os.setpgid(pid, pid)  # also here: the kill may come before the child has run a line
    except OSError:
        pass
    return pid


def _complete_lines(path: Path) -> int:
    """How many whole lines ``path`` holds now (0 before it exists)."""
    try:
        return path.read_bytes().count(b"\n")
    except FileNotFoundError:
        return 0


def test_kill_9_at_random_moments_leaves_whole_lines_and_whole_summaries(tmp_path: Path) -> None:
    """SIGKILL at stages of the run chosen by what it has logged (events, not clock times): every
    line left parses, the summary (if any) is whole. A reference run gives the log's length."""
    scenario = _scenario(tmp_path, alternatives=("left",))
    pid = _child_run(scenario, tmp_path / "reference")
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0
    reference = _one_run(tmp_path / "reference")
    assert reference[-1]["kind"] == "end"
    rng = random.Random(15)
    kills = 6  # after a random line in each sixth of the log
    cuts = [1 + int((len(reference) - 1) * (i + rng.random()) / kills) for i in range(kills)]
    seen: list[int] = []
    cut_mid_run = 0
    for i, cut in enumerate(cuts):
        out = tmp_path / f"killed{i}"
        pid = _child_run(scenario, out)
        deadline = time.monotonic() + 300.0  # generous: the log's lines arrive at any machine's pace
        while _complete_lines(out / "decisions.jsonl") < cut and time.monotonic() < deadline:
            if os.waitpid(pid, os.WNOHANG) != (0, 0):
                break  # it ended before the cut: nothing to kill
            time.sleep(0.002)
        time.sleep(rng.random() * 0.002)  # the lines after planning come within milliseconds
        try:
            os.killpg(pid, signal.SIGKILL)  # the run and its physics worker
        except ProcessLookupError:  # it had finished
            pass
        try:
            os.waitpid(pid, 0)
        except ChildProcessError:  # reaped above
            pass
        entries = _one_run(out)  # every line parses, one run's, its summary whole if there
        seen.append(len(entries))
        if entries and entries[-1]["kind"] == "end":
            assert (out / "summary.json").exists()  # written before the end line
        elif entries:
            cut_mid_run += 1
    print(f"reference {len(reference)} lines; killed after lines {cuts}; lines left {seen}")
    # The kills landed at different stages of the run: while the worker plans (the cuts in the first
    # sixths) and after it (the later ones), whatever the machine's speed.
    assert len(set(seen)) >= 2 and cut_mid_run >= 2


# --- a campaign resumed over a duplicated record --------------------------------------------------


def test_campaign_resume_counts_a_duplicated_record_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "campaign"
    args = ["campaign", str(scenario), "--trials", "1", "--out", str(out)]
    assert main(args) == 0
    trials = out / "trials.jsonl"
    (line,) = trials.read_text().splitlines()
    record = json.loads(line)
    beyond = json.dumps({**record, "trial": 4}, sort_keys=True)
    trials.write_text(f"{line}\n{line}\n{beyond}\n")  # twice, and one beyond --trials 1
    capsys.readouterr()
    assert main([*args, "--resume"]) == 0
    said = capsys.readouterr().out
    assert "1 duplicated record(s)" in said and "counted once" in said
    assert "1 record(s) beyond --trials 1" in said
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] and summary["duplicates_ignored"] == 1 and summary["new_trials"] == 0
    assert summary["records_beyond_trials"] == 1
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]
    # a campaign.json cut short: exit 2 with a message, no traceback
    config = (out / "campaign.json").read_text()
    (out / "campaign.json").write_text(config[: len(config) // 2])
    assert main([*args, "--resume"]) == 2
    err = capsys.readouterr().err
    assert "campaign.json cannot be read as JSON" in err and "Traceback" not in err


def test_a_second_campaign_on_a_running_campaigns_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from executive.validation.campaign import FolderLock

    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "campaign"
    out.mkdir()
    lock = FolderLock(out)  # as a campaign running there holds it
    try:
        assert main(["campaign", str(scenario), "--trials", "1", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"--out {out}: another campaign is running in this folder" in err and "Traceback" not in err
        assert not (out / "trials.jsonl").exists() or (out / "trials.jsonl").read_text() == ""
    finally:
        lock.release()
    FolderLock(out).release()  # free again once released


def test_a_cut_suite_json_gives_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "suite"
    out.mkdir()
    (out / "suite.json").write_text('{"scenario": "book_tr')
    code = main(
        ["fidelity", str(scenario), "--variants", "1", "--trials", "1", "--out", str(out), "--resume"]
    )
    err = capsys.readouterr().err
    assert code == 2 and "suite.json cannot be read as JSON" in err and "Traceback" not in err
