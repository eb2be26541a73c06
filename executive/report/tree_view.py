"""The mission's behaviour tree as a run builds it, with every alternative's subtree, for display.

:func:`mission_tree` lays out each alternative's steps (:meth:`TaskKind.steps`, no IK) and builds
its subtree with the kind's own :meth:`TaskKind.subtree` on a stand-in trajectory per motion step,
without planning or physics; a kind whose subtree cannot be built that way is planned (no
physics), said so in :attr:`MissionTree.notes`. A later task is laid out with the hands holding
what the earlier tasks leave, the objects where the scene starts them: where a run differs is in
docs/replay.md. Alternatives come in the task's order (a run ranks them by risk and leaves out
the infeasible).

Display it with :func:`text` (``py_trees.display.unicode_tree`` or ``ascii_tree``),
:func:`dot_source` (``py_trees.display.dot_tree``) and :func:`write_svg` (Graphviz's ``dot``).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import py_trees

from executive.decision.approval import make_channel
from executive.decision.audit import AuditLog
from executive.decision.selector import RiskSelector
from executive.errors import ExecutiveError
from executive.planning.plan import AlternativePlan, CompositionConfig, Step
from executive.planning.planner import Planner, PlanningError, Trajectory
from executive.schema.types import Scenario
from executive.tasks.base import TaskKind
from executive.tasks.steps import plan_alternative
from executive.world.model import World, build

__all__ = [
    "GraphvizMissing",
    "MissionTree",
    "dot_program",
    "dot_source",
    "mission_tree",
    "text",
    "write_svg",
]


class GraphvizMissing(ExecutiveError):
    """Graphviz's ``dot`` program, needed to draw an SVG, is not installed."""


@dataclass
class MissionTree:
    """The tree (``root``) and, per alternative left out or planned, a line saying why (``notes``)."""

    root: py_trees.behaviour.Behaviour
    notes: list[str] = field(default_factory=list)
    planned: list[str] = field(default_factory=list)  # "task0/left": built from a real plan


def _stand_in(step: Step, world: World) -> Trajectory:
    """A one-knot trajectory at the home pose named after ``step``: what a subtree is built from."""
    home = world.home_qpos()
    hands = {t.side: np.asarray(t.position, dtype=float)[None, :] for t in step.targets}
    return Trajectory(
        name=step.name,
        times=np.zeros(1),
        qpos=home[None, :],
        hand_paths=hands,
        com_path=np.zeros((1, 3)),
        carried=step.carried,
    )


def _subtree(
    kind: TaskKind, selector: RiskSelector, name: str, world: World, guard: bool, planner: list[Planner]
) -> tuple[py_trees.behaviour.Behaviour, bool, list[Step]]:
    """One alternative's subtree, from its steps (False) or, if that fails, from a real plan (True)."""
    task = selector.task
    steps = kind.steps(task, world, name, CompositionConfig())
    trajectories = {s.name: _stand_in(s, world) for s in steps if s.targets}
    try:
        plan = AlternativePlan(name, task, tuple(steps), trajectories)
        return kind.subtree(plan, guard=guard), False, steps
    except Exception:  # a kind whose subtree reads its trajectories: plan it for real
        if not planner:
            planner.append(Planner(world))
        plan = plan_alternative(planner[0], world, task, name)
        return kind.subtree(plan, guard=guard), True, list(plan.steps)


def _held_after(held: dict[str, str], steps: list[Step]) -> dict[str, str]:
    """What the hands hold (object -> side) after ``steps``, starting from ``held``."""
    out = dict(held)
    for step in steps:
        if step.kind == "grasp":
            out[step.obj] = step.side
        elif step.kind == "release" and out.get(step.obj) == step.side:
            del out[step.obj]
    return out


@contextlib.contextmanager
def _holding(world: World, held: dict[str, str]) -> Iterator[None]:
    """The estimate with its hands holding ``held`` (object -> side) for a while."""
    saved = world.held
    world.held = dict(held)
    try:
        yield
    finally:
        world.held = saved


def _expand(
    out: MissionTree,
    selector: RiskSelector,
    world: World,
    states: list[dict[str, str]],
    guard: bool,
    planner: list[Planner],
) -> list[dict[str, str]]:
    """Give ``selector`` the subtree of every alternative that can be laid out in one of ``states``.

    Returns the hold states its alternatives leave (the next task's starting states).
    """
    built: dict[str, py_trees.behaviour.Behaviour] = {}
    why: dict[str, str] = {}
    after: list[dict[str, str]] = []
    for held in states:
        with _holding(world, held):
            for alt in selector.kind.alternatives(selector.task, world):
                if alt.name in built:
                    continue
                if alt.unsupported:
                    why.setdefault(alt.name, alt.unsupported)
                    continue
                try:
                    subtree, planned, steps = _subtree(
                        selector.kind, selector, alt.name, world, guard, planner
                    )
                except PlanningError as exc:
                    why.setdefault(alt.name, str(exc))
                    continue
                built[alt.name] = subtree
                if planned:
                    out.planned.append(f"{selector.name}/{alt.name}")
                    out.notes.append(f"{selector.name}/{alt.name}: subtree built from a real plan")
                end = _held_after(held, steps)
                if end not in after:
                    after.append(end)
    for name in selector.names:  # the task's order
        if name in built:
            selector.add_child(built[name])
        else:
            out.notes.append(f"{selector.name}/{name}: not in the tree: {why.get(name, 'not offered')}")
    return after or states


def mission_tree(scenario: Scenario, *, guard: bool = True, world: World | None = None) -> MissionTree:
    """The Sequence of RiskSelectors ``executive run`` builds, every alternative's subtree as children.

    Args:
        scenario: the scenario.
        guard: motions wrapped in live risk guards (``executive run``'s default; ``--no-guard``).
        world: its estimate world (built if None).

    Returns:
        The :class:`MissionTree`. An alternative the robot does not support, or whose steps
        cannot be laid out on the estimate, is not in it: a note says why.
    """
    world = world if world is not None else build(scenario)
    log = AuditLog(None)
    channel = make_channel("deny")
    selectors = [
        RiskSelector(
            f"task{i}",
            task,
            estimate=world,
            channel=channel,
            log=log,
            timeout_s=scenario.approval.timeout_s,
            guard=guard,
            physics=None,
            background=False,
        )
        for i, task in enumerate(scenario.mission)
    ]
    root = py_trees.composites.Sequence(name=scenario.name, memory=True, children=list(selectors))
    out = MissionTree(root)
    planner: list[Planner] = []
    states = [dict(world.held)]  # what the hands hold when each task starts, as far as steps tell
    for selector in selectors:
        states = _expand(out, selector, world, states, guard, planner)
    return out


def text(root: py_trees.behaviour.Behaviour, *, unicode: bool = True) -> str:
    """The tree as py_trees draws it for a terminal (``unicode_tree``, or ``ascii_tree``)."""
    if unicode:
        return str(py_trees.display.unicode_tree(root))
    return str(py_trees.display.ascii_tree(root))


def dot_source(root: py_trees.behaviour.Behaviour) -> str:
    """Graphviz source of the tree (``py_trees.display.dot_tree``, through pydot)."""
    return str(py_trees.display.dot_tree(root).to_string())


def dot_program() -> str:
    """The path of Graphviz's ``dot`` program.

    Raises:
        GraphvizMissing: it is not on the PATH (the message says how to install it).
    """
    dot = shutil.which("dot")
    if dot is None:
        raise GraphvizMissing(
            "--svg needs Graphviz's `dot` program, which is not on the PATH "
            "(Debian/Ubuntu: apt-get install graphviz; macOS: brew install graphviz); "
            "--dot FILE writes the Graphviz source without it"
        )
    return dot


def write_svg(root: py_trees.behaviour.Behaviour, path: Path) -> Path:
    """Draw the tree as SVG with Graphviz's ``dot`` program.

    Raises:
        GraphvizMissing: ``dot`` is not on the PATH (with how to install it).
        ExecutiveError: ``dot`` failed or the file could not be written.
    """
    dot = dot_program()
    graph = py_trees.display.dot_tree(root)
    try:
        svg = graph.create(prog=dot, format="svg")
    except Exception as exc:  # pydot reports dot's failure as an assertion or OSError
        raise ExecutiveError(f"--svg {path}: Graphviz's dot failed: {exc}") from None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(svg if isinstance(svg, bytes) else str(svg).encode())
    except OSError as exc:
        raise ExecutiveError(f"--svg {path}: not written ({exc.strerror or exc})") from None
    return path
