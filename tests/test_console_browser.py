"""The operator's console in a real headless Chromium: approve a risky alternative from the page.

``book_transfer`` with its threshold at 0.001 (every alternative above it), rollouts off (the
dry runs still run), the console as the approval channel. The page must show every
alternative with its risk as the selector ranked it; scrubbing an alternative's time slider
in the browser must put the ghost where the plan has the robot at that time; pressing
approve must leave an ``approval`` line by ``console:<user>`` in ``decisions.jsonl`` and the
robot then moves on the page.

Needs the console extra (viser), Playwright (in the test extra) and Debian's Chromium
(``apt-get install -y chromium``); skipped otherwise. ``CONSOLE_SCREENSHOT=FILE`` keeps a
picture of the page during the approval (docs/console.png is one).
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
import yaml

from executive.console.channel import operator_name
from executive.console.risk_table import number
from executive.console.scene import STILL
from executive.decision.physics_check import with_rollouts
from executive.scenario import load

CHROMIUM = Path("/usr/bin/chromium")
ROOT = Path(__file__).resolve().parents[1]


def _requirements() -> str | None:
    """Why the test cannot run here (None: it can)."""
    try:
        import viser  # noqa: F401
    except ImportError:
        return 'the console extra is not installed: pip install ".[console]"'
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return 'Playwright is not installed: pip install ".[test]"'
    if not CHROMIUM.is_file():
        return f"no Chromium at {CHROMIUM}: apt-get install -y chromium (Debian's package)"
    return None


pytestmark = pytest.mark.skipif(_requirements() is not None, reason=str(_requirements()))


class Ticking:
    """The executive ticked in a thread, as ``executive run`` ticks it, until told to stop."""

    def __init__(self, executive: Any) -> None:
        self.executive = executive
        self.halt = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while not self.executive.done and not self.halt.is_set():
            self.executive.tick()

    def stop(self) -> None:
        self.halt.set()
        self.thread.join(timeout=30)
        if not self.executive.done:
            self.executive.stop("the test is over")


@pytest.fixture
def run(tmp_path: Path) -> Iterator[tuple[Any, Any, Path, Ticking]]:
    from executive.console.console import Console
    from executive.runtime.mission import Executive

    doc = yaml.safe_load((ROOT / "scenarios" / "book_transfer.yaml").read_text())
    doc["risk"]["threshold"] = 0.001
    risky = tmp_path / "risky.yaml"
    risky.write_text(yaml.safe_dump(doc, sort_keys=False))
    scenario = with_rollouts(load(str(risky)), 0)
    console = Console(0, title="book_transfer")
    folder = tmp_path / "run"
    executive = Executive(scenario, approval=console.channel, truth="exact", out=folder)
    console.attach(executive)
    ticking = Ticking(executive)
    try:
        yield console, executive, folder, ticking
    finally:
        ticking.stop()
        console.close()


def _approval_line(folder: Path, timeout: float) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for line in (folder / "decisions.jsonl").read_text().splitlines():
            entry = json.loads(line)
            if entry["kind"] == "approval":
                return dict(entry)
        time.sleep(0.05)
    raise AssertionError(f"no approval line in {folder / 'decisions.jsonl'} after {timeout} s")


def _slider(page: Any, name: str) -> Any:
    """The time slider of alternative ``name`` (the element its label is for)."""
    label = page.locator("label", has_text=f"{name} [s]")
    return page.locator(f"[id='{label.get_attribute('for')}']")


def _scrub(page: Any, name: str, fraction: float) -> None:
    """Click an alternative's time slider at ``fraction`` of its track, as an operator would."""
    track = _slider(page, name).locator(".mantine-Slider-track")
    track.scroll_into_view_if_needed()
    box = track.bounding_box()
    assert box is not None
    page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)


def _ghost_matches_plan(console: Any, name: str) -> float:
    """The ghost shows ``name`` at the slider's time, where the plan's kinematics have it; the time."""
    ghost = console.ghost
    motion = console.tasks["task0"].motions[name]
    with ghost.lock:  # not halfway through a redraw
        assert ghost.motion is motion
        data = mujoco.MjData(motion.world.model)
        data.qpos[:] = motion.timeline.sample(ghost.time)
        mujoco.mj_kinematics(motion.world.model, data)
        for batch, handle in zip(ghost._ghost.batches, ghost._ghost.handles, strict=True):
            axes = data.geom_xmat[batch.geoms].reshape(-1, 3, 3)[:, :, 2]
            expected = data.geom_xpos[batch.geoms] + axes * batch.offsets[:, None]
            np.testing.assert_allclose(handle.batched_positions, expected, atol=STILL)
        return float(ghost.time)


def _replay(page: Any, folder: Path) -> None:
    """``executive replay --console`` of the stopped run: its slider puts the recorded state on the page."""
    from executive.console.console import Console
    from executive.execution.tick_record import load_record

    record = load_record(folder)
    replay = Console(0, title="replay")
    try:
        replay.show_run(folder, replay=True)
        page.goto(replay.url)
        page.get_by_text("Replay (the run's per-tick record)").wait_for(timeout=30_000)
        assert f"{len(record)} ticks" in page.locator("body").inner_text()
        _scrub(page, "robot time", 0.8)  # the slider is labelled "robot time [s]"
        view = replay.replay
        assert view is not None
        deadline = time.monotonic() + 10
        while view.frame <= 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        with view.lock:
            frame = view.frame
            np.testing.assert_array_equal(replay.view.qpos, record.qpos[frame])
        t = record.times[frame]
        assert t == pytest.approx(record.times[0] + 0.8 * record.duration, abs=0.05 * record.duration)
        page.get_by_text(f"tick {int(record.ticks[frame])} ").first.wait_for(timeout=30_000)
    finally:
        replay.close()


def test_approve_a_risky_alternative_from_the_page(run: tuple[Any, Any, Path, Ticking]) -> None:
    from playwright.sync_api import sync_playwright

    console, executive, folder, ticking = run
    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=str(CHROMIUM), args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]
        )
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        t0 = time.perf_counter()
        page.goto(console.url)
        page.get_by_text("robot time").first.wait_for(timeout=30_000)
        load_s = time.perf_counter() - t0
        page.get_by_text("APPROVAL NEEDED").wait_for(timeout=120_000)
        selector = executive.selectors[0]
        request = executive.pending_approval.request
        panel = page.locator("body").inner_text()
        # Every alternative, with its risk as the selector ranked it.
        assert len(selector.results) == 3
        for alt in selector.results:
            assert alt.name in panel
            if alt.risk is not None:
                value = alt.risk.value(selector.ordering)
                assert f"{number(value)} !" in panel  # above the 0.001 threshold, marked
                assert number(alt.risk.components["collision"].probability) in panel
        assert "s left to answer" in panel and f"Approve {request.recommended}" in panel

        # Scrub the second-ranked alternative's ghost to 60 % of its motion.
        other = selector.ranking[1].name
        _scrub(page, other, 0.6)
        motion = console.tasks["task0"].motions[other]
        deadline = time.monotonic() + 10
        while console.ghost.motion is not motion and time.monotonic() < deadline:
            time.sleep(0.05)
        t = _ghost_matches_plan(console, other)
        assert t == pytest.approx(0.6 * motion.duration, abs=0.05 * motion.duration)
        shown = _slider(page, other).locator("[role=slider]").get_attribute("aria-valuenow")
        assert float(shown) == pytest.approx(t, abs=1e-6)

        if os.environ.get("CONSOLE_SCREENSHOT"):
            page.locator(".mantine-Notification-root button").first.click(timeout=2000)
            page.get_by_text("APPROVAL NEEDED").scroll_into_view_if_needed()
            time.sleep(1.0)
            page.screenshot(path=os.environ["CONSOLE_SCREENSHOT"])
        start = np.array(console.view.qpos)
        page.get_by_role("button", name=f"Approve {request.recommended}").click()
        approval = _approval_line(folder, timeout=30)
        assert (approval["decision"], approval["alternative"]) == ("approve", request.recommended)
        assert approval["by"] == f"console:{operator_name()}"
        # The robot moves, and the page with it.
        deadline = time.monotonic() + 20
        while np.allclose(console.view.qpos, start) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not np.allclose(console.view.qpos, start)
        page.get_by_text("[executing]").first.wait_for(timeout=30_000)
        # The behaviour tree, live: the approved alternative's subtree is running.
        page.get_by_text(f"{{-}} {request.recommended} [*]").first.wait_for(timeout=30_000)
        ticking.stop()
        _replay(page, folder)
        browser.close()
    print(f"page load (goto to the panel's first status line): {load_s:.2f} s")
