"""Offscreen pictures of a world (MuJoCo's Renderer; ``MUJOCO_GL=egl`` on headless machines)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray

from executive.errors import ExecutiveError
from executive.world.model import World

__all__ = ["VideoRecorder", "overview_camera", "render_png", "render_rgb"]


def overview_camera(world: World) -> mujoco.MjvCamera:
    """A free camera in front of the robot and to its left, looking at the table."""
    table = world.scenario.scene.table
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = [table.position[0] * 0.5, table.position[1], table.height * 1.15]
    cam.distance = 3.1
    cam.azimuth = 205.0
    cam.elevation = -22.0
    return cam


def render_rgb(
    world: World, width: int = 960, height: int = 720, camera: mujoco.MjvCamera | str | None = None
) -> NDArray[np.uint8]:
    """Render the world's current state to an RGB array (height x width x 3)."""
    if width > world.model.vis.global_.offwidth or height > world.model.vis.global_.offheight:
        raise ExecutiveError(
            f"picture size {width}x{height} (--width x --height) exceeds the model's offscreen buffer "
            f"{world.model.vis.global_.offwidth}x{world.model.vis.global_.offheight} "
            "(<visual><global offwidth offheight> in its MJCF): the largest picture it renders"
        )
    cam = camera if camera is not None else overview_camera(world)
    try:
        renderer = mujoco.Renderer(world.model, height=height, width=width)
    except Exception as exc:  # no OpenGL context: say how to get one
        raise ExecutiveError(
            f"offscreen rendering failed ({exc}); on a headless machine set MUJOCO_GL=egl (or osmesa)"
        ) from exc
    try:
        renderer.update_scene(world.data, camera=cam)
        return np.asarray(renderer.render(), dtype=np.uint8)
    finally:
        renderer.close()


def render_png(world: World, path: Path, width: int = 960, height: int = 720) -> Path:
    """Render the world's current state to a PNG file and return its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image

    rgb = render_rgb(world, width, height)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        matplotlib.image.imsave(path, rgb, format="png")
    except OSError as exc:
        raise ExecutiveError(f"{path}: the picture could not be written ({exc.strerror or exc})") from None
    return path


class VideoRecorder:
    """Offscreen frames of a world while it runs, saved as an animated GIF (Pillow).

    ``every`` control periods make one frame; frames play at the rate that keeps real time.
    """

    def __init__(
        self, world: World, path: Path, *, width: int = 480, height: int = 360, fps: float = 10.0
    ) -> None:
        if path.suffix.lower() != ".gif":
            raise ExecutiveError(
                f"--video {path}: only animated GIF (.gif) is written (Pillow, no ffmpeg needed)"
            )
        self.world, self.path, self.fps = world, path, fps
        self.camera = overview_camera(world)
        try:
            self.renderer = mujoco.Renderer(world.model, height=height, width=width)
        except Exception as exc:
            raise ExecutiveError(
                f"offscreen rendering failed ({exc}); on a headless machine set MUJOCO_GL=egl (or osmesa)"
            ) from exc
        self.frames: list[NDArray[np.uint8]] = []
        self._next_t = 0.0

    def capture(self) -> None:
        """Take a frame if 1/fps of simulated time has passed since the last one."""
        t = float(self.world.data.time)
        if t + 1e-9 < self._next_t:
            return
        self._next_t = t + 1.0 / self.fps
        self.renderer.update_scene(self.world.data, camera=self.camera)
        self.frames.append(np.asarray(self.renderer.render(), dtype=np.uint8).copy())

    def save(self) -> Path:
        """Write the frames as an animated GIF at ``path``; an ExecutiveError if that fails."""
        from PIL import Image

        self.renderer.close()
        if not self.frames:
            raise ExecutiveError(f"--video {self.path}: no frames were captured")
        images = [Image.fromarray(f) for f in self.frames]
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            images[0].save(
                self.path, save_all=True, append_images=images[1:], duration=int(1000 / self.fps), loop=0
            )
        except OSError as exc:
            raise ExecutiveError(f"--video {self.path}: not written ({exc.strerror or exc})") from None
        return self.path
