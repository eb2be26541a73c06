"""A run killed with SIGKILL in the middle of a motion replays up to where it was killed.

``executive run book_transfer`` runs in a child process; once the record shows it executing
(and a few seconds of motion recorded) the child is killed outright. Its record must hold
every tick up to the kill, without a gap, and ``executive replay`` must summarise and render it.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from executive.cli.main import main
from executive.execution.tick_record import load_record

MOTION_FRAMES = 150  # 3 s of motion at 50 Hz before the kill


def _executing_since(folder: Path) -> int | None:
    """The frame the record's ``executing`` phase starts at, once it is there."""
    events = folder / "record" / "events.jsonl"
    if not events.exists():
        return None
    for line in events.read_text().splitlines():
        try:
            event = json.loads(line)
        except ValueError:
            continue  # a line being written
        if event.get("k") == "phase" and event.get("phase") == "executing":
            return int(event["frame"])
    return None


def _frames(folder: Path, frame_bytes: int) -> int:
    path = folder / "record" / "frames.bin"
    return path.stat().st_size // frame_bytes if path.exists() else 0


def test_a_killed_run_replays_up_to_the_kill(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "run"
    argv = ["run", "book_transfer", "--exact", "--rollouts", "0", "--approve", "auto", "--out", str(folder)]
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    child = subprocess.Popen(
        [sys.executable, "-m", "executive.cli.main", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    try:
        deadline = time.monotonic() + 120
        seen = 0
        while time.monotonic() < deadline and child.poll() is None:
            start = _executing_since(folder)
            if start is not None:
                header = json.loads((folder / "record" / "header.json").read_text())
                seen = _frames(folder, header["frame_bytes"])
                if seen >= start + MOTION_FRAMES:
                    break
            time.sleep(0.05)
        assert child.poll() is None, "the run ended before it could be killed"
        assert seen > 0, "the run did not start executing in 120 s"
        child.send_signal(signal.SIGKILL)
    finally:
        if child.poll() is None:
            child.kill()
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL
    assert not (folder / "summary.json").exists()  # it never finished

    record = load_record(folder)
    assert not record.complete
    assert len(record) >= seen  # every frame seen before the kill is there, and any written after it
    assert np.array_equal(record.ticks, np.arange(len(record)))  # no gap
    assert np.allclose(np.diff(record.times), record.header["control_dt"])
    # the robot was moving when it was killed: its hands are away from the first frame's pose
    assert np.max(np.abs(record.qpos[-1] - record.qpos[0])) > 0.01

    assert main(["replay", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "without its end" in out and "the run was killed (no summary.json)" in out
    assert "RUNNING" in out  # the motion it was killed in
    video = tmp_path / "killed.gif"
    assert (
        main(["replay", str(folder), "--video", str(video), "--fps", "1", "--width", "96", "--height", "72"])
        == 0
    )
    assert video.stat().st_size > 0
    from PIL import Image

    with Image.open(video) as gif:
        # one a second and the last (Pillow merges identical consecutive frames: the robot holding still)
        assert 2 <= gif.n_frames <= int(np.ceil(record.duration)) + 1
