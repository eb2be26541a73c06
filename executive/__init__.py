"""A behaviour-tree task executive with risk gating for humanoid robots."""

import os

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

__all__ = ["ExecutiveError", "RobotProfileError", "ScenarioError", "WorldError"]
__version__ = "0.1.0"
