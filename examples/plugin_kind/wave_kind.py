"""A plug-in task kind in one file: ``wave``, a hand goes to a point above the table and back.

    mission:
      - wave: {at: [0.45, 0.10], height: 0.15}           # found by its entry point
      - kind: wave_kind:WaveKind                            # or by its dotted path (allowed)
        at: [0.45, 0.10]
        alternatives: [left]

``at``: the point (x, y, m) over the table; ``height``: how far above the table top the
hand's grasp site goes (m, default 0.15); ``alternatives``: the hands that may wave
(``left``, ``right``; default both). The hand goes there with its jaws pointing down and
comes home; nothing is touched. Register it with an entry point in your package's metadata::

    [project.entry-points."executive.task_kinds"]
    wave = "wave_kind:WaveKind"

or by its dotted path in the YAML (the module on ``sys.path``; a scenario imports it only
when the run allows it: ``executive validate FILE --allow-module wave_kind``,
``EXECUTIVE_ALLOW_MODULES=wave_kind``, or ``load(FILE, allow_modules=["wave_kind"])``), or in
code with ``executive.plugin.register(WaveKind)``. It imports only from :mod:`executive.plugin`, the
facade for plug-in kinds. See docs/task_kinds.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from executive.plugin import (
    Alternative,
    CompositionConfig,
    HandFrames,
    Node,
    SceneConfig,
    Step,
    Task,
    TaskKind,
    World,
    over_table,
)

__all__ = ["WaveKind", "WaveTask"]


@dataclass(frozen=True, kw_only=True)
class WaveTask(Task):
    """Move a hand to ``height`` above the table top at ``at`` (x, y) and back home."""

    kind = "wave"
    at: tuple[float, float]
    height: float = 0.15

    def label(self) -> str:
        return f"wave at ({self.at[0]:.2f}, {self.at[1]:.2f})"


class WaveKind(TaskKind):
    """The ``wave`` kind: one hand to a point above the table and back."""

    name = "wave"
    alternative_names = ("left", "right")

    def read(self, node: Node, scene: SceneConfig) -> Task:
        """``wave: {at: [x, y], height, alternatives}``; errors name the key path."""
        node.check_keys(("at",), ("height", "alternatives"))
        at_node = node.get("at")
        x, y = at_node.numbers(2, ge=-10.0, le=10.0)
        if not over_table(scene.table, x, y):
            at_node.fail(f"({x:.2f}, {y:.2f}) is not over the table")
        height_node = node.opt("height")
        height = height_node.number(gt=0.0, le=1.0) if height_node is not None else 0.15
        return WaveTask(object="", at=(x, y), height=height, alternatives=self.read_alternatives(node))

    def offered(self, task: Task, world: World) -> list[Alternative]:
        """Each hand the robot has."""
        return [Alternative(side) for side in self.alternative_names if side in world.profile.sides]

    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        """There with the jaws pointing down (the way the hand faces at home), then home."""
        assert isinstance(task, WaveTask)
        frames = HandFrames(world)
        point = np.array([*task.at, world.scenario.scene.table.height + task.height])
        there = frames.target(alternative, point, frames.heading)
        return [
            Step("move", f"{alternative}.wave", alternative, (there,)),
            Step("home", f"{alternative}.home", alternative, (frames.home[alternative],)),
        ]
