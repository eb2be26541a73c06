"""The operator's console without a browser: shapes, tables, the run log, the channel, the CLI.

The page's drawing is checked against MuJoCo's own geometry (every instance's farthest
vertex at the geom's bounding radius, as MuJoCo computes it), the closest approach against
coal's distance (MuJoCo's mj_geomDistance between the same geoms at the same time), the
ghost against the plan's kinematics. The browser test is tests/test_console_browser.py.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import py_trees
import pytest
import yaml

from executive.cli.main import main
from executive.console.channel import ConsoleChannel, EitherChannel
from executive.console.geoms import drawn_geoms, shape_batches
from executive.console.live import LiveFeed, RealTimePacer
from executive.console.risk_table import physics_table, risk_table
from executive.console.run_log import read_decisions, task_decisions
from executive.console.scene import STILL
from executive.console.server import ConsoleError
from executive.decision.approval import AlternativeRisk, ApprovalRequest, PendingApproval
from executive.scenario import load
from executive.world.model import build
from tests.conftest import HANG_S

REQUEST = ApprovalRequest(
    task="task0: transfer book",
    alternatives=(
        AlternativeRisk("left_to_right", True, {"combined": 0.06}, 0.17),
        AlternativeRisk("left", True, {"combined": 0.09}, 0.33),
        AlternativeRisk("right", False, {}, None, reason="cannot reach"),
    ),
    recommended="left_to_right",
    threshold=0.001,
    ordering="expected_loss",
    reason="above the threshold",
)


def _random_pose(model: mujoco.MjModel, seed: int) -> mujoco.MjData:
    """The model at random joint angles within the joints' ranges (free joints left as keyframed)."""
    data = mujoco.MjData(model)
    if model.nkey:
        mujoco.mj_resetDataKeyframe(model, data, 0)
    rng = np.random.default_rng(seed)
    for j in range(model.njnt):
        if model.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
            lo, hi = model.jnt_range[j] if model.jnt_limited[j] else (-1.0, 1.0)
            data.qpos[model.jnt_qposadr[j]] = rng.uniform(lo, hi)
    mujoco.mj_kinematics(model, data)
    return data


def _check_shapes(model: mujoco.MjModel, data: mujoco.MjData) -> set[int]:
    """Every geom's instances, in the geom's frame, span exactly MuJoCo's bounding box of the geom
    (``geom_aabb``: centre and half sizes), oriented as MuJoCo has it; returns the geoms drawn."""
    points: dict[int, list[np.ndarray]] = {}
    for batch in shape_batches(model, range(model.ngeom)):
        positions, wxyz = batch.poses(model, data)
        for i, g in enumerate(batch.geoms):
            rot = np.zeros(9)
            mujoco.mju_quat2Mat(rot, wxyz[i])
            np.testing.assert_allclose(rot, data.geom_xmat[g], atol=1e-9)  # same orientation as MuJoCo's
            world = positions[i] + (batch.vertices * batch.scales[i]) @ rot.reshape(3, 3).T
            points.setdefault(int(g), []).append(world)
    for g, parts in points.items():
        local = (np.vstack(parts) - data.geom_xpos[g]) @ data.geom_xmat[g].reshape(3, 3)
        lo, hi = local.min(axis=0), local.max(axis=0)
        np.testing.assert_allclose((lo + hi) / 2, model.geom_aabb[g][:3], atol=1e-6, err_msg=f"geom {g}")
        np.testing.assert_allclose((hi - lo) / 2, model.geom_aabb[g][3:], atol=1e-6, err_msg=f"geom {g}")
    return set(points)


def test_the_humanoids_geoms_are_drawn_where_mujoco_has_them() -> None:
    world = build(load("book_transfer"))
    model = world.model
    data = _random_pose(model, 3)
    drawn = _check_shapes(model, data)
    planes = {g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE}
    assert drawn == set(drawn_geoms(model)) == set(range(model.ngeom)) - planes
    keys = {b.key for b in shape_batches(model, range(model.ngeom))}
    assert keys == {"box", "sphere", "cylinder"}  # capsules are a cylinder and two spheres
    capsules = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE]
    spheres = next(b for b in shape_batches(model, capsules) if b.key == "sphere")
    assert len(spheres.geoms) == 2 * len(capsules)


def test_the_g1s_meshes_are_drawn_where_mujoco_has_them(g1_scenario_yaml: str, tmp_path: Path) -> None:
    path = tmp_path / "g1.yaml"
    path.write_text(g1_scenario_yaml)
    model = build(load(str(path))).model
    drawn = _check_shapes(model, _random_pose(model, 5))
    meshes = [g for g in drawn if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    assert len(meshes) > 20
    assert not [g for g in drawn if model.geom_group[g] >= 3]  # collision-only geoms are not drawn


ROWS = [
    {
        "name": "left",
        "feasible": True,
        "value": 0.3326,
        "risk": {
            "collision": 0.0517,
            "fall": 6e-23,
            "drop": 0.0499,
            "combined": 0.099,
            "expected_loss": 0.3326,
        },
        "physics": {
            "dry_run": {"outcome": "success"},
            "rollouts": 4,
            "outcomes": {"success": 3, "collision": 1},
            "modes": {
                "collision": {"analytic": 0.0517, "fused": 0.11, "interval": [0.01, 0.29]},
                "fall": {"analytic": 0.0, "fused": 0.0, "interval": [0.0, 0.0]},
                "drop": {"analytic": 0.0499, "fused": 0.04, "interval": [0.0001, 0.2]},
            },
        },
    },
    {"name": "right", "feasible": False, "reason": "fails in simulation: drop"},
    {
        "name": "left_to_right",
        "feasible": True,
        "value": 0.1707,
        "risk": {
            "collision": 0.0145,
            "fall": 0.0,
            "drop": 0.0528,
            "combined": 0.0665,
            "expected_loss": 0.1707,
        },
    },
]


def test_the_risk_table_ranks_marks_the_threshold_and_shows_the_intervals() -> None:
    text = risk_table(ROWS, "expected_loss", 0.2)
    lines = [line for line in text.splitlines() if line.startswith("| ")]
    assert [line.split("|")[2].strip(" *") for line in lines[1:]] == ["left_to_right", "left", "right"]
    assert "0.1707 |" in lines[1] and "0.3326 ! |" in lines[2]  # only the one above 0.2 is marked
    assert "≈0" in lines[2] and "infeasible: fails in simulation: drop" in lines[3]
    assert "left_to_right** is lowest (expected_loss 0.1707), within the threshold 0.2" in text
    assert "above the threshold 0.1: it needs approval" in risk_table(ROWS, "expected_loss", 0.1)
    physics = physics_table(ROWS)
    assert "3 rollouts" not in physics and "4: 1 collision" in physics
    assert "0.052 → 0.11 [0.01, 0.29]" in physics and "[0.0001, 0.2]" in physics


def _write_log(folder: Path, lines: list[dict[str, object]], tail: str = "") -> None:
    folder.mkdir()
    text = "".join(json.dumps(line) + "\n" for line in lines) + tail
    (folder / "decisions.jsonl").write_text(text)


def test_a_run_folder_reads_back_its_last_decision_per_task(tmp_path: Path) -> None:
    first = {"kind": "plan", "task": "task0", "name": "left", "value": 0.5}
    lines = [
        {"kind": "run", "scenario": "s", "tasks": ["transfer book"]},
        {"kind": "planning", "task": "task0"},
        first,
        {"kind": "failure", "task": "task0"},
        {"kind": "planning", "task": "task0"},
        {"kind": "plan", "task": "task0", "name": "right", "value": 0.2},
        {
            "kind": "approval",
            "task": "task0",
            "decision": "approve",
            "alternative": "right",
            "by": "console:x",
        },
    ]
    _write_log(tmp_path / "run", lines, tail='{"kind": "outco')  # killed mid-line
    entries = read_decisions(tmp_path / "run")
    assert len(entries) == len(lines)
    decision = task_decisions(entries)["task0"]
    assert [r["name"] for r in decision.rows] == ["right"]  # the re-plan's, not the first
    assert "by `console:x`" in decision.note()
    _write_log(tmp_path / "bad", lines[:1], tail="not json\n" + json.dumps(first) + "\n")
    with pytest.raises(ConsoleError, match="line 2 is not JSON"):
        read_decisions(tmp_path / "bad")
    with pytest.raises(ConsoleError, match="not a run folder"):
        read_decisions(tmp_path)


def test_the_console_channel_answers_as_console_user_and_first_answer_wins() -> None:
    channel = ConsoleChannel(user="ops")
    seen: list[PendingApproval] = []
    channel.listeners.append(seen.append)
    pending = PendingApproval(REQUEST, timeout_s=None)
    channel.submit(pending)
    assert seen == [pending] and channel.waiting is pending and pending.decision is None
    with pytest.raises(ValueError, match="cannot approve 'right'"):
        channel.answer(pending, "approve", "right")
    assert channel.answer(pending, "approve", "left", note="chosen")
    assert not channel.answer(pending, "abort")
    decision = pending.decision
    assert decision is not None and (decision.decision, decision.alternative, decision.by) == (
        "approve",
        "left",
        "console:ops",
    )
    assert channel.waiting is None
    other = ConsoleChannel(user="b")
    both = EitherChannel([channel, other])
    second = PendingApproval(REQUEST, timeout_s=None)
    both.submit(second)
    assert both.name == "console+console" and channel.waiting is second and other.waiting is second
    other.answer(second, "deny")
    assert channel.waiting is None and second.decision is not None and second.decision.by == "console:b"


def test_the_feed_takes_at_most_its_rate_and_the_pacer_keeps_to_the_clock(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    data = mujoco.MjData(build(load("book_transfer")).model)
    running = py_trees.common.Status.RUNNING
    executive = SimpleNamespace(robot=SimpleNamespace(data=data, time=0.0), ticks=0, status=running)
    feed = LiveFeed(rate_hz=20.0)
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 0.5 or executive.ticks <= 1000:  # at any machine's pace
        executive.ticks += 1
        data.qpos[0] = executive.ticks
        feed(executive)
    elapsed = time.perf_counter() - t0
    assert executive.ticks > 1000 and 1 <= feed.taken <= elapsed * 20 + 1
    snap = feed.take(0.0)
    assert snap is not None and snap.qpos[0] <= executive.ticks and snap.qpos is not data.qpos
    executive.status = py_trees.common.Status.SUCCESS
    feed(executive)  # the mission's last tick is always taken
    assert feed.take(0.0).done  # type: ignore[union-attr]
    pacer = RealTimePacer()
    asked: list[float] = []  # the pacer's own sleeps (a loaded machine's oversleeping is not its)
    sleep = time.sleep
    monkeypatch.setattr(time, "sleep", lambda s: (asked.append(s), sleep(s))[1])
    start = time.perf_counter()
    for k in range(26):
        pacer.wait(k * 0.02)  # 0.5 s of robot time
    elapsed = time.perf_counter() - start
    monkeypatch.undo()
    assert elapsed >= 0.5 - 1e-3  # never ahead of the robot's time
    assert len(asked) >= 1 and sum(asked) <= 0.5 + 1e-9  # and never waits longer than it


def test_without_viser_the_console_options_exit_2_saying_what_to_install(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser raises ImportError
    assert main(["run", "book_transfer", "--console", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert 'pip install ".[console]"' in err and "Traceback" not in err
    assert not (tmp_path / "run" / "decisions.jsonl").exists()  # refused before the run started
    assert main(["console", "book_transfer"]) == 2
    assert 'pip install ".[console]"' in capsys.readouterr().err
    assert main(["replay", str(tmp_path), "--console"]) == 2  # said before the record is looked for
    assert 'pip install ".[console]"' in capsys.readouterr().err


def test_the_recorded_tree_reads_as_py_trees_prints_it() -> None:
    from executive.console.replay_view import tree_text
    from executive.execution.tick_record import TreeNode

    nodes = [TreeNode("mission", "Sequence", -1), TreeNode("task0", "RiskSelector", 0)]
    nodes += [
        TreeNode("left", "Sequence", 1),
        TreeNode("left.grasp", "Grasp", 2),
        TreeNode("right", "Sequence", 1),
    ]
    statuses = ["RUNNING", "RUNNING", "RUNNING", "SUCCESS", "INVALID"]
    assert tree_text(list(zip(nodes, statuses, strict=True))).splitlines() == [
        "mission [*]",
        "    task0 [*]",
        "        left [*]",
        "            left.grasp [✓]",
        "        right [-]",
    ]


def test_console_refuses_a_folder_without_a_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["console", str(tmp_path)]) == 2
    assert "not a run folder (no decisions.jsonl" in capsys.readouterr().err


def _other_address() -> str | None:
    """An address of this machine other than loopback (None when it has none)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("192.0.2.1", 9))  # no packet is sent: only picks the outgoing interface
            address = s.getsockname()[0]
    except OSError:
        return None
    return None if address.startswith("127.") else address


def test_the_page_is_served_on_loopback_only_and_never_shared() -> None:
    pytest.importorskip("viser", reason='the console extra is not installed: pip install ".[console]"')
    from executive.console.server import start_server, stop_server

    server = start_server(0)
    try:
        port = server.get_port()
        with socket.create_connection(("127.0.0.1", port), timeout=2):
            pass
        other = _other_address()
        if other is not None:
            with pytest.raises(OSError):
                socket.create_connection((other, port), timeout=2).close()
        assert server.request_share_url() is None
    finally:
        stop_server(server)


def test_a_ghost_follows_the_plan_and_marks_the_closest_approach_coal_found() -> None:
    pytest.importorskip("viser", reason='the console extra is not installed: pip install ".[console]"')
    from executive.console.console import Console
    from executive.decision.assessment import assess_task

    scenario = load("book_transfer")
    world = build(scenario)
    results = assess_task(world, scenario.mission[0])
    console = Console(0)
    try:
        mujoco.mj_forward(world.model, world.data)
        console.show_world(world.model, world.data, world)
        console.show_alternatives("task0", "task0", world, results, "expected_loss", 0.3)
        view = console.tasks["task0"]
        assert set(view.sliders) == {a.name for a in results if a.feasible}
        for alt in results:
            motion = view.motions[alt.name]
            closest = motion.closest
            assert alt.risk is not None and closest is not None and closest.segment is not None
            # coal's distance (the collision model) and MuJoCo's, between the same geoms at that time
            gap = float(np.linalg.norm(closest.segment[1] - closest.segment[0]))
            assert gap == pytest.approx(alt.risk.components["collision"].details["min_distance"], abs=2e-4)
            t = 0.37 * motion.duration
            view.sliders[alt.name].value = round(t / 0.05) * 0.05  # as the page's slider does
            ghost = console.ghost
            assert ghost is not None and ghost.motion is motion
            data = mujoco.MjData(world.model)
            data.qpos[:] = motion.timeline.sample(ghost.time)
            mujoco.mj_kinematics(world.model, data)
            assert ghost._ghost is not None
            for batch, handle in zip(ghost._ghost.batches, ghost._ghost.handles, strict=True):
                centres = (
                    data.geom_xpos[batch.geoms]
                    + data.geom_xmat[batch.geoms].reshape(-1, 3, 3)[:, :, 2] * batch.offsets[:, None]
                )
                np.testing.assert_allclose(handle.batched_positions, centres, atol=STILL)
    finally:
        console.close()


def test_executive_run_console_serves_the_page_while_it_plans(tmp_path: Path) -> None:
    """`executive run --console`: the address is printed first and the page answers while planning;
    with `--approve deny` the page only shows (the policy answers) and the command ends."""
    pytest.importorskip("viser", reason='the console extra is not installed: pip install ".[console]"')
    doc = yaml.safe_load(
        (Path(__file__).resolve().parents[1] / "scenarios" / "book_transfer.yaml").read_text()
    )
    doc["risk"]["threshold"] = 0.001
    risky = tmp_path / "risky.yaml"
    risky.write_text(yaml.safe_dump(doc, sort_keys=False))
    script = Path(sys.executable).parent / "executive"
    cmd = [str(script)] if script.exists() else [sys.executable, "-m", "executive.cli.main"]
    args = ["run", str(risky), "--console", "--console-port", "0", "--approve", "deny", "--rollouts", "0"]
    out = tmp_path / "run"
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.Popen(
        [*cmd, *args, "--exact", "--out", str(out)], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline()
        assert first.startswith("console   http://127.0.0.1:"), first
        url = first.split()[1]
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read(2000).lower()
        rest, _ = proc.communicate(timeout=HANG_S)
        assert "policy:deny" in rest
    finally:
        proc.kill()
    assert proc.returncode == 1  # denied: the task ends aborted
    approval = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    approval = [e for e in approval if e["kind"] == "approval"]
    assert [(e["decision"], e["by"]) for e in approval] == [("deny", "policy:deny")]
