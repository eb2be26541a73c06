"""Plug-in task kinds (executive/tasks/registry.py): the example ``wave`` kind of
examples/plugin_kind, found by an entry point and by a dotted path, planned with the real
planner and run in MuJoCo; bad kinds give located errors (exit 2, no traceback).

A dotted path imports its module only when the run allows it (``load(..., allow_modules=...)``,
``--allow-module``, ``EXECUTIVE_ALLOW_MODULES``); the fixture clears that variable.

The entry point is a real installed distribution's metadata: a ``<name>.dist-info`` folder
with ``METADATA`` and ``entry_points.txt`` on ``sys.path``, read by ``importlib.metadata``
as pip's would be. The plug-in module is the example's file copied under a name no other
test uses, so each case imports it afresh.
"""

from __future__ import annotations

import ast
import importlib
import shutil
import sys
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest
import yaml

from executive.cli.main import main
from executive.execution.runner import RunResult, execute_plan
from executive.planning.planner import Planner
from executive.runtime.mission import Executive
from executive.scenario import load
from executive.schema.catalog import scenario_path
from executive.tasks import registry
from executive.tasks.steps import plan_alternative
from executive.world.model import build

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "plugin_kind" / "wave_kind.py"
MODULE = "plugin_module"
AT = [0.42, -0.20]  # over the table, right of the book stack's front
HEIGHT = 0.15


@pytest.fixture
def plugin_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """``tmp_path`` on ``sys.path`` with the plug-in module; no kind registered in this process yet."""
    shutil.copy(EXAMPLE, tmp_path / f"{MODULE}.py")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    monkeypatch.setattr(registry, "_registered", {})
    monkeypatch.delenv(registry.ALLOW_ENV, raising=False)
    importlib.invalidate_caches()
    return tmp_path


def test_the_example_imports_only_the_plugin_facade() -> None:
    """A plug-in kind needs nothing of the package but executive.plugin, which has all it exports."""
    import executive.plugin

    tree = ast.parse(EXAMPLE.read_text())
    modules = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)} | {
        a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
    }
    assert {m for m in modules if m.split(".")[0] == "executive"} == {"executive.plugin"}
    assert all(hasattr(executive.plugin, name) for name in executive.plugin.__all__)


def _install_entry_point(folder: Path) -> None:
    info = folder / "wave_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: wave-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[executive.task_kinds]\nwave = {MODULE}:WaveKind\n")
    importlib.invalidate_caches()


def _scenario_file(folder: Path, task: dict[str, Any]) -> Path:
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["mission"] = [task]
    path = folder / "wave.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _plan_and_run(path: Path, allow: tuple[str, ...] = ()) -> tuple[RunResult, float, float]:
    """Load, plan the ``right`` alternative with the real planner, run it in MuJoCo (truth = estimate).

    Returns:
        The run, how far the planned wave put the hand from its point (forward kinematics of
        the planned joint angles), and how far from home the hand ended in the truth world (m).
    """
    scenario = load(path, allow_modules=allow)
    task = scenario.mission[0]
    assert type(task).__module__ == MODULE
    estimate = build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, task, "right")
    site = estimate.ids.hand_sites["right"]
    data = mujoco.MjData(estimate.model)
    data.qpos[:] = plan.trajectories["right.wave"].qpos[-1]
    mujoco.mj_kinematics(estimate.model, data)
    reach = float(np.linalg.norm(data.site_xpos[site] - [*AT, scenario.scene.table.height + HEIGHT]))
    truth = build(scenario)
    home = truth.data.site_xpos[site].copy()
    result = execute_plan(plan, truth, task)
    return result, reach, float(np.linalg.norm(truth.data.site_xpos[site] - home))


def test_entry_point_kind_plans_and_runs(plugin_dir: Path) -> None:
    _install_entry_point(plugin_dir)
    assert "wave" in registry.available()
    path = _scenario_file(plugin_dir, {"wave": {"at": AT, "height": HEIGHT, "alternatives": ["right"]}})
    result, reach, back = _plan_and_run(path)
    assert result.success, result.message
    assert reach < 0.01 and back < 0.03


def test_dotted_path_kind_plans_and_runs(plugin_dir: Path) -> None:
    path = _scenario_file(
        plugin_dir, {"kind": f"{MODULE}:WaveKind", "at": AT, "height": HEIGHT, "alternatives": ["right"]}
    )
    result, reach, back = _plan_and_run(path, allow=(MODULE,))
    assert result.success, result.message
    assert reach < 0.01 and back < 0.03


@pytest.mark.parametrize("found_by", ["entry point", "dotted path"])
def test_plugin_kind_runs_through_the_executive(
    plugin_dir: Path, found_by: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The executive's physics check runs dry runs and rollouts in spawned worker processes,
    # which find the kind again: by its entry point, or beside its task's class (dotted path).
    if found_by == "entry point":
        _install_entry_point(plugin_dir)
        task: dict[str, Any] = {"wave": {"at": AT, "height": HEIGHT}}
    else:
        task = {"kind": f"{MODULE}:WaveKind", "at": AT, "height": HEIGHT}
        monkeypatch.setenv(registry.ALLOW_ENV, MODULE)  # Executive(path) loads the file itself
    executive = Executive(_scenario_file(plugin_dir, task), approval="deny", truth="exact", background=False)
    while not executive.done:
        executive.tick()
    summary = executive.summary()
    assert summary["outcome"] == "success", summary
    (row,) = summary["tasks"]
    assert row["chosen"] in ("left", "right") and row["approval"] is None  # below the threshold


def _validate(path: Path, capsys: pytest.CaptureFixture[str], *allow: str) -> str:
    code = main(["validate", str(path), *(a for m in allow for a in ("--allow-module", m))])
    out, err = capsys.readouterr()
    assert code == 2, out + err
    assert "Traceback" not in out + err
    return err


@pytest.mark.parametrize(
    ("task", "words"),
    [
        ({"juggle": {"object": "book"}}, ["mission[0]", "unknown task kind 'juggle'", "transfer"]),
        ({"kind": "no_such_module:WaveKind", "at": AT}, ["mission[0]", "cannot import 'no_such_module'"]),
        (
            {"kind": f"{MODULE}:NoSuchKind", "at": AT},
            ["mission[0]", f"module '{MODULE}' has no 'NoSuchKind'"],
        ),
        ({"kind": f"{MODULE}:WaveTask", "at": AT}, ["mission[0]", "is not a TaskKind"]),
        ({"kind": ":WaveKind", "at": AT}, ["mission[0]", "package.module:Class"]),
        ({"kind": "no colon", "at": AT}, ["mission[0]", "unknown task kind 'no colon'"]),
        ({"kind": f"{MODULE}:WaveKind", "at": [5.0, 0.0]}, ["mission[0].at", "not over the table"]),
        ({"kind": f"{MODULE}:Transfer", "at": AT}, ["mission[0]", "the name of the kind executive.tasks"]),
    ],
)
def test_bad_kinds_are_located(
    plugin_dir: Path, capsys: pytest.CaptureFixture[str], task: dict[str, Any], words: list[str]
) -> None:
    # A kind that takes a built-in kind's name (appended to the plug-in module).
    with (plugin_dir / f"{MODULE}.py").open("a") as module:
        module.write("\n\nclass Transfer(WaveKind):\n    name = 'transfer'\n")
    err = _validate(_scenario_file(plugin_dir, task), capsys, MODULE, "no_such_module")
    for word in words:
        assert word in err, err
