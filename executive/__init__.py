"""A behaviour-tree task executive with risk gating for humanoid robots."""

from executive.errors import ExecutiveError, RobotProfileError, ScenarioError, WorldError

__all__ = ["ExecutiveError", "RobotProfileError", "ScenarioError", "WorldError"]
__version__ = "0.1.0"
