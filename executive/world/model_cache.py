"""A per-process cache of the robot models that worlds are built from.

:func:`executive.world.model.build` starts every world from the robot's MJCF. Two parts of
that are the same for every world of a robot and are kept here, per process, for the few
robots most recently used (:data:`CAPACITY`):

- the parsed robot (:func:`robot_spec`): the ``mujoco.MjSpec`` read from the MJCF, never
  compiled itself; every build edits its own ``spec.copy()``;
- the robot's mass properties that a truth world's CoM offset needs (:func:`torso_inertia`),
  which otherwise cost an extra compile of the whole robot per truth world.

The processed meshes themselves are kept by MuJoCo's own asset cache (``mujoco.mj_getCache``,
per process, checked against each file's modification time): a robot's meshes are decoded once
per process while that cache has room. An entry here is keyed by the MJCF's resolved path and
is used only while the modification time and size of the MJCF, of the files it includes and of
every mesh, texture and height field it names are those it was read with; otherwise the robot
is read again. Worker processes (spawned) each fill their own cache on their first build.

:func:`disabled` turns the cache off for a measurement or a test (every build then parses the
MJCF and probes the masses as if nothing were cached); worlds are the same either way.
"""

from __future__ import annotations

import threading
import xml.etree.ElementTree as ET
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

__all__ = ["CAPACITY", "TorsoInertia", "clear", "disabled", "robot_spec", "size", "torso_inertia"]

#: Robots kept per process (least recently used dropped first).
CAPACITY = 4

Stamp = tuple[tuple[str, int, int], ...]


@dataclass(frozen=True)
class TorsoInertia:
    """What moving the torso's CoM needs: the robot's total mass and the torso's own inertial.

    ``total_mass`` (kg) is the subtree mass of the base body; ``mass`` (kg), ``inertia``
    (diagonal, kg m^2), ``ipos`` (m) and ``iquat`` (w x y z) are the torso body's.
    """

    total_mass: float
    mass: float
    inertia: NDArray[np.float64]
    ipos: NDArray[np.float64]
    iquat: NDArray[np.float64]


@dataclass
class _Entry:
    files: list[str]
    stamp: Stamp
    spec: mujoco.MjSpec
    inertia: dict[tuple[str, str], TorsoInertia] = field(default_factory=dict)


_lock = threading.Lock()
_entries: OrderedDict[str, _Entry] = OrderedDict()
_state = {"enabled": True}


@contextmanager
def disabled() -> Iterator[None]:
    """Within the block, build every world without the cache (for measurements and tests).

    Example::

        with model_cache.disabled():
            world = build(scenario)  # parses the MJCF, compiles the robot for its masses
    """
    before = _state["enabled"]
    _state["enabled"] = False
    try:
        yield
    finally:
        _state["enabled"] = before


def clear() -> None:
    """Forget every cached robot of this process."""
    with _lock:
        _entries.clear()


def size() -> int:
    """How many robots this process has cached."""
    return len(_entries)


def robot_spec(mjcf: Path | str) -> mujoco.MjSpec:
    """An editable robot spec of ``mjcf``: a copy of the cached parse, else a fresh one.

    Args:
        mjcf: path of the robot's MJCF file.

    Returns:
        A ``mujoco.MjSpec`` the caller owns (edit and compile it freely).

    Raises:
        ValueError: MuJoCo's parser error (the caller names the file in its message).
    """
    if not _state["enabled"]:
        return mujoco.MjSpec.from_file(str(mjcf))
    entry = _entry(mjcf)
    with _lock:
        return entry.spec.copy()


def torso_inertia(
    mjcf: Path | str, base_body: str, torso_body: str, probe: Callable[[], mujoco.MjModel]
) -> TorsoInertia:
    """The robot's total mass and the torso's inertial, computed once per robot.

    Args:
        mjcf: path of the robot's MJCF file (the cache key, as for :func:`robot_spec`).
        base_body: the profile's base body (root of the robot's tree).
        torso_body: the profile's torso body.
        probe: compiles the robot (a spec made by :func:`robot_spec`, bodies and masses as in
            the file); called on the first request for this robot, or every time while the
            cache is :func:`disabled`.

    Returns:
        The mass properties of the compiled robot.
    """
    if not _state["enabled"]:
        return _inertia_of(probe(), base_body, torso_body)
    entry = _entry(mjcf)
    key = (base_body, torso_body)
    found = entry.inertia.get(key)
    if found is None:
        found = _inertia_of(probe(), base_body, torso_body)
        with _lock:
            entry.inertia[key] = found
    return found


def _inertia_of(model: mujoco.MjModel, base_body: str, torso_body: str) -> TorsoInertia:
    torso = model.body(torso_body).id
    return TorsoInertia(
        total_mass=float(model.body_subtreemass[model.body(base_body).id]),
        mass=float(model.body_mass[torso]),
        inertia=np.array(model.body_inertia[torso], dtype=float),
        ipos=np.array(model.body_ipos[torso], dtype=float),
        iquat=np.array(model.body_iquat[torso], dtype=float),
    )


def _entry(mjcf: Path | str) -> _Entry:
    """The cache entry of ``mjcf``, read (again) when absent or when a file it uses changed."""
    path = str(Path(mjcf).expanduser().resolve())
    with _lock:
        entry = _entries.get(path)
        if entry is not None and entry.stamp == _stamp(entry.files):
            _entries.move_to_end(path)
            return entry
    before = _stat(path)
    spec = mujoco.MjSpec.from_file(path)
    files = _files(path, spec)
    entry = _Entry(files, _stamp(files), spec)
    if entry.stamp[0][1:] != before:  # written while being read: use it, keep nothing
        return entry
    with _lock:
        _entries[path] = entry
        _entries.move_to_end(path)
        while len(_entries) > CAPACITY:
            _entries.popitem(last=False)
    return entry


def _stamp(files: list[str]) -> Stamp:
    """(file, mtime_ns, size) of each file (-1, -1 for a missing one)."""
    return tuple((f, *_stat(f)) for f in files)


def _stat(path: str) -> tuple[int, int]:
    try:
        st = Path(path).stat()
    except OSError:
        return (-1, -1)
    return (st.st_mtime_ns, st.st_size)


def _files(path: str, spec: mujoco.MjSpec) -> list[str]:
    """The MJCF, the files it includes and the asset files its spec names."""
    root = Path(path).parent
    files = [path, *_includes(Path(path), root, depth=0)]
    folders = (
        (spec.meshdir, [m.file for m in spec.meshes]),
        (spec.texturedir, [t.file for t in spec.textures]),
        (spec.meshdir, [h.file for h in spec.hfields]),
        (spec.meshdir, [s.file for s in spec.skins]),
    )
    for folder, names in folders:
        base = root / folder if folder else root
        files.extend(str(base / name) for name in names if name)
    return files


def _includes(xml: Path, root: Path, depth: int) -> list[str]:
    """Files ``<include>``-d by ``xml`` (recursively; relative to the main model's folder)."""
    if depth > 8:
        return []
    try:
        tree = ET.parse(xml)
    except (OSError, ET.ParseError):
        return []
    found: list[str] = []
    for node in tree.iter("include"):
        name = node.get("file")
        if name:
            child = root / name
            found.append(str(child))
            found.extend(_includes(child, root, depth + 1))
    return found
