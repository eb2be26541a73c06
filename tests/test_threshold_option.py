"""``--threshold X`` on ``executive run`` and ``executive plan``: the risk gate set from the command line.

It lowers or raises ``risk.threshold`` within the range the scenario file's own value must lie in
(>= 0, below the largest value ``risk.ordering`` can take), so it can make the gate ask but never
switch it off; a value out of range is exit 2 before anything is planned.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
import yaml

from executive.cli.main import main
from executive.errors import ScenarioError
from executive.scenario import load, loads, max_ordering_value, with_threshold
from executive.schema.catalog import scenario_path


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The default ``runs/`` would be made in the working folder: keep it in the test's own."""
    monkeypatch.chdir(tmp_path)


def _with_file_threshold(value: float) -> float:
    """The threshold book_transfer.yaml gives when its file says ``value`` (the independent reference)."""
    path = scenario_path("book_transfer")
    doc = yaml.safe_load(path.read_text())
    doc["risk"]["threshold"] = value
    return loads(yaml.safe_dump(doc), base_dir=path.parent).risk.threshold


@pytest.mark.parametrize("value", [0.0, 0.05, 0.3, 5.0])
def test_an_override_is_the_value_the_file_would_give(value: float) -> None:
    scenario = load("book_transfer")
    changed = with_threshold(scenario, value)
    assert changed.risk.threshold == _with_file_threshold(value) == value
    assert changed.risk.ordering == scenario.risk.ordering and changed.scene == scenario.scene
    assert with_threshold(scenario, None) is scenario


def test_the_range_ends_just_below_the_orderings_largest_value() -> None:
    scenario = load("book_transfer")
    highest, _ = max_ordering_value(scenario.risk, scenario.scene)
    assert highest == 22.0  # expected loss: collision 3 x body-part factor 3 + fall 10 + drop 2 + tracking 1
    below = math.nextafter(highest, 0.0)
    assert with_threshold(scenario, below).risk.threshold == below
    for bad in (highest, highest * 10, -0.01, math.nan, math.inf):
        with pytest.raises(ScenarioError) as caught:
            with_threshold(scenario, bad)
        assert caught.value.source == "--threshold" and caught.value.key_path == "risk.threshold"


@pytest.mark.parametrize("command", ["run", "plan"])
@pytest.mark.parametrize(
    ("value", "needle"),
    [
        ("-0.1", "expected a number >= 0"),
        ("nan", "finite"),
        ("22", "can never be exceeded"),
        ("1e9", "below 22"),
    ],
)
def test_out_of_range_is_exit_2_before_anything_runs(
    command: str, value: str, needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main([command, "book_transfer", "--threshold", value])
    captured = capsys.readouterr()
    assert code == 2, captured.err
    assert "--threshold: risk.threshold" in captured.err and needle in captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    assert not (tmp_path / "runs").exists()


@pytest.mark.slow
def test_a_lowered_threshold_makes_the_gate_ask(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """book_transfer's lowest expected loss (about 0.17 without rollouts) is within its file's 0.3;
    below 0.01 the run asks, and the scenario's policy (deny) refuses: nothing moves, exit 1."""
    out = tmp_path / "run"
    code = main(
        ["run", "book_transfer", "--threshold", "0.01", "--exact", "--rollouts", "0", "--out", str(out)]
    )
    capsys.readouterr()
    assert code == 1
    lines = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    kinds = [line["kind"] for line in lines]
    assert lines[0]["kind"] == "run" and lines[0]["threshold"] == 0.01
    request = next(line for line in lines if line["kind"] == "approval_request")
    asked = request["request"]
    assert asked["threshold"] == 0.01 and "above the threshold 0.01" in asked["reason"]
    answer = next(line for line in lines if line["kind"] == "approval")
    assert answer["decision"] == "deny"
    assert "execute" not in kinds
    summary = json.loads((out / "summary.json").read_text())
    assert summary["threshold"] == 0.01 and summary["outcome"] == "aborted"
