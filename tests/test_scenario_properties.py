"""Any scenario that loads plans and runs to an outcome without a traceback, extreme numbers included.

Hypothesis draws book_transfer documents whose numbers reach the ends of their documented
ranges (:mod:`executive.schema.ranges`): object mass, friction, size and yaw, the
uncertainty, the risk and guard parameters. A document the loader rejects must be rejected
with a located :class:`ScenarioError`; one it accepts is run by the executive (auto approval,
sampled truth, real physics) to ``success``, ``failed`` or ``aborted``, with every
``decisions.jsonl`` line whole and an ``end`` line last.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from executive.errors import ExecutiveError
from executive.runtime.mission import Executive
from executive.scenario import loads
from executive.schema import ranges as R
from executive.schema.catalog import scenario_path

BASE = yaml.safe_load(scenario_path("book_transfer").read_text())
BASE["robot"] = "humanoid"


def _between(low: float, high: float) -> st.SearchStrategy[float]:
    """Values in [low, high], the ends themselves drawn often."""
    return st.one_of(st.sampled_from([low, high]), st.floats(low, high, allow_nan=False))


@st.composite
def documents(draw: st.DrawFn) -> dict[str, Any]:
    doc = copy.deepcopy(BASE)
    book = doc["scene"]["objects"][0]
    book["mass"] = draw(_between(R.MASS_MIN, R.MASS_MAX))
    book["friction"] = draw(_between(R.FRICTION_MIN, R.FRICTION_MAX))
    book["orientation"] = draw(_between(-R.ANGLE_MAX_DEG, R.ANGLE_MAX_DEG))
    scale = draw(_between(0.2, 1.5))
    book["size"] = [round(v * scale, 4) for v in book["size"]]
    u = doc["uncertainty"]
    u["object_position"] = draw(_between(0.0, R.POSITION_SIGMA_MAX))
    u["object_yaw"] = draw(_between(0.0, R.YAW_SIGMA_MAX_DEG))
    u["com"] = draw(_between(0.0, R.COM_SIGMA_MAX))
    u["object_mass"] = draw(_between(0.0, R.RELATIVE_SIGMA_MAX))
    u["friction"] = draw(_between(0.0, R.RELATIVE_SIGMA_MAX))
    risk = doc["risk"]
    risk["d_safety"] = draw(_between(1e-3, R.D_SAFETY_MAX))
    risk["guard"]["min_distance"] = draw(_between(0.0, R.GUARD_DISTANCE_MAX))
    risk["guard"]["min_com_margin"] = draw(_between(0.0, R.COM_MARGIN_MAX))
    risk["threshold"] = draw(_between(0.0, 20.0))
    risk["rollouts"] = {"count": draw(st.integers(0, 1)), "jobs": 1}
    doc["trials"]["seed"] = draw(st.integers(0, 2**32 - 1))
    return doc


@settings(
    max_examples=4,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(doc=documents())
def test_a_scenario_that_loads_runs_to_an_outcome(
    doc: dict[str, Any], tmp_path_factory: pytest.TempPathFactory
) -> None:
    try:
        scenario = loads(yaml.safe_dump(doc), source="drawn.yaml")
    except ExecutiveError as exc:  # rejected: located, one paragraph
        assert "drawn.yaml" in str(exc) and "Traceback" not in str(exc)
        print(f"rejected: {str(exc)[:150]}")
        return
    out = tmp_path_factory.mktemp("run") / "run"
    executive = Executive(scenario, approval="auto", out=out)  # holds at the wall clock's pace while it plans
    executive.run(time_limit_s=300.0)  # of robot time: a stop is an outcome too
    print(f"ran: {executive.outcome}")
    assert executive.outcome in ("success", "failed", "aborted")
    lines = [json.loads(line) for line in (Path(out) / "decisions.jsonl").read_text().splitlines()]
    assert lines[0]["kind"] == "run" and lines[-1]["kind"] == "end"
    assert json.loads((Path(out) / "summary.json").read_text())["outcome"] == executive.outcome
