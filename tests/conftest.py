"""Shared fixtures: paths to test data and the shared G1 model, a clean py_trees blackboard, and every
scenario a test loads checked against the scenario schema."""

from __future__ import annotations

import os

# Before anything imports mujoco: headless rendering through EGL (executive/__init__ does the
# same, but test modules may import mujoco first).
if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# ../shared beside the checkout (CI clones main with shared/ beside it).
G1_DIR = REPO.parent / "shared" / "robots" / "unitree_g1"
G1_MJCF = G1_DIR / "g1_with_hands.xml"
#: s: a subprocess that has not finished a run or shown a prompt by then is hung, on any machine
#: (a safety net, not a measure: a loaded 2-core machine ran a 10 s run for over 120 s).
HANG_S = 900.0

#: Two pads on slide joints pressing a free box (motor forces ``ctrl``), gravity (gx, 0, gz): the
#: standalone grip the hold models are checked against (tests/test_risk_hold.py, test_grasp_hold.py).
PAD_GRIP_XML = """
<mujoco>
  <option timestep="0.002" integrator="implicitfast" cone="elliptic" impratio="10" gravity="{gx} 0 {gz}"/>
  <default>
    <geom condim="4"/>
    <default class="pad">
      <geom type="box" size="{hx} 0.005 {hz}" friction="{mu} 0.02 0.001" priority="1"
            solref="0.004 1" solimp="0.95 0.99 0.001" mass="0.16"/>
    </default>
  </default>
  <worldbody>
    <body name="pad_a" pos="0 {ya} 0">
      <joint name="ja" type="slide" axis="0 -1 0" damping="50"/>
      <geom name="pad_a" class="pad"/>
    </body>
    <body name="pad_b" pos="0 {yb} 0">
      <joint name="jb" type="slide" axis="0 1 0" damping="50"/>
      <geom name="pad_b" class="pad"/>
    </body>
    <body name="box" pos="{dx} 0 0">
      <freejoint/>
      <geom name="box" type="box" size="{bx} {by} {bz}" mass="{m}" friction="1 0.01 0.001"/>
    </body>
  </worldbody>
  <actuator>
    <motor joint="ja"/>
    <motor joint="jb"/>
  </actuator>
</mujoco>
"""


def g1_floor_yaml(mjcf: Path, com: float | None = None) -> str:
    """The Unitree G1 on open floor, a table with a book behind it (out of its walks' way).

    ``com``: the scenario's ``uncertainty.com`` (m; None: the default), which sets the balance
    reserve a step plans with.
    """
    uncertainty = f"uncertainty: {{com: {com}}}\n" if com is not None else ""
    return f"""
name: g1_floor
description: The G1 on open floor, a table behind it.
robot: {{mjcf: {mjcf}, profile: unitree_g1}}
scene:
  table: {{position: [-0.65, 0.0], size: [0.4, 0.8, 0.04], height: 0.66}}
  objects:
    - {{name: book, shape: box, size: [0.14, 0.09, 0.05], position: [-0.55, 0.2], mass: 0.3}}
  obstacles: []
{uncertainty}mission:
  - transfer: {{object: book, to: [-0.55, -0.2]}}
"""


@pytest.fixture(autouse=True)
def _clear_blackboard() -> None:
    """py_trees' blackboard is global: start every test with an empty one."""
    import py_trees

    py_trees.blackboard.Blackboard.enable_activity_stream(maximum_size=100)
    py_trees.blackboard.Blackboard.clear()


@pytest.fixture(autouse=True)
def _loaded_scenarios_pass_the_schema(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """A scenario the loader accepts in any test also validates against the scenario schema
    (``executive schema``; tests/schema_check.py): the schema never refuses what the executive reads."""
    from schema_check import watch_loader  # tests/ is on sys.path (pytest's default prepend import mode)

    refused = watch_loader(monkeypatch)
    yield
    assert not refused, "the loader accepted what the scenario schema refuses:\n" + "\n".join(refused)


@pytest.fixture
def g1_mjcf() -> Path:
    if not G1_MJCF.is_file():
        pytest.skip(f"the shared Unitree G1 model is not at {G1_MJCF}")
    return G1_MJCF


@pytest.fixture
def g1_scenario_yaml(g1_mjcf: Path) -> str:
    """The book scene scaled to the Unitree G1 (1.3 m tall): a lower, nearer table.

    Laid out for the G1's Dex3 hands. Their grasp is a palm-down pinch across the
    book's 9 cm width (see scenarios/robots/unitree_g1/profile.yaml), so a hand
    holding a book has its wrist about 10 cm to one side of it, and a hand that
    works across the body has that wrist between the book and the stack. The stack
    therefore stands behind the row of books (its front face 3 cm behind their far
    ends) and the books 22 cm either side of the midline: the one-arm alternatives
    still carry the book across the body past the stack's front, as in the
    humanoid's scene, but a hand at either book has room beside it. (The first
    layout, books at y = +-0.17 m 6.5 cm from a stack level with them, left the
    wrist no room: the left hand stopped 1.6 cm short of its pre-place, the right
    1.6 cm short of its pre-grasp.) The table's front edge is 1 cm under the books'
    near ends.
    """
    mjcf = g1_mjcf
    return f"""
name: g1_book_transfer
description: The book transfer scene around the Unitree G1 with Dex3 hands.
robot: {{mjcf: {mjcf}, profile: unitree_g1}}
scene:
  table: {{position: [0.47, 0.0], size: [0.50, 1.0, 0.04], height: 0.66}}
  objects:
    - {{name: book, shape: box, size: [0.14, 0.09, 0.05], position: [0.30, 0.22], mass: 0.3}}
  obstacles:
    - {{name: book_stack, shape: box, size: [0.16, 0.12, 0.22], position: [0.48, 0.0]}}
uncertainty: {{object_position: 0.01, object_yaw: 3, obstacle_position: 0.01, com: 0.01}}
mission:
  - transfer: {{object: book, to: [0.30, -0.22]}}
"""
