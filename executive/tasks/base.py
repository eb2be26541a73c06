"""What a task is and what a task kind must provide.

A mission is a sequence of :class:`Task` values, each read from its YAML block by a
:class:`TaskKind` (``transfer``, ``pick``, ``place``, ``push``, ``press``, or a
third party's). The kind says which alternatives exist for the robot and world at
hand (:meth:`TaskKind.alternatives`), turns one into planner steps
(:meth:`TaskKind.steps`) and a behaviour subtree (:meth:`TaskKind.subtree`), and
checks afterwards that the task did what it asked (:meth:`TaskKind.verify`). Its block's keys
are declared once (:attr:`TaskKind.keys`, :mod:`executive.schema.declarations`): the kind reads
with them and :meth:`TaskKind.schema` gives ``executive schema`` their JSON Schema.

Register a kind with :func:`executive.tasks.registry.register`, an entry point in
the group ``executive.task_kinds``, or ``kind: package.module:Class`` in the YAML.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar

from executive.schema.declarations import Alternatives, Block, nullable
from executive.schema.types import Task
from executive.tasks.subtree import build_subtree
from executive.tasks.variation import VariedPoint

if TYPE_CHECKING:
    import py_trees

    from executive.monitoring.detectors import FailureDetector
    from executive.planning.plan import AlternativePlan, CompositionConfig, Step
    from executive.schema.types import SceneConfig
    from executive.schema.yaml_nodes import Node
    from executive.world.model import World

__all__ = ["Alternative", "Task", "TaskKind", "VariedPoint", "Verdict", "alternatives_key"]


def alternatives_key(names: tuple[str, ...]) -> Alternatives:
    """The declaration of a task block's ``alternatives``: distinct names of ``names``, at least one."""
    return Alternatives("the alternatives the selector may choose from, in the order they are tried", names)


@dataclass(frozen=True)
class Alternative:
    """One way to do a task; ``unsupported`` says why it cannot be done here ("" if it can)."""

    name: str
    unsupported: str = ""


@dataclass(frozen=True)
class Verdict:
    """A kind's check of a finished task: ``ok``, the audit line's event and its fields.

    Fields of a failure: ``mode`` (``misplaced``, ``drop``, ...), ``detail``, ``behaviour``, ``time``.
    """

    ok: bool
    event: str
    fields: dict[str, Any]
    failure: Any = None  # the detector's Failure behind a failed check, if it gave one


class TaskKind(abc.ABC):
    """A kind of task: its YAML block, its alternatives, their steps and subtrees.

    Subclasses set ``name`` (the YAML key) and ``alternative_names`` (every name an
    alternative of this kind can have, documented and stable), and implement
    :meth:`read`, :meth:`offered` and :meth:`steps`. Two flags say what a task of the kind
    leaves in a hand, for the checks of a whole mission (both False unless set):

    * ``leaves_held``: the task ends with its ``object`` still in a hand (a ``pick``); the next
      task must be one that ``needs_held`` that object;
    * ``needs_held``: the task starts with its ``object`` in the hand an earlier task left it
      in (a ``place``).

    ``moves_base``: the task ends with the robot standing elsewhere (a ``step``); later tasks
    plan from the stance it ends in. An alternative of another kind may walk too (its plan's
    ``walks``): the same holds after it.

    ``instead_of``: alternative -> the alternative it stands in for. It is planned only when that
    one, asked for in the same planning round, cannot be planned (a transfer's side-step, where the
    arm alone falls short); otherwise its row says it is not needed.

    ``keys``: the block's keys (a :class:`~executive.schema.declarations.Block`), declared once for
    :meth:`read` and :meth:`schema`; None (the default) leaves the block undescribed but for its
    ``alternatives``.
    """

    name: ClassVar[str] = ""
    alternative_names: ClassVar[tuple[str, ...]] = ()
    leaves_held: ClassVar[bool] = False
    needs_held: ClassVar[bool] = False
    moves_base: ClassVar[bool] = False
    instead_of: ClassVar[Mapping[str, str]] = MappingProxyType({})
    keys: ClassVar[Block | None] = None

    @abc.abstractmethod
    def read(self, node: Node, scene: SceneConfig) -> Task:
        """The task in ``node`` (the block under the kind's key); errors name the key path.

        Raises:
            ScenarioError: through ``node.fail``, naming what is wrong and where.
        """

    @abc.abstractmethod
    def offered(self, task: Task, world: World) -> list[Alternative]:
        """Every alternative this kind offers for ``task`` on this robot, in this world's state."""

    @abc.abstractmethod
    def steps(self, task: Task, world: World, alternative: str, config: CompositionConfig) -> list[Step]:
        """The steps of ``alternative`` with hand targets from the estimate ``world``.

        Raises:
            PlanningError: the alternative cannot be laid out (named reason).
        """

    def read_alternatives(self, node: Node, default: tuple[str, ...] = ()) -> tuple[str, ...]:
        """The block's optional ``alternatives`` (of :attr:`alternative_names`), else ``default``."""
        found = node.opt("alternatives")
        return alternatives_key(self.alternative_names).read(found) if found is not None else default

    def schema(self) -> dict[str, Any]:
        """The JSON Schema (draft 2020-12) of the kind's block, the mapping under its key.

        ``executive schema`` and ``docs/scenarios.md`` show it. Default: the schema of :attr:`keys`;
        without them, a mapping whose ``alternatives`` are checked and whose other keys are the
        kind's own (described by the class's docstring).
        """
        if self.keys is not None:
            return self.keys.json_schema()
        words = (type(self).__doc__ or f"The {self.name} task kind.").strip().split("\n\n")[0]
        return {
            "description": " ".join(words.split()),
            "type": "object",
            "properties": {"alternatives": nullable(alternatives_key(self.alternative_names).json_schema())},
        }

    def alternatives(self, task: Task, world: World) -> list[Alternative]:
        """The alternatives to assess: those offered that the task allows, in the task's order.

        An alternative the robot's profile declares unsupported comes back with that reason.
        """
        offered = {a.name: a for a in self.offered(task, world)}
        names = task.alternatives or tuple(offered)
        unsupported = world.profile.unsupported_alternatives
        out = []
        for name in names:
            alt = offered.get(name, Alternative(name, f"{self.name} does not offer '{name}' here"))
            if not alt.unsupported and name in unsupported:
                alt = Alternative(name, f"unsupported by robot '{world.profile.name}': {unsupported[name]}")
            out.append(alt)
        return out

    def subtree(self, plan: AlternativePlan, *, guard: bool = False) -> py_trees.behaviour.Behaviour:
        """The alternative's behaviour subtree (default: one behaviour per step, in order)."""
        return build_subtree(plan, guard=guard)

    def verify(self, task: Task, world: World, detector: FailureDetector) -> Verdict | None:
        """After the subtree succeeded, did the task do what it asked? (None: nothing to check.)

        ``world`` is the estimate (the scene as planned); ``detector`` watches the robot's world.
        """
        return None

    def varied_points(self, task: Task) -> tuple[VariedPoint, ...]:
        """The points of ``task``'s block a scene variant moves (:mod:`executive.tasks.variation`).

        Default: none (the task names no point of the scene; its objects vary with the scene).
        """
        return ()

    def moved_objects(self, task: Task) -> tuple[str, ...]:
        """The objects this task may move (their poses are observed again afterwards)."""
        return (task.object,) if task.object else ()
