"""The behaviour subtree of a planned alternative: one task-level behaviour per step.

:func:`build_subtree` turns an :class:`executive.planning.plan.AlternativePlan` into a
py_trees Sequence: a mover per motion step and a footstep per step of a walk (each may be
wrapped in a live risk guard), a gripper behaviour per grasp and release, and a handover
(receiver grasps, giver releases, giver retreats) as its own subtree. A walk that more motions
follow is followed by a :class:`behaviours.restance.Restance`: the robot measures where it stands
and those motions are re-planned from there before they run. It is the default of
:meth:`executive.tasks.base.TaskKind.subtree`; a kind with steps of its own passes their
behaviours in ``make``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

import py_trees

from executive.planning.plan import AlternativePlan, Step

__all__ = ["build_subtree"]


def build_subtree(
    plan: AlternativePlan,
    *,
    guard: bool = False,
    make: Mapping[str, Callable[[Step], py_trees.behaviour.Behaviour]] | None = None,
) -> py_trees.composites.Sequence:
    """The alternative as a py_trees Sequence of task-level behaviours (a handover is its own subtree).

    ``guard``: wrap every motion (a hand's, and each footstep of a walk) in a
    :class:`behaviours.guard.RiskGuard` (live risk checks, active when a monitor is on the
    blackboard). ``make``: a task kind's own behaviour for
    steps of a kind of its own (a press), by step kind.
    """
    from behaviours.gripper import Grasp, Release
    from behaviours.handover import handover_subtree

    children: list[py_trees.behaviour.Behaviour] = []
    walks: list[tuple[int, Step]] = []  # (child index, step) of each walk
    steps = list(plan.steps)
    i = 0
    while i < len(steps):
        step = steps[i]
        if make is not None and step.kind in make:
            children.append(make[step.kind](step))
            i += 1
            continue
        if step.kind == "grasp" and i + 2 < len(steps) and steps[i + 1].kind == "release":
            # receiver grasps, giver releases, giver retreats: the handover
            release, retreat = steps[i + 1], steps[i + 2]
            children.append(
                handover_subtree(
                    f"{release.side}_to_{step.side}.handover",
                    giver=release.side,
                    receiver=step.side,
                    obj=step.obj,
                    retreat=plan.trajectories[retreat.name],
                )
            )
            i += 3
            continue
        if step.kind == "step":  # a walk: one behaviour per footstep (KeyError: not planned)
            walks.append((len(children), step))
            children.append(_walk(plan, step, guard))
        elif step.kind == "grasp":
            children.append(Grasp(step.name, step.side, step.obj))
        elif step.kind == "release":
            children.append(Release(step.name, step.side, step.obj))
        else:
            children.append(_motion(plan, steps, i, guard))
        i += 1
    for at, walk in reversed(walks):  # from the last: the indices before stay valid
        restance = _restance(plan, walk, children[at + 1 :])
        if restance is not None:
            children.insert(at + 1, restance)
    return py_trees.composites.Sequence(name=plan.name, memory=True, children=children)


def _restance(
    plan: AlternativePlan, walk: Step, after: list[py_trees.behaviour.Behaviour]
) -> py_trees.behaviour.Behaviour | None:
    """The behaviour that re-plans what follows ``walk`` from the measured stance
    (:class:`behaviours.restance.Restance`); None when no hand moves after it before another walk.

    Its movers are the behaviours among ``after`` that follow the rest's planned trajectories.
    """
    from behaviours.restance import Restance
    from executive.planning.restance import rest_after

    rest = rest_after(plan, walk.name)
    if rest is None:
        return None
    by_trajectory = {id(t): name for name, t in rest.trajectories.items()}
    movers = {}
    for child in after:
        for node in child.iterate():
            name = by_trajectory.get(id(getattr(node, "trajectory", None)))
            if name is not None:
                movers[name] = node
    return Restance(f"{walk.name}.restance", walk=walk.name, rest=rest, movers=movers)


def _walk(plan: AlternativePlan, step: Step, guard: bool) -> py_trees.behaviour.Behaviour:
    """A walk's footsteps in a Sequence, each following its part of the walk's trajectory (wrapped
    in a live risk guard when ``guard``: its swing foot the guard's side; an object the walk
    carries in a hand is the guard's carried object, on the robot's side)."""
    from behaviours.guard import RiskGuard
    from behaviours.step import Step as FootStep

    walk = plan.trajectories.get(step.name)
    if walk is not None and step.carried is not None and walk.carried != step.carried:
        walk = replace(walk, carried=step.carried)  # the same knots (the guards' memo key)
    children: list[py_trees.behaviour.Behaviour] = []
    starts_at = 0.0
    for k, footstep in enumerate(plan.walks[step.name]):
        mover = FootStep(f"{step.name}.{k + 1}", footstep, walk=walk, starts_at=starts_at)
        starts_at += footstep.duration
        children.append(RiskGuard(mover, side=footstep.swing, kind="step", obj="") if guard else mover)
    return py_trees.composites.Sequence(name=step.name, memory=True, children=children)


def _motion(plan: AlternativePlan, steps: list[Step], i: int, guard: bool) -> py_trees.behaviour.Behaviour:
    """The mover of motion step ``i`` (wrapped in a live risk guard when ``guard``)."""
    from behaviours.guard import RiskGuard
    from behaviours.move_hand import Carry, Home, Lift, MoveHand, Place, Retreat
    from behaviours.push import Push

    movers = {
        "move": MoveHand,
        "lift": Lift,
        "carry": Carry,
        "place": Place,
        "retreat": Retreat,
        "home": Home,
        "push": Push,
    }
    step = steps[i]
    # After a release the open jaws may still brush the object they let go of.
    let_go = step.obj or (step.allow_contact[0] if step.allow_contact else "")
    touching = (step.side, let_go) if step.kind in ("retreat", "home", "push") and let_go else None
    # The move onto a grasp: the open jaws must straddle the object, not land on it.
    after = steps[i + 1] if i + 1 < len(steps) else None
    onto_grasp = after is not None and after.kind == "grasp" and after.side == step.side
    approaching = (step.side, after.obj) if after is not None and onto_grasp else None
    mover = movers[step.kind](
        step.name, plan.trajectories[step.name], touching=touching or None, approaching=approaching
    )
    if not guard:
        return mover
    return RiskGuard(
        mover, side=step.side, kind=step.kind, obj=plan.task.object, allow_contact=step.allow_contact
    )
