"""``import executive`` gives what an integrator needs, lazily (executive/__init__.py).

Each case runs in a fresh interpreter, so what ``import executive`` loads is seen from an
empty ``sys.modules``, not from what earlier tests imported.
"""

from __future__ import annotations

import json
import subprocess
import sys

from tests.conftest import HANG_S


def _run(code: str) -> str:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG_S)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr
    return done.stdout


def test_import_is_light() -> None:
    out = _run(
        "import json, sys; import executive; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('executive', 'mujoco', 'numpy', 'py_trees', 'mink', 'coal', 'scipy'))))"
    )
    assert json.loads(out) == ["executive", "executive.errors"]


def test_the_integrator_names_resolve() -> None:
    out = _run(
        "import executive; print(executive.Executive, executive.load, executive.HostRobot)\n"
        "from executive import (Alternative, CallbackChannel, Executive, ExecutiveError, HostChannel,\n"
        "    PlanningError, PolicyChannel, RobotInterface, ScenarioError, Task, TaskKind, TaskKindError,\n"
        "    TerminalChannel, from_dict, load, loads, make_channel, register)\n"
        "from executive.runtime.mission import Executive as E\n"
        "from executive.tasks.registry import register as r\n"
        "assert Executive is E and register is r\n"
        "assert issubclass(PlanningError, ExecutiveError) and issubclass(TaskKindError, ExecutiveError)\n"
        "assert all(getattr(executive, n) is not None for n in executive.__all__)\n"
        "assert set(executive.__all__) <= set(dir(executive))\n"
        "print(len(executive.__all__))"
    )
    first, count = out.strip().splitlines()
    assert "executive.runtime.mission.Executive" in first
    assert "function load" in first
    assert "executive.execution.robot_interface.HostRobot" in first
    assert int(count) == 26


def test_unknown_name_is_an_attribute_error() -> None:
    out = _run(
        "import executive\n"
        "try:\n    executive.Nothing\nexcept AttributeError as e:\n    print(e)\n"
        "print(hasattr(executive, 'Planner'))"
    )
    assert out.splitlines() == ["module 'executive' has no attribute 'Nothing'", "False"]


def test_subpackages_first_then_the_top_level_names() -> None:
    # A subpackage imported first (its own imports go through executive/__init__), then the
    # lazy names: no partially initialised module anywhere.
    _run(
        "import executive.tasks.transfer, executive.scenario.loader\n"
        "import executive\n"
        "assert executive.TaskKind is executive.tasks.base.TaskKind\n"
        "assert executive.load is executive.scenario.loader.load"
    )
