"""A behaviour-tree task executive with risk gating for humanoid robots.

What an integrator needs is importable from here::

    from executive import Executive, HostChannel, load

    executive = Executive(load("book_transfer"), approval=HostChannel("cell"), truth="exact")

* running a mission: :class:`Executive`, :func:`freeze_startup_heap`; scenarios:
  :func:`load` (a file or a bundled name), :func:`loads`, :func:`from_dict` (their
  ``allow_modules=`` names the modules a scenario's ``kind: module:Class`` may import);
* the robot: :class:`RobotInterface` (what the executive uses of a robot), :class:`HostRobot`
  (a host's own robot behind :class:`JointIO`);
* approvals: :class:`HostChannel`, :class:`CallbackChannel`, :class:`PolicyChannel`,
  :class:`TerminalChannel`, :func:`make_channel`, and the :class:`ApprovalRequest` /
  :class:`ApprovalDecision` they exchange;
* task kinds: :class:`TaskKind`, :class:`Task`, :class:`Alternative`, :func:`register`
  (see docs/task_kinds.md);
* errors: :class:`ExecutiveError` and its subclasses.

Everything but the errors is imported on first use (PEP 562 module ``__getattr__``), so
``import executive`` stays light and the subpackages can import this package freely.
"""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any

# MuJoCo picks its OpenGL backend when it is first imported. With no display,
# GLFW cannot make a context: default to EGL (works headless on Mesa, CPU).
if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

from executive.errors import (
    ExecutiveError,
    RobotProfileError,
    ScenarioError,
    WorldError,
)

if TYPE_CHECKING:
    from executive.decision.approval import (
        ApprovalChannel,
        ApprovalDecision,
        ApprovalRequest,
        CallbackChannel,
        HostChannel,
        PolicyChannel,
        TerminalChannel,
        make_channel,
    )
    from executive.execution.robot_interface import HostRobot, JointIO, RobotInterface
    from executive.planning.types import PlanningError
    from executive.runtime.mission import Executive, freeze_startup_heap
    from executive.scenario.loader import from_dict, load, loads
    from executive.tasks.base import Alternative, Task, TaskKind
    from executive.tasks.registry import TaskKindError, register

#: Each lazily imported name and the module it comes from.
_LAZY: dict[str, str] = {
    "Executive": "executive.runtime.mission",
    "freeze_startup_heap": "executive.runtime.mission",
    "load": "executive.scenario.loader",
    "loads": "executive.scenario.loader",
    "from_dict": "executive.scenario.loader",
    "RobotInterface": "executive.execution.robot_interface",
    "HostRobot": "executive.execution.robot_interface",
    "JointIO": "executive.execution.robot_interface",
    "ApprovalChannel": "executive.decision.approval",
    "ApprovalDecision": "executive.decision.approval",
    "ApprovalRequest": "executive.decision.approval",
    "CallbackChannel": "executive.decision.approval",
    "HostChannel": "executive.decision.approval",
    "PolicyChannel": "executive.decision.approval",
    "TerminalChannel": "executive.decision.approval",
    "make_channel": "executive.decision.approval",
    "Alternative": "executive.tasks.base",
    "Task": "executive.tasks.base",
    "TaskKind": "executive.tasks.base",
    "register": "executive.tasks.registry",
    "TaskKindError": "executive.tasks.registry",
    "PlanningError": "executive.planning.types",
}

__all__ = [
    "Alternative",
    "ApprovalChannel",
    "ApprovalDecision",
    "ApprovalRequest",
    "CallbackChannel",
    "Executive",
    "ExecutiveError",
    "HostChannel",
    "HostRobot",
    "JointIO",
    "PlanningError",
    "PolicyChannel",
    "RobotInterface",
    "RobotProfileError",
    "ScenarioError",
    "Task",
    "TaskKind",
    "TaskKindError",
    "TerminalChannel",
    "WorldError",
    "freeze_startup_heap",
    "from_dict",
    "load",
    "loads",
    "make_channel",
    "register",
]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'executive' has no attribute '{name}'")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # the next access does not come here
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
