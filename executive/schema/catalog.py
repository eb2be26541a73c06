"""Registry of what ships with the package: scenarios and robots.

Bundled scenarios are ``scenarios/<name>.yaml``; bundled robots are folders
``scenarios/robots/<name>/`` holding ``profile.yaml`` (and the MJCF it names,
for robots whose model we ship). Installed, the ``scenarios/`` folder is the
package ``executive.bundled``; in a source checkout it is read in place.
"""

from __future__ import annotations

import importlib.util
from functools import cache
from pathlib import Path

from executive.errors import ScenarioError

__all__ = [
    "bundled_root",
    "list_robots",
    "list_scenarios",
    "robot_profile_path",
    "scenario_path",
]


@cache
def bundled_root() -> Path:
    """The folder holding the bundled scenarios and robots."""
    spec = importlib.util.find_spec("executive.bundled")
    if spec is not None and spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    # Source checkout not installed: the folder beside the package.
    return Path(__file__).resolve().parents[2] / "scenarios"


def list_scenarios() -> list[str]:
    """Names of the bundled scenarios, sorted."""
    return sorted(p.stem for p in bundled_root().glob("*.yaml"))


def list_robots() -> list[str]:
    """Names of the bundled robot profiles, sorted."""
    return sorted(p.parent.name for p in (bundled_root() / "robots").glob("*/profile.yaml"))


def scenario_path(name_or_path: str | Path) -> Path:
    """Resolve a scenario given as a file path or as a bundled scenario's name."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists():
        if not candidate.is_file():
            raise ScenarioError(str(candidate), "", "no such scenario file")
        return candidate.resolve()
    names = list_scenarios()
    if str(name_or_path) in names:
        return bundled_root() / f"{name_or_path}.yaml"
    raise ScenarioError(
        str(name_or_path),
        "",
        f"not a file and not a bundled scenario; bundled scenarios are: {', '.join(names) or '(none)'}",
    )


def robot_profile_path(name: str) -> Path | None:
    """The profile file of a bundled robot, or None if there is no such robot."""
    path = bundled_root() / "robots" / name / "profile.yaml"
    return path if path.is_file() else None
