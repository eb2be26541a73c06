"""The project's exception hierarchy: one root, one subclass per concern.

Every message names what is wrong and where (file, key path, name), what was
expected and what was found, and lists the valid choices where there are some.
"""

from __future__ import annotations

__all__ = [
    "ExecutiveError",
    "RobotProfileError",
    "ScenarioError",
    "WorldError",
]


class ExecutiveError(Exception):
    """Root of every error this project raises on purpose."""


class ScenarioError(ExecutiveError):
    """A scenario file is malformed: bad YAML, a wrong type, a missing key, an impossible value.

    Attributes:
        source: the file the error is in (or ``"<string>"``).
        key_path: where in the document, e.g. ``scene.objects[1].size`` ("" for the root).
        problem: what is wrong, in words.
    """

    def __init__(self, source: str, key_path: str, problem: str) -> None:
        self.source = source
        self.key_path = key_path
        self.problem = problem
        where = f"{source}: {key_path}" if key_path else source
        super().__init__(f"{where}: {problem}")


class RobotProfileError(ScenarioError):
    """A robot profile is malformed or does not match its MJCF model."""


class WorldError(ExecutiveError):
    """The MuJoCo world could not be built from a (valid) scenario."""
