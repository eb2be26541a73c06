"""Route or reach: for the cluttered book scenes of tests/data, is a failed one-arm move's target
reachable at all?

Per scene and one-arm alternative, the steps are planned in order (as ``plan_alternative``) until
one fails; that step's start is kept and the step is planned again from there:

* ``cluttered``: as the alternative does (what binds: the active set, ``PlanningError.binding``);
* ``clear``: in book_transfer without the scene's added obstacles (same start);
* ``goal``: the clear plan's end configuration checked in the cluttered scene: the smallest
  distance less required clearance over the move's collision pairs (>= 0: that goal pose is
  free, so the target is reachable and what fails is the way there);
* ``via``: in the cluttered scene through one via point (10 cm up, 10 cm back towards the robot,
  10 cm towards the robot's middle), each a move of its own, then on to the target;
* ``clear's steps``: the alternative's moves as the clear scene lays them out (its carry lane,
  its targets), planned in the cluttered scene.

Run: ``python benchmarks/bench_planning_failures.py`` (a few seconds per scene). Results:
docs/planning_failures.md.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from executive.planning.plan import CompositionConfig, Step
from executive.planning.planner import HandTarget, Planner, PlanningError, Trajectory
from executive.scenario import from_dict
from executive.schema.catalog import scenario_path
from executive.tasks.registry import get as task_kind
from executive.world.model import World, build

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
SCENES = ("book_transfer_binders", "book_transfer_enclosure", "book_transfer_tight")
VIAS = {"up": (0.0, 0.0, 0.10), "back": (-0.10, 0.0, 0.0), "inwards": (0.0, None, 0.0)}


def _world(doc: dict[str, Any]) -> tuple[World, Any]:
    scenario = from_dict(doc)
    return build(scenario), scenario


def _move(planner: Planner, q: np.ndarray, step: Step, targets: list[HandTarget] | None = None) -> Trajectory:
    return planner.move(
        q,
        list(targets or step.targets),
        name=step.name,
        carried=step.carried,
        allow_contact=step.allow_contact,
        rest=step.kind == "home",
    )


def _failing_step(world: World, scenario: Any, side: str) -> tuple[Step, np.ndarray, PlanningError] | None:
    """The first move of the alternative that does not plan, its start and its error."""
    planner = Planner(world)
    task = scenario.mission[0]
    q = np.array(world.home_qpos(), dtype=float)
    for step in task_kind(task.kind).steps(task, world, side, CompositionConfig()):
        if not step.targets:
            continue
        try:
            q = _move(planner, q, step).qpos[-1]
        except PlanningError as exc:
            return step, q, exc
    return None


def _goal_margin(world: World, step: Step, q: np.ndarray) -> tuple[float, str]:
    """Smallest distance less required clearance over the step's pairs at ``q`` (m), and its pair."""
    planner = Planner(world)
    problem = planner.problem
    conf = planner.configuration
    conf.update(q)
    attach, _relative = problem.attachment(conf.data, step.carried)
    limit, required = problem.collisions.limit(step.carried, step.allow_contact, attach)
    gaps = limit.distances(conf.data) - required
    k = int(np.argmin(gaps))
    names = [world.model.geom(int(g)).name for g in limit.pairs[k]]
    return float(gaps[k]), " vs ".join(names)


def _via(world: World, step: Step, q: np.ndarray, offset: tuple[float, float | None, float]) -> str:
    """The step through one via point (``None`` in y: 10 cm towards y = 0), then its target."""
    planner = Planner(world)
    (target,) = step.targets
    shift = np.array(
        [offset[0], -0.10 * np.sign(target.position[1]) if offset[1] is None else offset[1], offset[2]]
    )
    via = HandTarget(target.side, np.asarray(target.position) + shift, target.quat, target.frame)
    try:
        q = _move(planner, q, step, [via]).qpos[-1]
        _move(planner, q, step)
    except PlanningError as exc:
        return f"short: {exc}"
    return "reached"


def _clear_steps(world: World, clear: World, scenario: Any, side: str) -> str:
    """The alternative's moves laid out on ``clear`` (its lane and targets), planned in ``world``."""
    planner = Planner(world)
    task = scenario.mission[0]
    q = np.array(world.home_qpos(), dtype=float)
    for step in task_kind(task.kind).steps(task, clear, side, CompositionConfig()):
        if step.targets:
            try:
                q = _move(planner, q, step).qpos[-1]
            except PlanningError as exc:
                return f"short: {exc}"
    return "every move plans"


def main(scenes: list[str]) -> None:
    base: dict[str, Any] = yaml.safe_load(scenario_path("book_transfer").read_text())
    for stem in scenes:
        doc: dict[str, Any] = yaml.safe_load((DATA / f"{stem}.yaml").read_text())
        world, scenario = _world(doc)
        clear_doc = dict(doc, scene=dict(doc["scene"], obstacles=base["scene"]["obstacles"]))
        clear, _ = _world(clear_doc)
        for side in ("left", "right"):
            found = _failing_step(world, scenario, side)
            if found is None:
                print(f"{stem} {side}: plans")
                continue
            step, q, exc = found
            print(f"{stem} {side}: {step.name} fails: {exc}")
            print(f"  clear's steps in the clutter: {_clear_steps(world, clear, scenario, side)}")
            try:
                end = _move(Planner(clear), q, step).qpos[-1]
            except PlanningError as clear_exc:
                print(f"  clear: short too: {clear_exc}")
                continue
            gap, pair = _goal_margin(world, step, end)
            print(
                f"  clear: reached; its goal pose in the clutter: {gap * 1000:+.1f} mm beyond clearance", pair
            )
            for label, offset in VIAS.items():
                print(f"  via {label}: {_via(world, step, q, offset)}")


if __name__ == "__main__":
    main(sys.argv[1:] or list(SCENES))
