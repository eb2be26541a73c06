"""The failure-mode table: every verdict lands in a mode or an explicit outcome, and a mode added
to the table (with its model) shows in plan, the campaign table, the console and the approval text."""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterator
from pathlib import Path

import py_trees
import pytest
from test_scenario import bundled_dict  # tests/ is on sys.path (pytest's prepend import mode)

from behaviours.gripper import Release
from executive.console.risk_table import physics_table, risk_table
from executive.decision.approval import AlternativeRisk as RequestRow
from executive.decision.approval import ApprovalRequest, request_table
from executive.decision.assessment import assess_task
from executive.decision.risk_models import PlanContext, register_model, unregister_model
from executive.decision.selector import risk_row
from executive.errors import ExecutiveError
from executive.execution.runner import behaviour_failure
from executive.report.plots import risk_json
from executive.report.plots import risk_table as plan_table
from executive.risk.fusion import observed_as
from executive.risk.orderings import Ordering, ordering_names, register_ordering, unregister_ordering
from executive.risk.report import RiskReport
from executive.scenario import from_dict, load, max_ordering_value
from executive.schema.failure_modes import (
    FailureMode,
    ScenarioDeprecationWarning,
    failure_mode,
    mode_names,
    mode_of_verdict,
    outcomes,
    register_mode,
    unregister_mode,
    verdict_names,
)
from executive.validation.campaign import run_campaign, table_markdown, table_text
from executive.world.model import build


def test_every_verdict_maps_to_one_mode_or_an_explicit_outcome() -> None:
    assert mode_names() == ("collision", "fall", "drop", "tracking")
    seen = [v for v in verdict_names()]
    assert len(seen) == len(set(seen))  # no verdict counts twice
    assert {v: mode_of_verdict(v) for v in verdict_names()} == {
        "collision": "collision",
        "fall": "fall",
        "unstable": "fall",  # a simulation that blew up: the robot is no longer controlled
        "slip": "fall",  # a standing foot slid: the support under the robot moved
        "drop": "drop",
        "tracking": "tracking",  # a hand (or foot) ended short of its plan: predicted since issue 27
        "guard": None,
        "task": None,
        "timeout": None,
        "error": None,
    }
    assert {o.name for o in outcomes()} == {"guard", "task", "timeout", "error"}
    assert observed_as("fall") == ("fall", "unstable", "slip") and observed_as("drop") == ("drop",)
    assert observed_as("tracking") == ("tracking",)
    assert failure_mode("fall").terminal and not failure_mode("drop").terminal
    assert not failure_mode("tracking").terminal
    with pytest.raises(ExecutiveError, match="valid: collision, fall, unstable, slip, drop, tracking"):
        mode_of_verdict("stalled")


def test_a_behaviour_says_its_verdict_and_one_without_a_verdict_did_not_do_its_task() -> None:
    stalled = Release("left.transfer", "left", "book")  # any task-level behaviour
    assert stalled.fail("tracking", "hand 37 mm from its planned end") == py_trees.common.Status.FAILURE
    failure = behaviour_failure(stalled, 3.5)
    assert (failure.mode, failure.time) == ("tracking", 3.5)
    assert failure.detail == "hand 37 mm from its planned end"  # the run's message adds its name, once
    assert behaviour_failure(py_trees.behaviours.Failure("plug-in"), 1.0).mode == "task"
    assert behaviour_failure(None, 1.0).mode == "task"
    bogus = Release("bogus", "left", "book")
    bogus.fail("stalled", "not in the table")
    with pytest.raises(ExecutiveError, match="unknown verdict 'stalled'"):
        behaviour_failure(bogus, 1.0)


def test_the_old_name_of_the_drop_mode_still_reads_with_a_warning() -> None:
    data = bundled_dict()
    data["risk"] = {"weights": {"grasp": 0.5}, "severity": {"grasp": 4.0}}
    with pytest.warns(ScenarioDeprecationWarning) as caught:
        s = from_dict(data)
    assert [str(w.message).split(": ", 1)[1] for w in caught] == [
        f"risk.{key}.grasp: 'grasp' is the old name of the failure mode 'drop'; write 'drop'"
        for key in ("weights", "severity")
    ]
    assert dict(s.risk.weights)["drop"] == 0.5 and s.risk.severity.drop == 4.0
    data["risk"] = {"weights": {"drop": 0.5}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert dict(from_dict(data).risk.weights)["drop"] == 0.5


def test_an_ordering_is_a_registry_entry_the_loader_and_the_selector_read() -> None:
    assert ordering_names() == ("weighted_sum", "probability", "expected_loss", "loss_and_time")
    data = bundled_dict()
    data["risk"] = {"ordering": "fall_first", "threshold": 0.1}
    with pytest.raises(ExecutiveError, match="fall_first"):
        from_dict(data)
    register_ordering(
        Ordering(
            "fall_first", lambda t: 10 * t.components["fall"].probability, lambda r, s: (10.0, "10 x P(fall)")
        )  # type: ignore[attr-defined]
    )
    try:
        s = from_dict(data)
        assert max_ordering_value(s.risk, s.scene) == (10.0, "10 x P(fall)")
    finally:
        unregister_ordering("fall_first")
    assert "fall_first" not in ordering_names()


def _slow_model(ctx: PlanContext) -> RiskReport:
    """A mode for the test: the plan's share of a 100 s budget (longer plans wear the robot more)."""
    p = min(1.0, ctx.plan.duration / 100.0)
    return RiskReport("slow", p, (p, p), ctx.severity("slow"), p)


@pytest.fixture
def slow_mode() -> Iterator[None]:
    register_mode(FailureMode("slow", "too slow", "slow", verdicts=(), severity=0.5, weight=0.25))
    register_model("slow", _slow_model)
    try:
        yield
    finally:
        unregister_model("slow")
        unregister_mode("slow")


def test_a_mode_added_to_the_table_shows_everywhere_and_goes_when_removed(
    slow_mode: None, tmp_path: Path
) -> None:
    scenario = load("book_transfer")
    world = build(scenario)
    alternatives = assess_task(world, scenario.mission[0])
    left = next(a for a in alternatives if a.name == "left")
    assert left.risk is not None and left.plan is not None
    slow = left.risk.components["slow"]
    assert slow.probability == pytest.approx(left.plan.duration / 100.0)
    assert left.risk.expected_loss == pytest.approx(
        sum(r.probability * r.severity for r in left.risk.components.values())
    )
    assert slow.severity == 0.5  # the table's default: the scenario does not name the mode
    # executive plan: the table and the JSON
    assert "too slow" in plan_table(scenario, "0: transfer", alternatives).splitlines()[1]
    plan = json.loads(risk_json(scenario, [("0", alternatives)]))
    assert plan["tasks"][0]["alternatives"][0]["risk"]["slow"] == pytest.approx(slow.probability)
    # the console's risk table and the approval text, from the selector's rows
    rows = [risk_row(a, scenario.risk.ordering) for a in alternatives]
    assert "| too slow |" in risk_table(rows, scenario.risk.ordering, scenario.risk.threshold)
    request = ApprovalRequest(
        "0: transfer",
        tuple(RequestRow(r["name"], True, r["risk"], r["value"]) for r in rows if r.get("risk")),
        "left",
        0.1,
        scenario.risk.ordering,
        "above the threshold",
    )
    text = request_table(request)
    assert "too slow" in text and f"{slow.probability:.4f}" in text
    # the campaign table: predicted P(slow) beside the observed outcomes
    with open(tmp_path / "log", "w") as log:
        result = run_campaign(scenario, trials=1, alternatives=["left"], out=tmp_path / "c", stream=log)
    assert "P(slow)" in table_text(result.summary) and "P(slow)" in table_markdown(result.summary)
    predicted = result.summary["alternatives"][0]["predicted"]["slow"]
    assert 0.2 < predicted < 0.6 and f"{predicted:.4f}" in table_text(result.summary)  # a 20-60 s plan


def test_without_the_added_mode_nothing_shows_it() -> None:
    assert "slow" not in mode_names()
    rows = [{"name": "left", "feasible": True, "value": 0.1, "risk": {"collision": 0.1, "combined": 0.1}}]
    assert "too slow" not in risk_table(rows, "expected_loss", 0.3)
    assert "too slow" not in physics_table(rows)
    data = bundled_dict()
    data["risk"] = {"severity": {"slow": 1.0}}
    with pytest.raises(ExecutiveError, match=r"risk\.severity\.slow"):
        from_dict(data)


def _verdicts_in_source() -> dict[str, set[str]]:
    """Every verdict literal the code returns: ``Failure("x", ...)``, ``self.fail("x", ...)``,
    ``self.verdict = "x"`` in executive/ and behaviours/, with the files that say it."""
    import ast

    root = Path(__file__).resolve().parent.parent
    found: dict[str, set[str]] = {}
    for path in [*root.glob("executive/**/*.py"), *root.glob("behaviours/*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            literal = None
            if isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
                func = node.func
                if (isinstance(func, ast.Name) and func.id == "Failure") or (
                    isinstance(func, ast.Attribute) and func.attr == "fail" and path.parts[-2] == "behaviours"
                ):
                    literal = node.args[0].value
            elif isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant):
                if any(isinstance(t, ast.Attribute) and t.attr == "verdict" for t in node.targets):
                    literal = node.value.value or None
            if isinstance(literal, str):
                found.setdefault(literal, set()).add(path.name)
    return found


def test_every_verdict_the_code_returns_is_in_the_table() -> None:
    found = _verdicts_in_source()
    assert {"collision", "fall", "unstable", "drop", "tracking", "guard", "task"} <= set(found), found
    unknown = {v: files for v, files in found.items() if v not in verdict_names()}
    assert not unknown, f"verdicts the failure-mode table does not know: {unknown}"
