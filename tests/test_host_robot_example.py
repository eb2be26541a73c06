"""examples/host_robot.py, the host controller integrators copy, runs its robot to the task's end and
stops safely on Ctrl-C.

The first run goes in this process in lockstep (``--fast``) with the risk threshold lowered so the
approval callback is asked: the book must lie at its target in the robot's own simulation (the
physics, not the executive's summary), the callback's approval logged. The second runs the example
as a program at the wall clock's pace and sends it SIGINT once it says the robot has moved for a
second: it must end with exit 1, the log's last lines ``stop`` then ``end``, the summary
``aborted``, and the robot holding (its joints still). Each waits for the example's own lines,
never for a time.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
import yaml

from executive.schema.catalog import scenario_path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "host_robot.py"
TARGET = (0.52, -0.26)  # book_transfer's mission: the book to [0.52, -0.26] on the table


def _example(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    """The example as a module (in sys.modules while the test runs: its dataclass needs it)."""
    spec = importlib.util.spec_from_file_location("host_robot", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "host_robot", module)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_the_host_drives_its_robot_to_the_goal_and_the_callback_approves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    example = _example(monkeypatch)
    args = ["--fast", "--rollouts", "0", "--threshold", "0.05", "--out", str(tmp_path / "run")]
    result = example.run(example.build_parser().parse_args(args))
    example.report(result)
    out = capsys.readouterr().out
    world = result.robot.world
    (x, y, z), _ = world.object_pose("book")
    table = world.scenario.scene.table
    print(out, f"book at ({x:.3f}, {y:.3f}, {z:.3f})")
    assert np.hypot(x - TARGET[0], y - TARGET[1]) < 0.02  # placed, within the placement check's 2 cm
    assert abs(z - (table.height + 0.025)) < 0.005  # resting on the table (the book is 5 cm thick)
    pelvis = world.data.xpos[world.ids.base_body]
    assert pelvis[2] > 0.8  # standing
    approvals = [e for e in result.executive.log.entries if e["kind"] == "approval"]
    assert [(a["decision"], a["by"]) for a in approvals] == [("approve", "callback:host-robot")]
    assert "[host] approval asked" in out and "outcome success" in out
    assert result.executive.outcome == "success"


@pytest.mark.slow
def test_ctrl_c_halts_the_tree_and_the_robot_holds(tmp_path: Path) -> None:
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    # book_transfer with only the alternative it chooses: the stop is the subject, not the choice
    doc = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["mission"][0]["transfer"]["alternatives"] = ["left_to_right"]
    scenario = tmp_path / "handover_only.yaml"
    scenario.write_text(yaml.safe_dump(doc, sort_keys=False))
    command = [sys.executable, "-u", str(EXAMPLE), str(scenario), "--rollouts", "0", "--out", str(out)]
    with subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, text=True) as run:
        assert run.stdout is not None
        lines = []
        moving = 0
        for line in run.stdout:  # the example's own lines: an event each, no time assumed
            lines.append(line)
            moving += line.startswith("[robot ") and "[executing]" in line  # at each robot second
            if moving == 3:  # at least a second into the motion
                run.send_signal(signal.SIGINT)  # Ctrl-C while the robot moves
                break
        lines += run.stdout.readlines()
        code = run.wait(timeout=600)  # a hang guard only
    text = "".join(lines)
    print(text)
    assert code == 1, text
    assert "stopped by SIGINT; held 0.5 s: joints moved at most" in text
    drift_mrad = float(text.split("joints moved at most ")[1].split(" mrad")[0])
    assert drift_mrad < 5.0  # holding: each joint within 5 mrad of where it stopped
    log = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    assert [e["kind"] for e in log[-2:]] == ["stop", "end"]
    assert log[-2]["reason"] == "interrupted by the operator (Ctrl-C): tree halted, robot holding"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "aborted"
