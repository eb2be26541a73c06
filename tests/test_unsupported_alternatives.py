"""A robot profile's ``unsupported_alternatives`` (executive/robot/profile.py) reach the assessment.

A copy of the bundled humanoid's profile declares ``left_to_right`` unsupported: the
transfer still offers it, the kind reports it with the profile's reason, and the assessment
marks it infeasible with that reason without planning it; the other alternatives stay.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from executive.decision.assessment import assess_task
from executive.scenario import from_dict
from executive.schema.catalog import robot_profile_path, scenario_path
from executive.tasks.transfer import TransferKind
from executive.world.model import build

REASON = "the wrists cannot turn the half turn a handover needs"


def _profile(folder: Path) -> Path:
    source = robot_profile_path("humanoid")
    assert source is not None
    doc: dict[str, Any] = yaml.safe_load(source.read_text())
    doc["mjcf"] = str((source.parent / doc["mjcf"]).resolve())
    doc["unsupported_alternatives"] = {"left_to_right": REASON}
    path = folder / "profile.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_profile_declares_an_alternative_unsupported(tmp_path: Path) -> None:
    doc: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    doc["robot"] = {"profile": str(_profile(tmp_path))}
    scenario = from_dict(doc)
    world = build(scenario)
    assert world.profile.unsupported_alternatives == {"left_to_right": REASON}
    task = scenario.mission[0]
    kind = TransferKind()
    assert "left_to_right" in {a.name for a in kind.offered(task, world) if not a.unsupported}
    rows = {a.name: a.unsupported for a in kind.alternatives(task, world)}
    assert rows["left"] == "" and rows["right"] == ""
    assert rows["left_to_right"] == f"unsupported by robot 'humanoid': {REASON}"
    (row,) = assess_task(world, task.restricted(("left_to_right",)))
    assert not row.feasible and row.plan is None
    assert REASON in row.error and row.plan_s == 0.0
