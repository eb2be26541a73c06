"""The example plug-in kind ``wave`` (wave_kind.py): registered in code, planned, run in physics.

    python -m pytest -q examples/plugin_kind/test_plugin_kind.py

pytest puts this folder on ``sys.path`` (it has no ``__init__.py``), so ``wave_kind`` imports
as a plug-in installed on its own would. The hand's reach is measured from the planned joint
angles with MuJoCo's forward kinematics, the run's outcome from the truth world's data.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import yaml
from wave_kind import WaveKind, WaveTask

from executive.execution.runner import execute_plan
from executive.planning.planner import Planner
from executive.plugin import plan_alternative, register
from executive.scenario import from_dict
from executive.schema.catalog import scenario_path
from executive.world.model import build

AT = (0.42, -0.20)  # over the table, right of the book stack's front
HEIGHT = 0.15


def _doc() -> dict[str, Any]:
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["mission"] = [{"wave": {"at": list(AT), "height": HEIGHT, "alternatives": ["right"]}}]
    return doc


def test_wave_plans_and_runs() -> None:
    register(WaveKind)
    scenario = from_dict(_doc())
    task = scenario.mission[0]
    assert isinstance(task, WaveTask) and task.alternatives == ("right",)
    estimate = build(scenario)
    plan = plan_alternative(Planner(estimate), estimate, task, "right")
    # Where the planned joint angles put the right hand's site (forward kinematics, not the planner's word).
    site = estimate.ids.hand_sites["right"]
    data = mujoco.MjData(estimate.model)
    data.qpos[:] = plan.trajectories["right.wave"].qpos[-1]
    mujoco.mj_kinematics(estimate.model, data)
    want = np.array([*AT, scenario.scene.table.height + HEIGHT])
    assert np.linalg.norm(data.site_xpos[site] - want) < 0.01

    truth = build(scenario)
    book = truth.ids.object_bodies["book"]
    book_before = truth.data.xpos[book].copy()
    home = truth.data.site_xpos[site].copy()
    result = execute_plan(plan, truth, task)
    assert result.success, result.message
    assert np.linalg.norm(truth.data.site_xpos[site] - home) < 0.03  # back home
    assert np.linalg.norm(truth.data.xpos[book] - book_before) < 0.005  # nothing touched
