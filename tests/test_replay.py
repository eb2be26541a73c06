"""The run folder's per-tick record and ``executive replay``: a real book_transfer run (exact truth,
guards on), its record read back, the world rebuilt, a video rendered and decoded.

References: the run's own final state (``summary.json``'s object position, the live truth
world's MuJoCo state rendered directly), the real run's tree and the guard's CoM margin
recomputed from the rebuilt world's contacts.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

from executive.cli.main import main
from executive.decision.physics_check import with_rollouts
from executive.execution.tick_record import FORMAT, load_record, preorder
from executive.monitoring.live_risk import contact_support_margin
from executive.report.replay import make_renderer, rebuild_world, step_spans, video_frames
from executive.report.tree_view import mission_tree
from executive.runtime.mission import Executive
from executive.scenario import load

imageio_ffmpeg = pytest.importorskip(
    "imageio_ffmpeg", reason="imageio-ffmpeg is not installed (pip install '.[video]' to run this test)"
)

SIZE = (320, 240)


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """book_transfer with truth = estimate, guards on, no rollouts; the run folder and the final render."""
    folder = tmp_path_factory.mktemp("replay") / "run"
    scenario = with_rollouts(load("book_transfer"), 0)
    executive = Executive(scenario, approval="auto", truth="exact", out=folder, guard=True)
    snapshots: list[list[tuple[str, str]]] = []  # every node's status after every tick, in full

    def snapshot(ex: Executive) -> None:
        snapshots.append([(n.name, n.status.value) for n in preorder(ex.root)])

    executive.tick_listeners.append(snapshot)
    summary = executive.run(time_limit_s=120)
    assert summary["outcome"] == "success", summary
    assert executive.truth is not None
    renderer = make_renderer(executive.truth, *SIZE)
    from executive.report.render import overview_camera

    renderer.update_scene(executive.truth.data, camera=overview_camera(executive.truth))
    final = np.asarray(renderer.render(), dtype=np.uint8).copy()
    renderer.close()
    return {
        "folder": folder,
        "summary": json.loads((folder / "summary.json").read_text()),
        "final_rgb": final,
        "final_qpos": executive.truth.data.qpos.copy(),
        "ticks": executive.ticks,
        "snapshots": snapshots,
        "guard_min": scenario.risk.guard.min_distance,
    }


def test_the_record_has_every_tick_and_the_final_state(run: dict[str, Any]) -> None:
    record = load_record(run["folder"])
    assert record.header["format"] == FORMAT and record.header["truth"] == "exact"
    assert record.complete
    # one frame before the first tick and one after each tick, none missing
    assert len(record) == run["ticks"] + 1
    assert np.array_equal(record.ticks, np.arange(run["ticks"] + 1))
    # every tick steps the physics one period but the last (the mission is over: nothing to step)
    assert np.allclose(np.diff(record.times[:-1]), record.header["control_dt"])
    assert record.times[-1] == record.times[-2]
    assert abs(record.duration - run["summary"]["sim_time_s"]) < 1e-9
    # the final frame is the run's final state (float32: well under a micrometre here)
    (placement,) = run["summary"]["placement"]
    pos, quat = record.object_pose(len(record) - 1, placement["object"])
    assert np.linalg.norm(pos - np.array(placement["position"])) < 1e-3
    assert np.max(np.abs(record.qpos[-1] - run["final_qpos"])) < 1e-5
    assert abs(np.linalg.norm(quat) - 1.0) < 1e-6


def test_the_recorded_statuses_are_every_node_at_every_tick(run: dict[str, Any]) -> None:
    """The record keeps only changes, looking at the running path; replayed, they give every node's status."""
    record = load_record(run["folder"])
    for frame, full in enumerate(run["snapshots"], start=1):
        replayed = [(node.name, status) for node, status in record.statuses_at(frame)]
        assert replayed == full, frame


def test_the_recorded_tree_is_the_one_executive_tree_shows(run: dict[str, Any]) -> None:
    record = load_record(run["folder"])
    executing = next(p for p in record.phases if p["phase"] == "executing")
    nodes = record.tree_at(executing["frame"])
    assert nodes[0].name == "book_transfer" and nodes[1].kind == "RiskSelector"
    shown = mission_tree(load("book_transfer")).root.children[0]
    for subtree in shown.children:  # every alternative: the run ranked them, the shapes are the same
        names = [n.name for n in subtree.iterate()]
        top = next(i for i, n in enumerate(nodes) if n.name == subtree.name and n.parent == 1)
        below = [n.name for i, n in enumerate(nodes) if _under(nodes, i, top)]
        assert sorted(below) == sorted(names)
    statuses = dict((n.name, s) for n, s in record.statuses_at(len(record) - 1) if n.parent == 1)
    assert statuses[executing["alternative"]] == "SUCCESS"


def _under(nodes: Any, i: int, top: int) -> bool:
    while i >= 0:
        if i == top:
            return True
        i = nodes[i].parent
    return False


def test_guard_values_are_the_guards(run: dict[str, Any]) -> None:
    """Every guarded frame has the guard's numbers; its CoM margin is a lower bound of the exact one."""
    record = load_record(run["folder"])
    world = rebuild_world(record)
    checked = np.flatnonzero(record.guard >= 0)
    # the motions are most of the execution (the frames while it plans follow the wall clock: as
    # many as the machine's speed makes them)
    executing = next(p["frame"] for p in record.phases if p["phase"] == "executing")
    assert len(checked) > 0.5 * (len(record) - executing)
    assert np.all(record.guard_ok[checked] == 1)
    assert np.all(record.clearance[checked] >= run["guard_min"] - 1e-6)
    for frame in checked[:: max(1, len(checked) // 25)].tolist():
        world.data.qpos[:] = record.qpos[frame]
        mujoco.mj_forward(world.model, world.data)
        exact = contact_support_margin(world, world.data)
        assert exact is not None
        # a certified lower bound (float32 rounding and the contacts' penetration aside)
        assert record.com_margin[frame] <= exact + 2e-3
        assert record.com_margin[frame] > 0.05
    spans = step_spans(record)
    assert [s.status for s in spans] == ["SUCCESS"] * len(spans)
    guarded = [s for s in spans if record.tree_at(s.start)[s.node.parent].kind == "RiskGuard"]
    assert len(guarded) >= 10 and all(np.isfinite(s.clearance) and s.com_margin > 0.05 for s in guarded)


def test_replay_prints_the_phases(run: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(run["folder"])]) == 0
    out = capsys.readouterr().out
    chosen = run["summary"]["tasks"][0]["chosen"]
    assert "task0 planning" in out and f"task0 executing {chosen}" in out
    assert "ended     SUCCESS" in out and "kB/s" in out
    assert "right.place" in out or "left.place" in out


def test_the_video_ends_in_the_run_final_state(
    run: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    video = run["folder"] / "replay.mp4"
    w, h = SIZE
    argv = [
        "replay",
        str(run["folder"]),
        "--video",
        str(video),
        "--fps",
        "4",
        "--width",
        str(w),
        "--height",
        str(h),
    ]
    assert main(argv) == 0
    record = load_record(run["folder"])
    frames = video_frames(record, 4.0)
    assert frames[-1] == len(record) - 1  # the last video frame shows the last tick
    (placement,) = run["summary"]["placement"]
    pos, _ = record.object_pose(int(frames[-1]), placement["object"])
    assert np.linalg.norm(pos - np.array(placement["position"])) < 1e-3
    reader = imageio_ffmpeg.read_frames(str(video))
    meta = next(reader)
    assert tuple(meta["size"]) == SIZE
    decoded = [np.frombuffer(f, dtype=np.uint8).reshape(h, w, 3) for f in reader]
    assert len(decoded) == len(frames)
    last = decoded[-1].astype(float)
    assert last.std() > 10  # not blank
    diff = np.abs(last - run["final_rgb"]).max(axis=2)
    # H.264 at quality 8 moves a pixel by about a grey level; hardly one in a thousand by 40 or more
    assert diff.mean() < 3.0 and (diff > 40).mean() < 1e-3, (diff.mean(), (diff > 40).mean())
    # while the first frame (the book at its start) differs from the last in the book's pixels
    moved = np.abs(decoded[0].astype(float) - last).max(axis=2)
    assert (moved > 40).mean() > 5e-3


def test_missing_or_corrupt_records_are_exit_2(
    run: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", str(tmp_path / "nowhere")]) == 2
    assert "no such run folder" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["replay", str(empty)]) == 2
    assert "header.json: missing" in capsys.readouterr().err
    # a copy of the record, then broken in turn
    copy = tmp_path / "copy" / "record"
    copy.mkdir(parents=True)
    for name in ("header.json", "frames.bin", "events.jsonl"):
        (copy / name).write_bytes((run["folder"] / "record" / name).read_bytes())
    with open(copy / "frames.bin", "ab") as f:  # a cut last frame (a kill mid-write): dropped
        f.write(b"\x01\x02\x03")
    assert len(load_record(copy.parent)) == run["ticks"] + 1
    lines = (copy / "events.jsonl").read_text().splitlines()
    (copy / "events.jsonl").write_text("\n".join([lines[0], "{not json", *lines[1:]]) + "\n")
    assert main(["replay", str(copy.parent)]) == 2
    err = capsys.readouterr().err
    assert "events.jsonl: line 2" in err and "Traceback" not in err
    (copy / "events.jsonl").write_text(
        "\n".join([*lines[:3], '{"k":"status","frame":3,"s":[[0,7]]}', *lines[3:]])
    )
    assert main(["replay", str(copy.parent)]) == 2
    assert (
        "events.jsonl: line 4: status: s: expected [node index, status code 0-3]" in capsys.readouterr().err
    )
    header = json.loads((run["folder"] / "record" / "header.json").read_text())
    (copy / "header.json").write_text(json.dumps({**header, "nq": "47"}))
    assert main(["replay", str(copy.parent)]) == 2
    assert "header.json: nq: unexpected value '47'" in capsys.readouterr().err
    (copy / "header.json").write_text("{")
    assert main(["replay", str(copy.parent)]) == 2
    assert "header.json: not a readable record header" in capsys.readouterr().err
    assert main(["replay", str(run["folder"]), "--video", str(tmp_path / "v.webp")]) == 2
    assert "unknown video type" in capsys.readouterr().err
    with pytest.MonkeyPatch.context() as patch:  # as if imageio-ffmpeg were not installed
        patch.setitem(sys.modules, "imageio_ffmpeg", None)
        assert main(["replay", str(run["folder"]), "--video", str(tmp_path / "v.mp4")]) == 2
    err = capsys.readouterr().err
    assert 'pip install ".[video]"' in err and ".gif" in err and not (tmp_path / "v.mp4").exists()
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["replay", str(run["folder"]), "--video", str(blocker / "v.mp4")]) == 2
    assert "--video" in capsys.readouterr().err
    assert os.listdir(tmp_path / "copy") == ["record"]


def test_a_sampled_truth_is_rebuilt_with_its_seed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A run on a sampled truth replays in that truth: its obstacles and objects where the run had them."""
    scenario = with_rollouts(load("book_transfer"), 0)
    executive = Executive(scenario, approval="deny", truth=7, out=tmp_path / "run")
    try:
        assert executive.truth is not None
        truth_model = executive.truth.model
        record = load_record(tmp_path / "run")  # the header and the state before the first tick
        assert record.header["truth"] == 7 and record.header["world"] == "truth"
        world = rebuild_world(record)
        assert np.array_equal(world.model.body_pos, truth_model.body_pos)
        assert np.array_equal(world.model.body_mass, truth_model.body_mass)
        assert not np.array_equal(world.model.body_pos, executive.estimate.model.body_pos)  # it was perturbed
        assert np.max(np.abs(record.qpos[0] - world.data.qpos)) < 1e-6  # float32 of the same state
    finally:
        executive.stop("test over")
    assert main(["replay", str(tmp_path / "run")]) == 0  # a stopped run: its summary says how it ended
    assert "the run was stopped, outcome aborted (test over)" in capsys.readouterr().out


def test_a_host_robot_run_records_what_the_host_reports(tmp_path: Path) -> None:
    """With a host's robot the frames are its measured state in the estimate's layout; no truth to rebuild."""
    from executive.execution.robot_interface import HostRobot, SimulatedJointIO
    from executive.world.model import build

    scenario = with_rollouts(load("book_transfer"), 0)
    hardware = SimulatedJointIO(build(scenario), control_dt=0.02)
    robot = HostRobot(build(scenario), hardware, control_dt=0.02)
    executive = Executive(scenario, approval="deny", robot=robot, out=tmp_path / "run")
    seen = []
    try:
        for _ in range(20):
            robot.sync()
            executive.tick()
            seen.append(robot.data.qpos.copy())
            hardware.servo.advance()
    finally:
        executive.stop("test over")
    record = load_record(tmp_path / "run")
    assert record.header["world"] == "estimate" and record.header["truth"] is None
    assert len(record) == 21 and np.max(np.abs(record.qpos[1:] - np.array(seen))) < 1e-5
    world = rebuild_world(record)
    assert world.model.nq == record.header["nq"]
