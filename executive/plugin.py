"""Everything a task kind needs, in one import: the facade for plug-in kinds.

A kind is a :class:`TaskKind` subclass with a ``name`` (its YAML key) and its
``alternative_names``; it reads its block into a frozen :class:`Task` dataclass
(:meth:`TaskKind.read`, errors through :class:`Node`), says which :class:`Alternative`
values it offers on this robot in this :class:`World`, and lays one out as :class:`Step`
values (hand targets from :class:`HandFrames`; :class:`PlanningError` when it cannot).
Make it known with :func:`register` (or an entry point in ``executive.task_kinds``), and
try it with :func:`plan_alternative`. Declare the block's keys once as :attr:`TaskKind.keys`, a
:class:`Block` of :class:`Number`, :class:`Vector`, :class:`Text`, :class:`Choice` and
:class:`Integer` declarations: read with them, and ``executive schema`` describes the block from
them (:meth:`TaskKind.schema`). docs/task_kinds.md has the details and a complete example,
examples/plugin_kind/wave_kind.py::

    from executive.plugin import Alternative, Task, TaskKind, register
"""

from __future__ import annotations

from executive.planning.plan import CompositionConfig, Step
from executive.planning.types import PlanningError
from executive.schema.declarations import Block, Choice, Integer, Number, Text, Vector
from executive.schema.readers import over_table
from executive.schema.types import SceneConfig
from executive.schema.yaml_nodes import Node
from executive.tasks.base import Alternative, Task, TaskKind, Verdict
from executive.tasks.hands import HandFrames
from executive.tasks.registry import register
from executive.tasks.steps import plan_alternative
from executive.tasks.variation import VariedPoint
from executive.world.model import World

__all__ = [
    "Alternative",
    "Block",
    "Choice",
    "CompositionConfig",
    "HandFrames",
    "Integer",
    "Node",
    "Number",
    "PlanningError",
    "SceneConfig",
    "Step",
    "Task",
    "TaskKind",
    "Text",
    "VariedPoint",
    "Vector",
    "Verdict",
    "World",
    "over_table",
    "plan_alternative",
    "register",
]
