"""SIGTERM and SIGHUP stop ``executive`` exactly as Ctrl-C does, and ``--jobs`` is held to the machine.

A run is signalled at a moment told by an event, never by a sleep: its log's ``planning`` line
and its planning worker's rollout process (planning), its ``execute`` line (moving), its
approval prompt on a pseudo-terminal (waiting for the operator). Each time: exit code 1, the
log's last lines ``stop`` and ``end``, ``summary.json`` whole, no process of the run left, no
"leaked semaphore" warning. A campaign signalled mid-trials keeps them and resumes.

The runs are ``python -m executive.cli.main`` with this checkout first on the path (the
installed ``executive`` script may be another checkout's), each in a session of its own.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pytest
import yaml
from test_runs_robust import PROMPT, Pty, _one_run, _scenario  # tests/ is on sys.path

from executive.cli.main import main
from executive.cli.signals import Terminated, interrupts_held, stop_signals_as_interrupt
from executive.schema.catalog import scenario_path
from executive.validation.worker_limit import WORKER_BYTES, Capacity, capacity, check_jobs, max_workers
from tests.conftest import HANG_S

REPO = Path(__file__).resolve().parents[1]
CMD = [sys.executable, "-m", "executive.cli.main"]
ENV = {
    **os.environ,
    "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
    "TERM": "xterm",
    "PYTHONPATH": os.pathsep.join([str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])]),
}
LEAK = "leaked semaphore"


# --- helpers ------------------------------------------------------------------------------------


def _until(condition: Callable[[], Any], what: str, timeout: float = 120.0) -> Any:
    """Poll ``condition`` until it returns something true (returned); fail after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        assert time.monotonic() < deadline, f"{what} never happened in {timeout:.0f} s"
        time.sleep(0.02)


def _has_line(folder: Path, kind: str) -> Callable[[], bool]:
    def seen() -> bool:
        try:
            text = (folder / "decisions.jsonl").read_text()
        except OSError:
            return False
        return f'"kind": "{kind}"' in text

    return seen


def _children(pid: int) -> list[int]:
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
        return [int(c) for t in tasks for c in Path(f"/proc/{pid}/task/{t}/children").read_text().split()]
    except OSError:
        return []


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def _rollout_process(pid: int) -> int | None:
    """The planning worker's rollout process, once there is one (the worker is a spawned child
    of ``pid`` other than the resource tracker; the rollout process its spawned child)."""
    for worker in _children(pid):
        if "spawn_main" in _cmdline(worker):
            for rollout in _children(worker):
                if "spawn_main" in _cmdline(rollout):
                    return rollout
    return None


def _alive_in_group(pgid: int) -> list[str]:
    """The processes of process group ``pgid`` that still run (zombies left to init do not)."""
    alive = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            fields = Path(f"/proc/{entry}/stat").read_bytes().rsplit(b")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] != b"Z":
            alive.append(f"{entry} {_cmdline(int(entry))[:120]}")
    return alive


def _none_left(pgid: int) -> None:
    """Every process of the run has ended (within a few seconds: the resource tracker ends last)."""
    try:
        _until(lambda: not _alive_in_group(pgid), f"the end of process group {pgid}", timeout=20)
    except AssertionError:
        left = _alive_in_group(pgid)
        with pytest.raises(ProcessLookupError):
            os.killpg(pgid, signal.SIGKILL)
        raise AssertionError(f"processes left: {left}") from None


def _start(argv: Sequence[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [*CMD, *argv],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=REPO,
        start_new_session=True,  # its own process group: the workers are found, and killed on failure
    )


def _finish(proc: subprocess.Popen[str]) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    return proc.returncode, out, err


def _reap(pid: int, timeout: float = 120.0) -> int:
    """Wait for child ``pid`` to end; its exit code."""
    status: list[int] = []

    def ended() -> bool:
        done, code = os.waitpid(pid, os.WNOHANG)
        if done:
            status.append(code)
        return bool(done)

    _until(ended, f"the end of process {pid}", timeout)
    return os.waitstatus_to_exitcode(status[0])


def _stopped_by(out: Path, name: str) -> list[dict[str, Any]]:
    """The run's log ends ``stop`` (by ``name``) then ``end``, aborted; its summary is whole and says so."""
    entries = _one_run(out)
    kinds = [e["kind"] for e in entries]
    assert kinds[-2:] == ["stop", "end"], kinds
    assert name in entries[-2]["reason"] and entries[-1]["outcome"] == "aborted"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted" and name in summary["reason"]
    return entries


def _slow_planning(folder: Path) -> Path:
    """``book_transfer`` with its default rollouts on one process: planning takes seconds."""
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc.setdefault("risk", {})["rollouts"] = {"jobs": 1}
    path = folder / "slow.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


# --- a run, signalled -----------------------------------------------------------------------------


def test_sigterm_while_planning_ends_the_workers_and_leaks_nothing(tmp_path: Path) -> None:
    out = tmp_path / "run"
    proc = _start(["run", str(_slow_planning(tmp_path)), "--exact", "--approve", "deny", "--out", str(out)])
    try:
        _until(_has_line(out, "planning"), "the planning line")
        rollout = _until(lambda: _rollout_process(proc.pid), "the planning worker's rollout process")
        assert not _has_line(out, "selection")()  # still planning
        proc.send_signal(signal.SIGTERM)
    finally:
        code, stdout, stderr = _finish(proc)
    assert code == 1, stderr
    assert LEAK not in stderr and "Traceback" not in stderr, stderr
    entries = _stopped_by(out, "SIGTERM")
    assert "selection" not in [e["kind"] for e in entries]
    assert "stopped: stopped by SIGTERM" in stdout
    _none_left(proc.pid)
    assert not _cmdline(rollout)  # the rollout process of the worker it ended, too


def test_sighup_while_moving_halts_the_motion(tmp_path: Path) -> None:
    out = tmp_path / "run"
    scenario = _scenario(tmp_path, alternatives=("left",))
    proc = _start(["run", str(scenario), "--exact", "--approve", "auto", "--out", str(out)])
    try:
        _until(_has_line(out, "execute"), "the execute line")
        proc.send_signal(signal.SIGHUP)
    finally:
        code, _, stderr = _finish(proc)
    assert code == 1, stderr
    assert LEAK not in stderr and "Traceback" not in stderr, stderr
    kinds = [e["kind"] for e in _stopped_by(out, "SIGHUP")]
    assert "execute" in kinds and "outcome" not in kinds  # stopped mid-motion
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tasks"][0]["chosen"] == "left"
    _none_left(proc.pid)


@pytest.mark.parametrize("how", ["SIGTERM", "hangup"])
def test_a_stop_signal_at_the_prompt_answers_abort(tmp_path: Path, how: str) -> None:
    """SIGTERM: the request is answered abort by ``signal:SIGTERM`` before the stop line. A
    terminal hung up (its master closed: SIGHUP, and end of input for the prompt): the run ends
    as safely, though nobody sees what it prints."""
    out = tmp_path / "prompt"
    scenario = _scenario(tmp_path, alternatives=("left",))  # the signal is the subject, not the choice
    argv = [*CMD, "run", str(scenario), "--approve", "prompt", "--exact", "--out", str(out)]
    term = Pty(["/usr/bin/env", f"PYTHONPATH={ENV['PYTHONPATH']}", *argv])
    with term:
        term.expect(PROMPT, timeout=HANG_S)
        if how == "SIGTERM":
            os.kill(term.pid, signal.SIGTERM)
            code = term.close()
        else:
            os.close(term.fd)  # the terminal hangs up
            term.fd = -1
            term.code = code = _reap(term.pid)
    if how == "SIGTERM":
        assert code == 1, term.screen[-2000:]
        assert "Traceback" not in term.screen and LEAK not in term.screen
        entries = _stopped_by(out, "SIGTERM")
        kinds = [e["kind"] for e in entries]
        approval = next(e for e in entries if e["kind"] == "approval")
        assert approval["decision"] == "abort" and approval["by"] == "signal:SIGTERM"
        assert kinds.index("approval") < kinds.index("stop") and "execute" not in kinds
        summary = json.loads((out / "summary.json").read_text())
        assert summary["tasks"][0]["approval"]["by"] == "signal:SIGTERM"
    else:
        assert code == 1
        entries = _one_run(out)
        assert entries[-1]["kind"] == "end" and entries[-1]["outcome"] == "aborted"
        assert "execute" not in [e["kind"] for e in entries]
        assert json.loads((out / "summary.json").read_text())["outcome"] == "aborted"
    _none_left(term.pid)


# --- a campaign, signalled, resumed ---------------------------------------------------------------


def test_sigterm_mid_campaign_keeps_the_trials_and_resume_completes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "campaign"
    trials = out / "trials.jsonl"
    args = [
        "campaign",
        str(scenario),
        "--trials",
        "3",
        "--jobs",
        str(min(2, max_workers())),
        "--out",
        str(out),
    ]
    proc = _start(args)
    try:
        _until(lambda: trials.exists() and trials.read_text().endswith("\n"), "the first trial's record")
        proc.send_signal(signal.SIGTERM)
    finally:
        code, _, stderr = _finish(proc)
    assert code == 1, stderr
    assert "interrupted" in stderr and "--resume" in stderr
    assert LEAK not in stderr and "Traceback" not in stderr, stderr
    kept = [json.loads(line) for line in trials.read_text().splitlines()]
    assert 1 <= len(kept) < 3
    _none_left(proc.pid)
    assert main([*args, "--resume"]) == 0
    capsys.readouterr()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] and summary["new_trials"] == 3 - len(kept)
    records = [json.loads(line) for line in trials.read_text().splitlines()]
    assert sorted(r["trial"] for r in records) == [0, 1, 2]


def test_sigterm_mid_fidelity_suite_keeps_its_trials_and_resume_completes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    scenario = _scenario(tmp_path, alternatives=("left",))
    out = tmp_path / "suite"
    args = ["fidelity", str(scenario), "--variants", "2", "--trials", "2", "--out", str(out)]

    def a_trial() -> bool:
        return any(f.read_text().endswith("\n") for f in out.glob("variant-*/trials.jsonl"))

    proc = _start([*args, "--jobs", str(min(2, max_workers()))])
    try:
        _until(a_trial, "the first trial's record")
        proc.send_signal(signal.SIGTERM)
    finally:
        code, _, stderr = _finish(proc)
    assert code == 1, stderr
    assert "interrupted" in stderr and "--resume" in stderr
    assert LEAK not in stderr and "Traceback" not in stderr, stderr
    _none_left(proc.pid)
    kept = {f.parent.name: f.read_text() for f in out.glob("variant-*/trials.jsonl")}
    assert main([*args, "--resume"]) == 0
    capsys.readouterr()
    assert json.loads((out / "summary.json").read_text())["complete"]
    for variant, text in kept.items():  # the trials kept are kept, and counted once
        now = (out / variant / "trials.jsonl").read_text()
        assert now.startswith(text) and len({json.loads(line)["trial"] for line in now.splitlines()}) == 2


# --- the handlers ---------------------------------------------------------------------------------


def test_importing_the_library_installs_no_signal_handler() -> None:
    code = (
        "import signal, executive, executive.runtime.mission, executive.cli.main, "
        "executive.validation.campaign, executive.validation.fidelity\n"
        "print(signal.getsignal(signal.SIGTERM).name, signal.getsignal(signal.SIGHUP).name)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["SIG_DFL", "SIG_DFL"]


@pytest.fixture
def default_stop_signals() -> Any:
    """SIGTERM and SIGHUP at their default action for the test, as they were after it."""
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    for s in before:
        signal.signal(s, signal.SIG_DFL)
    yield
    for s, handler in before.items():
        signal.signal(s, handler)


@pytest.mark.usefixtures("default_stop_signals")
def test_stop_signals_raise_terminated_inside_and_ignored_ones_stay_ignored() -> None:
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as under nohup
    with stop_signals_as_interrupt():
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        with pytest.raises(Terminated) as stopped:
            os.kill(os.getpid(), signal.SIGTERM)  # delivered to this thread before kill returns
            raise AssertionError("the handler did not raise")
    assert isinstance(stopped.value, KeyboardInterrupt) and stopped.value.name == "SIGTERM"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


@pytest.mark.usefixtures("default_stop_signals")
def test_a_stop_signal_while_the_run_is_built_is_held_then_raised() -> None:
    with stop_signals_as_interrupt(), interrupts_held() as held:
        os.kill(os.getpid(), signal.SIGHUP)
        os.kill(os.getpid(), signal.SIGTERM)  # a second one: the first is what stops the run
    (first,) = held
    assert isinstance(first, Terminated) and first.name == "SIGHUP"


# --- --jobs and the machine -----------------------------------------------------------------------


def test_the_worker_limit_is_the_cores_or_the_memory_whichever_holds_fewer(tmp_path: Path) -> None:
    proc, root = tmp_path / "proc", tmp_path / "cgroup"
    (proc / "self").mkdir(parents=True)
    (root / "job").mkdir(parents=True)
    (proc / "meminfo").write_text("MemTotal:       24683584 kB\nMemAvailable:    1048576 kB\n")
    (proc / "self" / "cgroup").write_text("0::/job\n")
    machine = capacity(proc, root, cores=8)
    assert machine == Capacity(8, 2**30) and machine.workers == 2**30 // WORKER_BYTES == 3
    (root / "job" / "cpu.max").write_text("150000 100000\n")  # a quota of 1.5 cores
    (root / "job" / "memory.max").write_text(f"{2**31}\n")
    (root / "job" / "memory.current").write_text(f"{2**31 - 700 * 2**20}\n")  # 700 MB left
    machine = capacity(proc, root, cores=8)
    assert machine == Capacity(2, 700 * 2**20) and machine.workers == 2
    check_jobs(2, machine=machine)
    with pytest.raises(Exception, match=r"--jobs 3: this machine holds at most 2 worker process\(es\)"):
        check_jobs(3, machine=machine)
    assert Capacity(4, 0).workers == 1 and Capacity(64, None).workers == 64


@pytest.mark.parametrize("command", ["campaign", "fidelity"])
def test_more_jobs_than_the_machine_holds_is_refused_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    limit = max_workers()
    if limit >= 1024:
        pytest.skip(f"this machine holds {limit} workers: --jobs cannot ask for more")
    for jobs in (limit + 1, 1024):
        out = tmp_path / f"{command}{jobs}"
        assert main([command, "book_transfer", "--jobs", str(jobs), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"--jobs {jobs}: this machine holds at most {limit} worker process(es)" in err
        assert f"use --jobs {limit} or fewer" in err and "Traceback" not in err
        assert not out.exists()
