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

from benchmarks.g1_scenes import G1_DIR, G1_MJCF, g1_book_yaml, g1_floor_yaml

__all__ = ["G1_DIR", "G1_MJCF", "HANG_S", "PAD_GRIP_XML", "g1_floor_yaml"]

REPO = Path(__file__).resolve().parents[1]
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
    """The book scene scaled to the Unitree G1 (:func:`benchmarks.g1_scenes.g1_book_yaml`)."""
    return g1_book_yaml(g1_mjcf)
