"""Setting a stopped step down on both feet along its own plan: back to where the foot lifted, or on.

A step stopped part-way (a live guard tripped, :mod:`behaviours.guard`) must end on both feet,
not on one. Its plan's knots already lead there either way, each knot checked by the planner
(clearance, the CoM inside the stance sole, the ZMP), and they start where the step is now:

* :func:`back_to_both_feet`: the step played backwards, from where it is to where the swing foot
  lifted from (``set_down``, on the stance foot), then the weight shift backwards
  (``shift_home``, both feet): the robot ends as it stood before the step;
* :func:`on_to_both_feet`: the step played on to the end of its touchdown (``set_down``), then
  its weight shift back (``shift_back``).

:func:`single_support_left` says how long each keeps the robot on one foot. Usage::

    back_s, on_s = single_support_left(plan, index, t)
    phases = back_to_both_feet(plan, index, t) if back_s <= on_s else on_to_both_feet(plan, index, t)
"""

from __future__ import annotations

import numpy as np

from executive.planning.stepping_types import StepPhase, StepPlan
from executive.planning.timing import Trajectory, concatenate

__all__ = ["back_to_both_feet", "on_to_both_feet", "reverse", "segment", "single_support_left"]


def segment(trajectory: Trajectory, t0: float, t1: float) -> Trajectory:
    """The part of ``trajectory`` between its times ``t0`` < ``t1`` (clamped to it), its knots
    inside and the two ends sampled; times from 0.

    Raises:
        ValueError: when the part is empty (``t1 <= t0`` once clamped).
    """
    t0, t1 = max(0.0, float(t0)), min(trajectory.duration, float(t1))
    if t1 <= t0:
        raise ValueError(f"{trajectory.name}: no part between {t0:.3f} and {t1:.3f} s")
    times = trajectory.times
    inside = times[(times > t0) & (times < t1)]
    at = np.concatenate([[t0], inside, [t1]])

    def along(path: np.ndarray) -> np.ndarray:
        return np.stack([np.interp(at, times, path[:, k]) for k in range(path.shape[1])], axis=1)

    return Trajectory(
        name=trajectory.name,
        times=at - t0,
        qpos=trajectory.sample_many(at),
        hand_paths={side: along(path) for side, path in trajectory.hand_paths.items()},
        com_path=along(trajectory.com_path),
        carried=trajectory.carried,
        free_quat_adr=trajectory.free_quat_adr,
    )


def reverse(trajectory: Trajectory) -> Trajectory:
    """``trajectory`` played backwards: the same knots and times, from its end to its start."""
    return Trajectory(
        name=trajectory.name,
        times=trajectory.duration - trajectory.times[::-1],
        qpos=trajectory.qpos[::-1].copy(),
        hand_paths={side: path[::-1].copy() for side, path in trajectory.hand_paths.items()},
        com_path=trajectory.com_path[::-1].copy(),
        carried=trajectory.carried,
        free_quat_adr=trajectory.free_quat_adr,
    )


def _one_foot(plan: StepPlan) -> list[int]:
    """Indices of the phases with the swing foot off the floor (one foot in support)."""
    return [k for k, phase in enumerate(plan.phases) if len(phase.support) == 1]


def single_support_left(plan: StepPlan, index: int, t: float) -> tuple[float, float]:
    """Seconds on one foot, from time ``t`` of phase ``index``, going back to where the swing foot
    lifted and going on to the end of its touchdown (0 when the phase has both feet down).

    Args:
        plan: the step.
        index: the phase the step is in.
        t: the time in that phase (s; clamped to it).
    """
    phases, single = plan.phases, _one_foot(plan)
    if index not in single:
        return 0.0, 0.0
    t = min(max(t, 0.0), phases[index].trajectory.duration)
    before = sum(phases[k].trajectory.duration for k in single if k < index)
    after = sum(phases[k].trajectory.duration for k in single if k > index)
    return t + before, phases[index].trajectory.duration - t + after


def back_to_both_feet(plan: StepPlan, index: int, t: float) -> tuple[StepPhase, ...]:
    """The step from time ``t`` of phase ``index`` played backwards to its start: the swing foot
    back where it lifted from (``set_down``, on the stance foot), then the weight shift back
    (``shift_home``, both feet).

    A phase with both feet down: its part before ``t`` backwards (a weight shift that had started,
    undone); after the swing foot landed: nothing (go on instead).
    """
    phases, single = plan.phases, _one_foot(plan)
    pieces: list[Trajectory] = []
    if t > 0.0:
        pieces.append(reverse(segment(phases[index].trajectory, 0.0, t)))
    if index not in single:
        undone = index < min(single) and pieces
        return (StepPhase("shift_home", pieces[0], phases[index].support),) if undone else ()
    pieces += [reverse(phases[k].trajectory) for k in reversed(single) if k < index]
    out = [StepPhase("set_down", concatenate(pieces, "set_down"), (plan.stance,))] if pieces else []
    first = min(single)
    out += [StepPhase("shift_home", reverse(p.trajectory), p.support) for p in phases[:first]]
    return tuple(out)


def on_to_both_feet(plan: StepPlan, index: int, t: float) -> tuple[StepPhase, ...]:
    """The step from time ``t`` of phase ``index`` played on: to the end of the touchdown
    (``set_down``, on the stance foot), then the weight shift back (``shift_back``, both feet).

    A phase with both feet down after the touchdown: the rest of it; before the lift: nothing
    (go back instead).
    """
    phases, single = plan.phases, _one_foot(plan)
    duration = phases[index].trajectory.duration
    rest = [segment(phases[index].trajectory, t, duration)] if t < duration else []
    if index not in single:
        finished = index > max(single) and rest
        return (StepPhase("shift_back", rest[0], phases[index].support),) if finished else ()
    rest += [phases[k].trajectory for k in single if k > index]
    out = [StepPhase("set_down", concatenate(rest, "set_down"), (plan.stance,))] if rest else []
    last = max(single)
    out += [StepPhase("shift_back", p.trajectory, p.support) for p in phases[last + 1 :]]
    return tuple(out)
