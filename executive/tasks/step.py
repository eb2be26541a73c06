"""The ``step`` kind: the robot walks to a goal stance in quasi-static steps.

    mission:
      - step: {to: [0.35, 0.0], yaw: 0}      # where the pelvis should stand (x, y m; yaw deg)

``to``: the pelvis's goal on the floor (x, y, m, world frame); ``yaw``: its heading (degrees,
default: the heading it has); ``alternatives``: which foot leads, ``left_first`` or
``right_first`` (default both). Each alternative is a walk of quasi-static steps
(:mod:`executive.planning.stepping`: weight shift, lift, swing, touchdown, weight shift back),
each within the robot's measured step reach, planned from where the robot stands; the
behaviour :class:`behaviours.step.Step` follows each step in physics. Later tasks plan from
the stance the walk ends in (``moves_base``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco

from executive.planning.plan import CompositionConfig, Step
from executive.planning.stepping_geometry import foothold_of, stance_of, stance_offsets
from executive.schema.declarations import Block, Number, Vector
from executive.schema.types import SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks.base import Alternative, Task, TaskKind, Verdict, alternatives_key
from executive.world.heading import yaw_of
from executive.world.model import World

__all__ = ["STANCE_TOLERANCE", "StepKind", "StepTask", "feet_stance"]

#: m: how far the feet's stance may end from its goal (a walk's steps are placed open loop).
STANCE_TOLERANCE = 0.05
#: m: the farthest goal a step task may name from the origin (a walk is at most a few metres).
TO_MAX = 5.0


@dataclass(frozen=True, kw_only=True)
class StepTask(Task):
    """Walk so that the pelvis stands at ``stance`` (x, y, m) heading ``yaw_rad`` (None: as it is)."""

    kind = "step"
    stance: tuple[float, float]
    yaw_rad: float | None = None

    def label(self) -> str:
        yaw = "" if self.yaw_rad is None else f", yaw {math.degrees(self.yaw_rad):.0f} deg"
        return f"step to ({self.stance[0]:.2f}, {self.stance[1]:.2f}){yaw}"


class StepKind(TaskKind):
    """The ``step`` kind: a walk to a goal stance, either foot first."""

    name = "step"
    alternative_names = ("left_first", "right_first")
    moves_base = True
    keys = Block(
        "Walk to a goal stance in quasi-static steps, either foot first; later tasks plan from there",
        {
            "to": Vector(
                "where the pelvis should stand on the floor, x y in the world frame",
                (Number("coordinate", "m", -TO_MAX, TO_MAX),),
                (2,),
                ("x", "y"),
                unit="m",
            ),
            "yaw": Number(
                "the pelvis's heading at the goal; absent: the heading it has",
                "deg",
                -180.0,
                180.0,
                to_radians=True,
            ),
            "alternatives": alternatives_key(alternative_names),
        },
        required=("to",),
        defaults={"alternatives": list(alternative_names)},
    )

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``step: {to: [x, y], yaw, alternatives}``; errors name the key path."""
        self.keys.check_keys(node)
        x, y = self.keys.read_key(node, "to")
        yaw = self.keys.read_key(node, "yaw")
        return StepTask(
            object="",
            stance=(x, y),
            yaw_rad=yaw,
            alternatives=self.read_alternatives(node, self.alternative_names),
        )

    def offered(self, task: Task, world: World) -> list[Alternative]:
        """A walk led by each foot the robot has."""
        feet = tuple(world.profile.feet)
        return [Alternative(name) for name in self.alternative_names if name.split("_")[0] in feet]

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        """One walking step: the planner lays out the footsteps (:func:`plan_alternative`)."""
        assert isinstance(task, StepTask)
        lead = alternative.split("_")[0]
        return [Step("step", f"{alternative}.walk", lead, stance=(*task.stance, task.yaw_rad))]

    def verify(self, task: Task, world: World, detector: object) -> Verdict | None:
        """The stance the robot's feet now stand in, against the goal: event ``stood``, or a failure.

        The stance is where the pelvis stands over the feet as the keyframe puts the feet about it
        (:func:`~executive.planning.stepping_geometry.stance_of`), not the pelvis itself: the
        balance feedback shifts the pelvis over the feet by as much as the robot's CoM is off its
        model (docs/stepping.md).
        """
        assert isinstance(task, StepTask)
        robot = getattr(detector, "world", None)
        if robot is None:
            return None
        x, y = feet_stance(robot)
        px, py = (float(v) for v in robot.data.xpos[robot.ids.base_body][:2])
        error = math.hypot(x - task.stance[0], y - task.stance[1])
        fields = {
            "stance": [round(x, 4), round(y, 4)],
            "pelvis": [round(px, 4), round(py, 4)],
            "stance_error_m": round(error, 4),
        }
        if error <= STANCE_TOLERANCE:
            return Verdict(True, "stood", fields)
        limit = f"tolerance {STANCE_TOLERANCE * 100:.0f} cm"
        detail = f"the robot's feet stand {error * 100:.1f} cm from the goal stance ({limit})"
        return Verdict(False, "failure", {**fields, "mode": "tracking", "detail": detail})

    def moved_objects(self, task: Task) -> tuple[str, ...]:
        return ()


def feet_stance(world: World) -> tuple[float, float]:
    """Where the pelvis of ``world``'s robot stands over its feet (x, y, m) as its keyframe puts the
    feet about the pelvis: the stance its feet stand in, whatever the pelvis leans over them."""
    model, ids = world.model, world.ids
    feet = {side: int(model.body(foot.body).id) for side, foot in world.profile.feet.items()}
    home = mujoco.MjData(model)
    home.qpos[:] = world.home_qpos()
    mujoco.mj_kinematics(model, home)
    offsets = stance_offsets(
        home.xpos[ids.base_body][:2],
        yaw_of(home.xquat[ids.base_body]),
        {side: foothold_of(home, side, body) for side, body in feet.items()},
    )
    now = {side: foothold_of(world.data, side, body) for side, body in feet.items()}
    x, y, _ = stance_of(now, offsets)
    return x, y
