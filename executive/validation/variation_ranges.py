"""The ranges a fidelity suite draws scene variants from, and a family's ranges file.

:class:`VariationRanges` holds them (uniform draws; the defaults suit a book on a table). A scene
family whose layout must partly stay put (a glovebox's walls and ports) or whose objects are
lighter or smaller gives its own in a YAML file, read by :func:`load_ranges`: every key is
optional and has the field's meaning and unit::

    yaw_deg: 20                 # object yaw change, +- (deg)
    mass_kg: [0.1, 0.8]         # object mass (kg), low <= high
    scale: [0.8, 1.2]           # factor on each extent of an object
    friction: [0.5, 1.2]        # object sliding friction coefficient
    position_m: 0.04            # object shift along x and y, +- (m)
    obstacle_m: 0.02            # obstacle shift, +- (m) (default: position_m)
    target_m: 0.03              # shift of a task's target, +- (m) (default: position_m)
    table_height_m: 0.0         # table top height change, +- (m)
    clearance_m: 0.01           # least gap kept around objects, targets and moved obstacles (m)
    max_redraws: 200            # invalid draws tolerated per variant
    fixed: [front_wall, roof]   # bodies a variant leaves as they are (only the table moves them)
    shift_m: {seal_control: 0.02}   # a body's own shift limit, +- (m)

``executive fidelity SCENARIO`` reads ``variation/<scenario file's stem>.yaml`` beside the
scenario's file when it exists, else uses the defaults; ``--ranges FILE`` names another.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from types import MappingProxyType
from typing import Any

from executive.errors import ScenarioError
from executive.schema.yaml_nodes import Node, load_yaml_file

__all__ = ["VariationRanges", "check_names", "family_ranges_path", "load_ranges"]


@dataclass(frozen=True)
class VariationRanges:
    """The ranges variants are drawn from (uniform), and what a valid scene keeps.

    ``obstacle_m`` and ``target_m`` None: ``position_m``. ``fixed``: bodies never shifted, turned
    or resized. ``shift_m``: a body's own shift limit in place of its category's.
    """

    yaw_deg: float = 45.0  # object yaw change, +- (deg)
    mass_kg: tuple[float, float] = (0.2, 3.0)  # object mass (kg)
    scale: tuple[float, float] = (0.7, 1.3)  # factor on each extent of an object
    friction: tuple[float, float] = (0.4, 1.2)  # object sliding friction coefficient
    position_m: float = 0.10  # shift of objects along x and y, +- (m)
    table_height_m: float = 0.05  # table top height change, +- (m)
    clearance_m: float = 0.01  # least gap between an object (or its target pose) and any other body (m)
    max_redraws: int = 200  # invalid draws tolerated per variant before giving up
    obstacle_m: float | None = None  # shift of obstacles, +- (m); None: position_m
    target_m: float | None = None  # shift of a task's target, +- (m); None: position_m
    fixed: tuple[str, ...] = ()  # bodies a variant leaves as they are
    shift_m: MappingProxyType[str, float] = field(default_factory=lambda: MappingProxyType({}))

    def body_shift(self, name: str, obstacle: bool) -> float:
        """The shift limit (m) of body ``name`` (0 for a fixed one)."""
        if name in self.fixed:
            return 0.0
        if name in self.shift_m:
            return self.shift_m[name]
        if obstacle and self.obstacle_m is not None:
            return self.obstacle_m
        return self.position_m

    @property
    def target_shift(self) -> float:
        """The shift limit (m) of a task's target."""
        return self.position_m if self.target_m is None else self.target_m

    def as_dict(self) -> dict[str, Any]:
        """Plain values, for a suite's ``suite.json``."""
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["fixed"] = list(self.fixed)
        out["shift_m"] = dict(self.shift_m)
        for key in ("mass_kg", "scale", "friction"):
            out[key] = list(out[key])
        return out


def family_ranges_path(scenario_source: Path | None) -> Path | None:
    """``variation/<stem>.yaml`` beside a scenario's file, when it exists."""
    if scenario_source is None:
        return None
    path = Path(scenario_source).parent / "variation" / f"{Path(scenario_source).stem}.yaml"
    return path if path.is_file() else None


_SCALARS = {  # key: (lower bound, inclusive?)
    "yaw_deg": (0.0, True),
    "position_m": (0.0, True),
    "obstacle_m": (0.0, True),
    "target_m": (0.0, True),
    "table_height_m": (0.0, True),
    "clearance_m": (0.0, True),
}
_PAIRS = {"mass_kg": 0.0, "scale": 0.0, "friction": 0.0}  # key: exclusive lower bound


def load_ranges(path: Path | str) -> VariationRanges:
    """The ranges in the YAML file at ``path`` (keys as :class:`VariationRanges`' fields).

    Raises:
        ScenarioError: naming the file and the key: an unknown key, a value of the wrong type or
            out of its range, a pair whose low end is above its high end.
    """
    root = load_yaml_file(Path(path))
    if root.value is None:
        return VariationRanges()
    valid = [f.name for f in fields(VariationRanges)]
    root.check_keys(optional=valid)
    values: dict[str, Any] = {}
    for key, node in root.items():
        values[key] = _read(key, node)
    return VariationRanges(**values)


def _read(key: str, node: Node) -> Any:
    if key in _SCALARS:
        low, _ = _SCALARS[key]
        return node.number(ge=low)
    if key in _PAIRS:
        low, high = node.numbers(2, gt=_PAIRS[key])
        if low > high:
            node.fail(f"expected [low, high] with low <= high, got [{low:g}, {high:g}]")
        return (low, high)
    if key == "max_redraws":
        return node.integer(ge=0, le=100_000)
    if key == "fixed":
        return node.strings()
    # shift_m: body name -> limit (m)
    return MappingProxyType({name: value.number(ge=0.0) for name, value in node.items()})


def check_names(ranges: VariationRanges, bodies: list[str], scenario: str, source: str) -> None:
    """Every body ``ranges`` (read from ``source``) names in ``fixed`` and ``shift_m`` is one of
    the scene's ``bodies``.

    Raises:
        ScenarioError: naming the unknown body and the scene's bodies.
    """
    for key, names in (("fixed", ranges.fixed), ("shift_m", tuple(ranges.shift_m))):
        for name in names:
            if name not in bodies:
                raise ScenarioError(
                    source,
                    key,
                    f"no body '{name}' in {scenario}; its bodies are: {', '.join(bodies)}",
                )
