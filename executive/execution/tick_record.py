"""The run's per-tick record: the robot's state, the tree's statuses and the guards' values, every tick.

A run folder (``executive run --out DIR``, ``Executive(out=DIR)``) gets a ``record/`` folder
written by :class:`TickRecorder` (an ``Executive.tick_listeners`` entry): ``header.json`` (how to
read the frames and rebuild the world), ``frames.bin`` (one fixed-size frame per tick: time,
guard values, ``qpos``) and ``events.jsonl`` (tree, status and phase changes). Every frame and
line is one unbuffered append, so a killed run keeps every tick before the kill; at most one cut
frame or line at the end, which :func:`load_record` drops.

Reading: ``record = load_record(run_dir)`` gives a :class:`Record` (arrays per frame,
``object_pose``, ``frame_at``, ``statuses_at``, ``phases``). docs/replay.md has the file format.
"""

from __future__ import annotations

import bisect
import json
import math
import operator
import os
import struct
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, cast

import mujoco
import numpy as np
import py_trees
from numpy.typing import NDArray

from behaviours.guard import RiskGuard
from executive.errors import ExecutiveError

__all__ = [
    "FORMAT",
    "STATUS_CODES",
    "Record",
    "RecordError",
    "TickRecorder",
    "TreeNode",
    "frame_dtype",
    "load_record",
    "preorder",
]

FORMAT = "executive-tick-record/1"
FOLDER = "record"
HEADER, FRAMES, EVENTS = "header.json", "frames.bin", "events.jsonl"
Status = py_trees.common.Status
#: Status codes of the ``status`` events.
STATUS_CODES: dict[Status, int] = {Status.INVALID: 0, Status.RUNNING: 1, Status.SUCCESS: 2, Status.FAILURE: 3}
STATUS_NAMES = {code: status.value for status, code in STATUS_CODES.items()}
FloatArray = NDArray[np.float64]


class RecordError(ExecutiveError):
    """A run folder without a readable record: the file and what is wrong with it."""


_STATUS = operator.attrgetter("status")
#: The fields of a frame before its qpos, packed as :func:`frame_dtype` lays them out.
_FIELDS = struct.Struct("<Idfffhb")


def frame_dtype(nq: int) -> np.dtype[Any]:
    """The layout of one frame of ``frames.bin`` for a model with ``nq`` qpos entries (packed)."""
    return np.dtype(
        [
            ("tick", "<u4"),
            ("time", "<f8"),
            ("wall", "<f4"),
            ("clearance", "<f4"),
            ("com_margin", "<f4"),
            ("guard", "<i2"),
            ("guard_ok", "i1"),
            ("qpos", "<f4", (nq,)),
        ]
    )


def _dtype_text(dtype: np.dtype[Any]) -> list[list[Any]]:
    assert dtype.fields is not None
    out = []
    for name in dtype.names or ():
        sub = dtype.fields[name][0]
        base, shape = (sub.base, list(sub.shape)) if sub.shape else (sub, [])
        out.append([name, base.str, shape])
    return out


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def _joints(model: mujoco.MjModel) -> list[list[Any]]:
    """Every joint as ``[name, type, qpos address]`` (type: free ball slide hinge)."""
    types = {0: "free", 1: "ball", 2: "slide", 3: "hinge"}
    return [
        [model.joint(j).name, types[int(model.jnt_type[j])], int(model.jnt_qposadr[j])]
        for j in range(model.njnt)
    ]


def preorder(root: py_trees.behaviour.Behaviour) -> list[py_trees.behaviour.Behaviour]:
    """The nodes of the tree under ``root``, each before its children (as py_trees' displays list them)."""
    out, stack = [], [root]
    while stack:
        node = stack.pop()
        out.append(node)
        stack.extend(reversed(node.children))
    return out


def truth_of(executive: Any, truth: str | int | None) -> str | int | None:
    """How the replay rebuilds the recorded world: ``"exact"``, the truth's seed, or None (a host's)."""
    if not executive.owns_physics:
        return None
    if truth == "exact":
        return "exact"
    return executive.scenario.trials.seed if truth is None else int(truth)


class TickRecorder:
    """Appends a frame (and the events of the tick) to the run folder's record after every tick.

    Use: ``executive.tick_listeners.append(TickRecorder(folder, executive, truth=...))``
    (the :class:`executive.runtime.mission.Executive` does so for every run folder). The
    constructor writes the header and the state before the first tick.

    Args:
        folder: the run folder (``record/`` is made in it).
        executive: the executive whose ``robot``, ``root``, ``selectors`` are read.
        truth: the executive's ``truth`` argument (``"exact"``, a seed or None: ``trials.seed``).
    """

    def __init__(self, folder: Path | str, executive: Any, *, truth: str | int | None = None) -> None:
        self.folder = Path(folder) / FOLDER
        self.folder.mkdir(parents=True, exist_ok=True)
        robot = executive.robot
        data = robot.data
        model = executive.truth.model if executive.owns_physics else executive.estimate.model
        self.nq = int(model.nq)
        self._qpos = data.qpos
        self._robot = robot
        self._root: py_trees.behaviour.Behaviour = executive.root
        self._selectors = list(executive.selectors)
        self._frame = np.zeros(1, dtype=frame_dtype(self.nq))
        self._q = np.zeros(self.nq, dtype="<f4")
        self.frames = self._existing_frames()
        self._write_header(executive, model, truth)
        self._frames: BinaryIO = open(self.folder / FRAMES, "ab", buffering=0)
        self._events: BinaryIO = open(self.folder / EVENTS, "ab", buffering=0)
        self._t0 = time.perf_counter()
        self._nodes: list[py_trees.behaviour.Behaviour] = []
        self._statuses: list[Status] = []
        self._shape: list[int] | None = None  # the selectors' children, by id: None before the first look
        self._index: dict[int, int] = {}  # id(node) -> its index
        self._path: list[py_trees.behaviour.Behaviour] = []  # the running path of the last tick
        self._path_index: list[int] = []
        self._path_guards: list[tuple[int, py_trees.behaviour.Behaviour]] = []  # (index, guard) on it
        self._parallel = False  # the running path goes through a Parallel
        self._verdicts: dict[int, Any] = {}  # guard's node index -> its last verdict seen
        self._phases: list[str] = ["" for _ in self._selectors]
        self.closed = False
        self._event({"k": "start", "run_id": executive.log.run_id, "tick": executive.ticks})
        self(executive)

    def _existing_frames(self) -> int:
        """Frames already in the folder (a resumed run appends to its record)."""
        path = self.folder / FRAMES
        return path.stat().st_size // self._frame.itemsize if path.exists() else 0

    def _write_header(self, executive: Any, model: mujoco.MjModel, truth: str | int | None) -> None:
        path = self.folder / HEADER
        if path.exists():
            return
        sc = executive.scenario
        world = executive.truth if executive.owns_physics else executive.estimate
        header = {
            "format": FORMAT,
            "run_id": executive.log.run_id,
            "scenario": sc.name,
            "source": str(sc.source),
            "world": "truth" if executive.owns_physics else "estimate",
            "truth": truth_of(executive, truth),
            "control_dt": float(getattr(self._robot, "control_dt", math.nan)),
            "nq": self.nq,
            "joints": _joints(model),
            "objects": {name: int(adr) for name, adr in world.ids.object_qpos.items()},
            "dtype": _dtype_text(self._frame.dtype),
            "frame_bytes": self._frame.itemsize,
            "status_codes": {str(c): n for c, n in STATUS_NAMES.items()},
        }
        _write_atomic(path, json.dumps(header, indent=1) + "\n")

    def _event(self, fields: dict[str, Any]) -> None:
        fields["frame"] = self.frames
        self._events.write((json.dumps(fields, separators=(",", ":")) + "\n").encode())

    def _restructure(self) -> None:
        """The tree's nodes changed (alternatives swapped in): a ``tree`` event and every status."""
        nodes = preorder(self._root)
        self._index = {id(n): i for i, n in enumerate(nodes)}
        layout = [
            [n.name, type(n).__name__, self._index[id(n.parent)] if n.parent is not None else -1]
            for n in nodes
        ]
        self._nodes = nodes
        self._statuses = [n.status for n in nodes]
        self._verdicts = {i: n.last_verdict for i, n in enumerate(nodes) if isinstance(n, RiskGuard)}
        self._path = []
        self._event({"k": "tree", "nodes": layout})
        changed = [[i, STATUS_CODES[s]] for i, s in enumerate(self._statuses) if s != Status.INVALID]
        self._event({"k": "status", "s": changed})

    def _running_path(self) -> list[py_trees.behaviour.Behaviour]:
        """The root, then each composite's current child and each decorator's child, down to a leaf."""
        path = []
        node: Any = self._root
        while node is not None:
            path.append(node)
            child = getattr(node, "current_child", None)
            node = child if child is not None else getattr(node, "decorated", None)
        return path

    def _scan(self) -> None:
        """Statuses that changed this tick (a ``status`` event), and the path's guards.

        A node's status changes only when it is ticked or stopped. While the running path
        (:meth:`_running_path`) is the one of the previous tick, only its nodes were ticked and
        none was stopped (the tree's composites are memory Sequences and the RiskSelectors,
        which tick their current child only), so only they are compared; a tick that changed
        the path, a path through a Parallel, and every 64th frame compare every node.
        """
        path = self._running_path()
        if path != self._path or self.frames % 64 == 0 or self._parallel:
            self._path = path
            self._path_index = index = [self._index[id(n)] for n in path]
            self._path_guards = [(i, n) for i, n in zip(index, path, strict=True) if i in self._verdicts]
            self._parallel = any(isinstance(n, py_trees.composites.Parallel) for n in path)
            statuses = list(map(_STATUS, self._nodes))
            changed = [
                [i, STATUS_CODES[s]]
                for i, (s, old) in enumerate(zip(statuses, self._statuses, strict=True))
                if s is not old
            ]
            self._statuses = statuses
        else:
            changed = []
            for i, node in zip(self._path_index, path, strict=True):
                status = node.status
                if status is not self._statuses[i]:
                    self._statuses[i] = status
                    changed.append([i, STATUS_CODES[status]])
        if changed:
            self._event({"k": "status", "s": changed})

    def __call__(self, executive: Any) -> None:
        """Record the tick that just ended (an ``Executive.tick_listeners`` entry)."""
        if self.closed:
            return
        shape = [id(c) for s in self._selectors for c in s.children]
        if shape != self._shape:
            self._shape = shape
            self._restructure()
        self._scan()
        phases = [s.phase for s in self._selectors]
        if phases != self._phases:
            self._phase_events(phases)
        ending = executive.status != Status.RUNNING and executive.ticks > 0
        if ending:
            self._event({"k": "end", "status": executive.status.value, "tick": executive.ticks})
        self._write_frame(executive.ticks)
        if ending:
            self.close()

    def _phase_events(self, phases: list[str]) -> None:
        for selector, phase, old in zip(self._selectors, phases, self._phases, strict=True):
            if phase != old:
                alternative = selector.chosen if phase == "executing" else None
                self._event({"k": "phase", "task": selector.name, "phase": phase, "alternative": alternative})
        self._phases = phases

    def _write_frame(self, tick: int) -> None:
        """One frame: the fields before ``qpos`` packed by :data:`_FIELDS`, then qpos as float32."""
        guard, ok, clearance, com = -1, -1, math.nan, math.nan
        verdicts = self._verdicts
        for i, node in self._path_guards:  # a guard checks only when ticked: on the running path
            verdict = cast(RiskGuard, node).last_verdict
            if verdict is not verdicts[i]:  # it checked this tick
                verdicts[i] = verdict
                guard, ok, clearance = i, 1 if verdict.ok else 0, verdict.min_distance
                com = math.nan if verdict.com_margin is None else verdict.com_margin
        wall = time.perf_counter() - self._t0
        head = _FIELDS.pack(tick, self._robot.time, wall, clearance, com, guard, ok)
        self._q[:] = self._qpos
        self._frames.write(head + self._q.tobytes())
        self.frames += 1

    def close(self) -> None:
        """Flush the files to disk and close them (the last tick does; later ticks record nothing)."""
        if self.closed:
            return
        self.closed = True
        for f in (self._frames, self._events):
            os.fsync(f.fileno())
            f.close()


# --- reading ------------------------------------------------------------------------------


@dataclass(frozen=True)
class TreeNode:
    """One node of the recorded tree: its name, py_trees class name and parent's index (-1: root)."""

    name: str
    kind: str
    parent: int


@dataclass(frozen=True)
class _Layout:
    frame: int
    nodes: tuple[TreeNode, ...]


@dataclass
class Record:
    """A run's per-tick record, as :func:`load_record` reads it (F frames).

    Attributes:
        folder: the ``record/`` folder.
        header: ``header.json`` (scenario, source, world, truth, nq, joints, objects, ...).
        ticks, times, wall: (F,) tick number, robot time (s), wall time since the start (s).
        qpos: (F, nq) the recorded world's qpos (robot and objects' free joints), float64.
        clearance, com_margin: (F,) the guard's values (m; NaN: no guard check that tick).
        guard, guard_ok: (F,) checking guard's node index (-1 none); 1 ok, 0 tripped, -1 none.
        events: every line of ``events.jsonl`` (dicts with ``k`` and ``frame``).
        complete: the record has its ``end`` event (False: the run was killed or stopped).
    """

    folder: Path
    header: dict[str, Any]
    ticks: NDArray[np.int64]
    times: FloatArray
    wall: FloatArray
    qpos: FloatArray
    clearance: FloatArray
    com_margin: FloatArray
    guard: NDArray[np.int64]
    guard_ok: NDArray[np.int64]
    events: list[dict[str, Any]]
    complete: bool
    _layouts: list[_Layout] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._layouts = [
            _Layout(int(e["frame"]), tuple(TreeNode(str(n), str(k), int(p)) for n, k, p in e["nodes"]))
            for e in self.events
            if e["k"] == "tree"
        ]

    def __len__(self) -> int:
        return len(self.times)

    @property
    def duration(self) -> float:
        """Robot time from the first frame to the last (s)."""
        return float(self.times[-1] - self.times[0]) if len(self) else 0.0

    def frame_at(self, t: float) -> int:
        """The last frame at or before robot time ``t`` (clamped to the record)."""
        return max(0, min(len(self) - 1, int(np.searchsorted(self.times, t, side="right")) - 1))

    def object_pose(self, frame: int, name: str) -> tuple[FloatArray, FloatArray]:
        """An object's position (3,) and quaternion (4, wxyz) at ``frame``, from its free joint."""
        objects = self.header["objects"]
        if name not in objects:
            raise RecordError(f"{self.folder / HEADER}: no object '{name}' (objects: {', '.join(objects)})")
        adr = int(objects[name])
        q = self.qpos[frame]
        return q[adr : adr + 3].copy(), q[adr + 3 : adr + 7].copy()

    def tree_at(self, frame: int) -> tuple[TreeNode, ...]:
        """The tree's nodes at ``frame`` (each before its children), as last swapped in before it."""
        layout = self._layout(frame)
        return layout.nodes if layout is not None else ()

    def _layout(self, frame: int) -> _Layout | None:
        starts = [lay.frame for lay in self._layouts]
        i = bisect.bisect_right(starts, frame) - 1
        return self._layouts[i] if i >= 0 else None

    def statuses_at(self, frame: int) -> list[tuple[TreeNode, str]]:
        """Every node of the tree at ``frame`` with its status then (``INVALID``, ``RUNNING``, ...)."""
        layout = self._layout(frame)
        if layout is None:
            return []
        codes = [0] * len(layout.nodes)
        for event in self.events:
            if event["k"] != "status" or not layout.frame <= event["frame"] <= frame:
                continue
            for i, code in event["s"]:
                if i < len(codes):
                    codes[i] = int(code)
        return [(node, STATUS_NAMES[c]) for node, c in zip(layout.nodes, codes, strict=True)]

    @property
    def phases(self) -> list[dict[str, Any]]:
        """The ``phase`` events (``task``, ``phase``, ``alternative``, ``frame``), in order."""
        return [e for e in self.events if e["k"] == "phase"]


def _read_header(folder: Path) -> dict[str, Any]:
    path = folder / HEADER
    if not folder.parent.is_dir():
        raise RecordError(f"{folder.parent}: no such run folder")
    if not path.is_file():
        raise RecordError(
            f"{path}: missing: {folder.parent} holds no per-tick record (a run folder written by "
            "`executive run` or Executive(out=...) has one)"
        )
    try:
        header = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RecordError(f"{path}: not a readable record header ({exc})") from None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        found = header.get("format") if isinstance(header, dict) else type(header).__name__
        raise RecordError(f"{path}: format: expected '{FORMAT}', found {found!r}")
    for key in ("nq", "objects", "frame_bytes", "scenario", "source", "world"):
        if key not in header:
            raise RecordError(f"{path}: {key}: missing")
    checks: list[tuple[str, Callable[[Any], bool]]] = [  # in order: later ones rely on earlier ones
        ("nq", lambda v: _whole(v) and v >= 1),
        ("frame_bytes", _whole),
        (
            "objects",
            lambda v: isinstance(v, dict) and all(_whole(a) and 0 <= a < header["nq"] for a in v.values()),
        ),
        ("world", lambda v: v in ("truth", "estimate")),
        ("truth", lambda v: v in (None, "exact") or _whole(v)),
    ]
    for key, good in checks:
        if not good(header.get(key)):
            raise RecordError(f"{path}: {key}: unexpected value {header.get(key)!r}")
    return header


def _whole(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _event_problem(event: Any) -> str | None:
    """What is wrong with one parsed event line (None: nothing)."""
    if not isinstance(event, dict) or not isinstance(event.get("k"), str) or not _whole(event.get("frame")):
        return "not an event (an object with 'k' and a whole 'frame')"
    if event["k"] == "tree":
        nodes = event.get("nodes")
        if not isinstance(nodes, list) or not all(
            isinstance(n, list) and len(n) == 3 and _whole(n[2]) and -1 <= n[2] < len(nodes) for n in nodes
        ):
            return "tree: nodes: expected [name, class, parent index] lists"
    if event["k"] == "status":
        pairs = event.get("s")
        if not isinstance(pairs, list) or not all(
            isinstance(p, list) and len(p) == 2 and _whole(p[0]) and p[1] in STATUS_NAMES for p in pairs
        ):
            return "status: s: expected [node index, status code 0-3] pairs"
    return None


def _read_events(path: Path) -> list[dict[str, Any]]:
    """The event lines; a cut last line (a killed run) is dropped, a bad line before it is an error."""
    if not path.is_file():
        raise RecordError(f"{path}: missing")
    lines = path.read_bytes().split(b"\n")
    events = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            event = json.loads(line)
            problem = _event_problem(event)
            if problem is not None:
                raise ValueError(problem)
        except ValueError as exc:
            if number == len(lines):  # no newline after it: cut by a kill
                break
            raise RecordError(f"{path}: line {number}: {exc}") from None
        events.append(event)
    return events


def load_record(run_dir: Path | str) -> Record:
    """Read the per-tick record of a run folder (what :class:`TickRecorder` wrote).

    A run killed mid-write leaves at most one cut frame and one cut line at the end: both are
    dropped, and the record is every tick before. Events that name a frame past the last whole
    one are dropped too.

    Args:
        run_dir: the run folder (``executive run --out DIR``), or its ``record/`` folder.

    Returns:
        The :class:`Record`.

    Raises:
        RecordError: no such folder, no record in it, or a header, frame file or event line
            that cannot be read (the file and what is wrong).
    """
    run_dir = Path(run_dir)
    folder = run_dir if run_dir.name == FOLDER and (run_dir / HEADER).exists() else run_dir / FOLDER
    header = _read_header(folder)
    dtype = frame_dtype(int(header["nq"]))
    frames_path = folder / FRAMES
    if dtype.itemsize != header["frame_bytes"]:
        raise RecordError(
            f"{folder / HEADER}: frame_bytes {header['frame_bytes']} does not match nq {header['nq']} "
            f"({dtype.itemsize} bytes a frame): a record of another format version"
        )
    try:
        raw = frames_path.read_bytes()
    except OSError as exc:
        raise RecordError(f"{frames_path}: cannot be read ({exc.strerror or exc})") from None
    frames = np.frombuffer(raw, dtype=dtype, count=len(raw) // dtype.itemsize)
    if not len(frames):
        raise RecordError(f"{frames_path}: no whole frame (the run stopped before its first tick)")
    events = [e for e in _read_events(folder / EVENTS) if int(e["frame"]) < len(frames)]
    return Record(
        folder=folder,
        header=header,
        ticks=frames["tick"].astype(np.int64),
        times=frames["time"].astype(np.float64),
        wall=frames["wall"].astype(np.float64),
        qpos=frames["qpos"].astype(np.float64),
        clearance=frames["clearance"].astype(np.float64),
        com_margin=frames["com_margin"].astype(np.float64),
        guard=frames["guard"].astype(np.int64),
        guard_ok=frames["guard_ok"].astype(np.int64),
        events=events,
        complete=any(e["k"] == "end" for e in events),
    )
