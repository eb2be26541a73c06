"""Playing a run's per-tick record back: its world rebuilt, a video rendered offscreen, a summary per phase.

``executive replay RUN_DIR [--video FILE]`` reads the record
(:func:`executive.execution.tick_record.load_record`), rebuilds the world the frames are of
(:func:`rebuild_world`: the scenario's truth with the run's seed, or the estimate itself for an
exact run or a host's robot), and either prints :func:`phase_summary` or renders
:func:`render_video`: each video frame is the recorded qpos of the last tick at or before its
time, put into the rebuilt world (``mj_forward``) and drawn by ``mujoco.Renderer`` from the
overview camera of ``executive show``. MP4 (and MKV, AVI, MOV) are encoded as H.264 by
imageio-ffmpeg (``pip install ".[video]"``: the wheel ships an ffmpeg binary); an animated GIF
is written with Pillow and needs nothing more.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.execution.tick_record import HEADER, Record, RecordError, TreeNode
from executive.report.render import overview_camera
from executive.schema.types import Scenario
from executive.world.model import World, build, sample_perturbation

__all__ = [
    "FFMPEG_SUFFIXES",
    "StepSpan",
    "encoder",
    "make_renderer",
    "phase_summary",
    "rebuild_world",
    "render_video",
    "step_spans",
    "video_frames",
]

#: Containers written through imageio-ffmpeg, all as H.264 (libx264).
FFMPEG_SUFFIXES = (".mp4", ".mkv", ".avi", ".mov")
_INSTALL = 'pip install ".[video]" (or: pip install imageio-ffmpeg)'


def _scenario_of(record: Record, scenario: Scenario | str | Path | None) -> Scenario:
    from executive.scenario import load

    if isinstance(scenario, Scenario):
        return scenario
    source = scenario if scenario is not None else record.header["source"]
    if scenario is None and not Path(str(source)).is_file():
        raise RecordError(
            f"{record.folder / HEADER}: source: the run's scenario {source!r} is not a file here "
            "(a scenario built in code, or moved); give it with --scenario FILE"
        )
    return load(str(source))


def rebuild_world(record: Record, scenario: Scenario | str | Path | None = None) -> World:
    """The world the record's frames are of, built afresh as the run built it.

    ``truth`` ``"exact"`` (or a host's robot's record: the estimate) is the scenario's world
    itself; a seed rebuilds the truth sampled with it (``sample_perturbation`` from
    ``np.random.default_rng(seed)``, as :class:`executive.runtime.mission.Executive` does).

    Args:
        record: the record.
        scenario: the scenario (or its file) to use instead of the header's ``source``.

    Raises:
        RecordError: the scenario cannot be found, or its model is not the recorded one
            (another nq or other joints: the scenario or robot changed since the run).
    """
    sc = _scenario_of(record, scenario)
    truth = record.header.get("truth")
    if record.header["world"] == "truth" and truth not in (None, "exact"):
        world = build(sc, sample_perturbation(sc, np.random.default_rng(int(truth))), kind="truth")
    else:
        world = build(sc)
    model = world.model
    joints = [model.joint(j).name for j in range(model.njnt)]
    recorded = [j[0] for j in record.header.get("joints", [])]
    if model.nq != record.header["nq"] or (recorded and joints != recorded):
        raise RecordError(
            f"{record.folder / HEADER}: the scenario {sc.source} now builds a model with nq={model.nq} "
            f"and {len(joints)} joints, the run's had nq={record.header['nq']} and {len(recorded)}: "
            "the scenario or its robot changed since the run"
        )
    return world


def make_renderer(world: World, width: int, height: int, *, shadows: bool = False) -> mujoco.Renderer:
    """An offscreen ``mujoco.Renderer`` of ``world``; without ``shadows``, no shadows or reflections.

    Rendered on the CPU (EGL with Mesa's llvmpipe) shadows and reflections take most of a frame's
    time (docs/replay.md); the replay leaves them out unless asked.

    Raises:
        ExecutiveError: no OpenGL context (with how to get one).
    """
    try:
        renderer = mujoco.Renderer(world.model, height=height, width=width)
    except Exception as exc:  # no OpenGL context: say how to get one
        raise ExecutiveError(
            f"offscreen rendering failed ({exc}); on a headless machine set MUJOCO_GL=egl (or osmesa)"
        ) from exc
    if not shadows:
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
        renderer.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    return renderer


def video_frames(record: Record, fps: float) -> NDArray[np.int64]:
    """The record's frame shown at each video frame: one every 1/fps s of robot time, the last always."""
    if len(record) == 0:
        return np.zeros(0, dtype=np.int64)
    times = record.times[0] + np.arange(0.0, record.duration, 1.0 / fps)
    frames = np.searchsorted(record.times, times, side="right") - 1
    return np.append(np.clip(frames, 0, len(record) - 1), len(record) - 1).astype(np.int64)


def encoder(path: Path) -> Any:
    """The module that writes ``path``'s video type: imageio-ffmpeg, or None for a ``.gif`` (Pillow).

    Raises:
        ExecutiveError: an unknown video type, or imageio-ffmpeg not installed (with the pip command).
    """
    suffix = path.suffix.lower()
    if suffix == ".gif":
        return None
    if suffix not in FFMPEG_SUFFIXES:
        raise ExecutiveError(
            f"--video {path}: unknown video type '{path.suffix}'; one of {', '.join(FFMPEG_SUFFIXES)}, .gif"
        )
    try:
        import imageio_ffmpeg
    except ImportError:
        raise ExecutiveError(
            f"--video {path}: {suffix} is encoded by imageio-ffmpeg, which is not installed: {_INSTALL}; "
            "or write an animated .gif (Pillow)"
        ) from None
    return imageio_ffmpeg


@contextmanager
def _writer(path: Path, size: tuple[int, int], fps: float) -> Iterator[Callable[[np.ndarray], None]]:
    """A function taking RGB frames (height x width x 3) for ``path``; the file is closed after."""
    suffix = path.suffix.lower()
    if suffix == ".gif":
        from PIL import Image

        images: list[Any] = []  # each frame with its own 256 colours: a third of its RGB memory
        yield lambda rgb: images.append(Image.fromarray(rgb).convert("P", palette=Image.Palette.ADAPTIVE))
        images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
        return
    imageio_ffmpeg = encoder(path)
    # Quality 8 of 10 is libx264's CRF 10: a replay's frame differs from a direct render by about
    # a grey level on average (docs/replay.md).
    gen = imageio_ffmpeg.write_frames(
        str(path), size, fps=fps, quality=8, macro_block_size=1, ffmpeg_log_level="error"
    )
    gen.send(None)
    try:
        yield lambda rgb: gen.send(np.ascontiguousarray(rgb))
    finally:
        gen.close()


def render_video(
    record: Record,
    world: World,
    path: Path,
    *,
    fps: float = 25.0,
    width: int = 640,
    height: int = 480,
    shadows: bool = False,
) -> tuple[int, float]:
    """Render the record as a video of the rebuilt ``world`` (``mujoco.Renderer``, offscreen).

    Args:
        record: the record.
        world: :func:`rebuild_world`'s world (its ``data`` is overwritten).
        path: ``.mp4``/``.mkv``/``.avi``/``.mov`` (imageio-ffmpeg, H.264) or ``.gif`` (Pillow).
        fps: video frames per second of robot time (the video plays in real time).
        width, height: pixels (even: H.264 needs even sizes).
        shadows: draw shadows and reflections (:func:`make_renderer`).

    Returns:
        (frames written, seconds it took).

    Raises:
        ExecutiveError: an unknown file type, imageio-ffmpeg missing for it (with the pip
            command), no OpenGL context (set ``MUJOCO_GL=egl``), or the file not written.
    """
    t0 = time.perf_counter()
    frames = video_frames(record, fps)
    renderer = make_renderer(world, width, height, shadows=shadows)
    camera = overview_camera(world)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with _writer(path, (width, height), fps) as write:
            for frame in frames.tolist():
                world.data.qpos[:] = record.qpos[frame]
                world.data.time = record.times[frame]
                mujoco.mj_forward(world.model, world.data)
                renderer.update_scene(world.data, camera=camera)
                write(renderer.render())
    except OSError as exc:
        raise ExecutiveError(f"--video {path}: not written ({exc.strerror or exc})") from None
    except RuntimeError as exc:  # ffmpeg stopped (imageio-ffmpeg reports its exit so)
        raise ExecutiveError(f"--video {path}: ffmpeg failed: {exc}") from None
    finally:
        renderer.close()
    return len(frames), time.perf_counter() - t0


# --- the summary ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StepSpan:
    """One behaviour's run in the record: frames it was RUNNING, how it ended, the guard's least values."""

    task: str
    node: TreeNode
    start: int  # frame it started RUNNING
    end: int  # frame it left RUNNING (the last frame if it never did)
    status: str  # SUCCESS, FAILURE, INVALID (halted), RUNNING (the record ends in it)
    clearance: float  # least predicted clearance its guard saw (m; NaN: no guard)
    com_margin: float  # least CoM margin its guard saw (m; NaN: none)


def _task_of(nodes: tuple[TreeNode, ...], i: int) -> str:
    """The name of the selector (a child of the root) above node ``i``."""
    while nodes[i].parent >= 0 and nodes[nodes[i].parent].parent >= 0:
        i = nodes[i].parent
    return nodes[i].name


def step_spans(record: Record) -> list[StepSpan]:
    """Every leaf behaviour that ran, in the order it started, with its guard's least values."""
    spans: list[StepSpan] = []
    layouts = [e for e in record.events if e["k"] == "tree"]
    for n, layout in enumerate(layouts):
        first = int(layout["frame"])
        last = int(layouts[n + 1]["frame"]) if n + 1 < len(layouts) else len(record)
        nodes = record.tree_at(first)
        # the behaviours: no children, below a task's selector (a selector before planning has none)
        parents = {m.parent for m in nodes}
        leaves = {i for i, m in enumerate(nodes) if i not in parents and m.parent > 0}
        started: dict[int, int] = {}
        for event in record.events:
            if event["k"] != "status" or not first <= event["frame"] < last:
                continue
            for i, code in event["s"]:
                if i not in leaves:
                    continue
                if code == 1 and i not in started:
                    started[i] = int(event["frame"])
                elif code != 1 and i in started:
                    spans.append(_span(record, nodes, i, started.pop(i), int(event["frame"]), code))
        for i, start in started.items():
            spans.append(_span(record, nodes, i, start, last - 1, 1))
    return sorted(spans, key=lambda s: (s.start, s.end))


def _span(record: Record, nodes: tuple[TreeNode, ...], i: int, start: int, end: int, code: int) -> StepSpan:
    parent = nodes[i].parent
    guarded = parent >= 0 and nodes[parent].kind == "RiskGuard"
    mask = record.guard[start : end + 1] == parent if guarded else np.zeros(0, dtype=bool)
    clear = record.clearance[start : end + 1][mask]
    com = record.com_margin[start : end + 1][mask]
    com = com[np.isfinite(com)]
    return StepSpan(
        task=_task_of(nodes, i),
        node=nodes[i],
        start=start,
        end=end,
        status={0: "INVALID", 1: "RUNNING", 2: "SUCCESS", 3: "FAILURE"}[int(code)],
        clearance=float(clear.min()) if clear.size else math.nan,
        com_margin=float(com.min()) if com.size else math.nan,
    )


def _mm(value: float) -> str:
    return f"{value * 1000:8.1f}" if math.isfinite(value) else f"{'-':>8}"


def _ending(record: Record) -> str:
    """How the record ends: the mission's status, or where it stops (and the summary's outcome, if any)."""
    end = next((e for e in record.events if e["k"] == "end"), None)
    if end is not None:
        return f"ended     {end['status']} at tick {end['tick']}"
    text = f"ended     without its end at t={record.times[-1]:.2f} s: "
    try:
        summary = json.loads((record.folder.parent / "summary.json").read_text(encoding="utf-8"))
        outcome = f"{summary['outcome']}" + (f" ({summary['reason']})" if summary.get("reason") else "")
    except (OSError, ValueError, KeyError, TypeError):
        return text + "the run was killed (no summary.json)"
    return text + f"the run was stopped, outcome {outcome} (summary.json)"


def _phase_spans(record: Record) -> list[tuple[dict[str, Any], int, int]]:
    """Each phase a task was in (not ``idle`` or ``done``), its first frame and the frame it ended."""
    phases = record.phases
    out = []
    for n, phase in enumerate(phases):
        if phase["phase"] in ("idle", "done"):
            continue
        later = (p for p in phases[n + 1 :] if p["task"] == phase["task"])
        end = next(later, None)
        out.append((phase, int(phase["frame"]), int(end["frame"]) if end else len(record) - 1))
    return out


def phase_summary(record: Record) -> str:
    """A short text: the record, the tasks' phases with their times, each step's outcome and guard minima."""
    h = record.header
    size = sum(p.stat().st_size for p in record.folder.iterdir() if p.is_file())
    per_s = size / record.duration if record.duration > 0 else math.nan
    truth = {"exact": "exact (truth = estimate)", None: "the host's robot (estimate)"}.get(
        h.get("truth"), f"sampled, seed {h.get('truth')}"
    )
    lines = [
        f"record    {record.folder}: {h['scenario']}, truth {truth}",
        f"          {len(record)} frames, ticks {record.ticks[0]}-{record.ticks[-1]}, "
        f"{record.duration:.2f} s of robot time, {size / 1000:.0f} kB"
        + (f" ({per_s / 1000:.1f} kB/s)" if math.isfinite(per_s) else ""),
        _ending(record),
        "",
        f"{'phase / step':<40}{'from s':>8}{'to s':>8}{'dur s':>7}  {'status':<8}"
        f"{'min clear mm':>13}{'min CoM mm':>11}",
    ]
    spans = step_spans(record)
    for phase, a, b in _phase_spans(record):
        label = f"{phase['task']} {phase['phase']}" + (
            f" {phase['alternative']}" if phase.get("alternative") else ""
        )
        t0, t1 = record.times[a], record.times[b]
        lines.append(f"{label:<40}{t0:>8.2f}{t1:>8.2f}{t1 - t0:>7.2f}")
        if phase["phase"] == "executing":
            for span in spans:
                if span.task == phase["task"] and a <= span.start <= b:
                    s0, s1 = record.times[span.start], record.times[span.end]
                    lines.append(
                        f"  {span.node.name:<38}{s0:>8.2f}{s1:>8.2f}{s1 - s0:>7.2f}  {span.status:<8}"
                        f"{_mm(span.clearance):>13}{_mm(span.com_margin):>11}"
                    )
    for name in h["objects"]:
        pos, _ = record.object_pose(len(record) - 1, name)
        lines.append(f"final     {name} at ({pos[0]:.4f}, {pos[1]:.4f}, {pos[2]:.4f}) m")
    return "\n".join(lines)
