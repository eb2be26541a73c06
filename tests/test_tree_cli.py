"""``executive tree``: the mission's tree with every alternative's subtree, as py_trees draws it.

The subtrees are built from the task kinds' steps, without planning; they must be the very
subtrees a run builds from the planned alternatives (checked node for node against
``kind.subtree`` of real plans), and every alternative ``executive plan --json`` lists must
appear with its step behaviours.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import py_trees
import pydot
import pytest

from executive.cli.main import main
from executive.decision.assessment import assess_task
from executive.report.tree_view import dot_source, mission_tree, text
from executive.scenario import load
from executive.tasks.registry import get as task_kind
from executive.world.model import build


def _shape(node: py_trees.behaviour.Behaviour) -> list[tuple[int, str, str]]:
    """(depth, class, name) of every node, each before its children."""
    out: list[tuple[int, str, str]] = []

    def walk(n: py_trees.behaviour.Behaviour, depth: int) -> None:
        out.append((depth, type(n).__name__, n.name))
        for child in n.children:
            walk(child, depth + 1)

    walk(node, 0)
    return out


@pytest.fixture(scope="module")
def planned() -> dict[str, py_trees.behaviour.Behaviour]:
    """book_transfer's alternatives planned for real (the whole-body planner), as a run builds them."""
    scenario = load("book_transfer")
    world = build(scenario)
    task = scenario.mission[0]
    kind = task_kind(task.kind)
    results = assess_task(world, task)
    assert all(r.plan is not None for r in results), [r.error for r in results]
    return {r.name: kind.subtree(r.plan, guard=True) for r in results if r.plan is not None}


def test_every_planned_alternative_is_in_the_tree_with_its_steps(
    planned: dict[str, py_trees.behaviour.Behaviour], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["plan", "book_transfer", "--json", "--rollouts", "0"]) == 0
    (task,) = json.loads(capsys.readouterr().out)["tasks"]
    names = [alt["name"] for alt in task["alternatives"]]
    assert names == list(planned) == ["left", "right", "left_to_right"]
    assert main(["tree", "book_transfer"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert lines[0].endswith("book_transfer") and "task0" in lines[1]
    for name, subtree in planned.items():
        # the alternative's subtree as py_trees draws it, indented under task0, is in the output
        drawn = text(subtree).splitlines()
        start = next(i for i, line in enumerate(lines) if line.strip() == f"{{-}} {name}")
        assert [line[8:] for line in lines[start : start + len(drawn)]] == drawn
        steps = [n.name for n in subtree.iterate() if not n.children]
        assert len(steps) >= 10 and all(f"--> {s}" in out for s in steps)


def test_the_tree_without_planning_is_node_for_node_the_planned_one(
    planned: dict[str, py_trees.behaviour.Behaviour],
) -> None:
    scenario = load("book_transfer")
    tree = mission_tree(scenario)
    assert tree.notes == [] and tree.planned == []
    (selector,) = tree.root.children
    assert type(selector).__name__ == "RiskSelector"
    built = {child.name: child for child in selector.children}
    assert list(built) == ["left", "right", "left_to_right"]  # the task's order
    for name, subtree in planned.items():
        assert _shape(built[name]) == _shape(subtree)
    # without guards: the motions are the selector's children's leaves, no RiskGuard
    bare = mission_tree(scenario, guard=False)
    kinds = {type(n).__name__ for n in bare.root.iterate()}
    assert "RiskGuard" not in kinds and "MoveHand" in kinds


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # pydot's parser on a newer pyparsing
def test_dot_source_holds_every_node(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dot = tmp_path / "deeper" / "tree.dot"
    assert main(["tree", "book_transfer", "--dot", str(dot)]) == 0
    assert f"dot       {dot}" in capsys.readouterr().out
    (graph,) = pydot.graph_from_dot_data(dot.read_text())
    tree = mission_tree(load("book_transfer"))
    nodes = list(tree.root.iterate())
    assert len([n for n in graph.get_nodes() if n.get_name() not in ("node", "graph", "edge")]) == len(nodes)
    assert len(graph.get_edges()) == len(nodes) - 1
    assert dot_source(tree.root).startswith("digraph")


def test_svg_without_graphviz_is_exit_2_with_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))  # no `dot` on it
    svg = tmp_path / "tree.svg"
    assert main(["tree", "book_transfer", "--svg", str(svg)]) == 2
    err = capsys.readouterr().err
    assert "--svg" in err and "apt-get install graphviz" in err and "Traceback" not in err
    assert not svg.exists()


def test_svg_with_graphviz(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    if shutil.which("dot") is None:
        pytest.skip("Graphviz's dot is not installed (apt-get install graphviz to run this test)")
    svg = tmp_path / "tree.svg"
    assert main(["tree", "book_transfer", "--svg", str(svg)]) == 0
    body = svg.read_text()
    assert "<svg" in body and "left_to_right.handover" in body


def test_bad_input_is_exit_2_naming_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["tree", "no_such_scenario"]) == 2
    assert "no_such_scenario" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nrobot: {mjcf: nowhere.xml}\n")
    assert main(["tree", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "Traceback" not in err
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    assert main(["tree", "book_transfer", "--dot", str(blocker / "tree.dot")]) == 2
    err = capsys.readouterr().err
    assert "--dot" in err and "a file, not a folder" in err


def test_a_place_after_a_pick_shows_each_hand_the_pick_may_leave_holding() -> None:
    """pick_place_push's place (task1) needs the object in hand: laid out from what the pick's steps leave."""
    tree = mission_tree(load("pick_place_push"))
    assert tree.notes == []
    tasks = {s.name: s for s in tree.root.children}
    assert [c.name for c in tasks["task0"].children] == ["left", "right"]  # the pick
    place = {c.name: [n.name for n in c.iterate()] for c in tasks["task1"].children}
    assert set(place) == {"left", "right"}
    for side, names in place.items():
        assert f"{side}.place" in names and f"{side}.release" in names and f"{side}.grasp" not in names
