"""The `executive` command as a user runs it: a real subprocess, its exit code and its words."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from executive.report.render import overview_camera
from executive.scenario import load
from executive.world.model import build

SCRIPT = Path(sys.executable).parent / "executive"


def run(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    cmd = [str(SCRIPT), *args] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main", *args]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def test_list_names_the_bundled_scenario_and_robots() -> None:
    out = run("list")
    assert out.returncode == 0, out.stderr
    assert "book_transfer" in out.stdout
    assert "humanoid" in out.stdout and "unitree_g1" in out.stdout


def test_version_is_the_packages_one_written_once(capsys: pytest.CaptureFixture[str]) -> None:
    """``executive --version`` prints ``executive.__version__``, which pyproject.toml reads (its
    version is dynamic), so the installed distribution's metadata says the same."""
    import importlib.metadata
    import tomllib

    import executive
    from executive.cli.main import main

    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"executive {executive.__version__}"
    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "executive.__version__"}
    assert importlib.metadata.version("risk-gated-executive") == executive.__version__


def test_validate_bundled_from_another_directory(tmp_path: Path) -> None:
    out = run("validate", "book_transfer", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    for word in ("humanoid", "DoF", "kg", "book", "book_stack", "transfer"):
        assert word in text, (word, text)
    # The package found its bundled data from a directory that is not the checkout.
    where = subprocess.run(
        [sys.executable, "-c", "import executive.schema.catalog as r; print(r.bundled_root())"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
    ).stdout.strip()
    assert (Path(where) / "book_transfer.yaml").is_file()
    assert (Path(where) / "robots" / "humanoid" / "humanoid.xml").is_file()


@pytest.mark.parametrize(
    ("content", "needle"),
    [
        ("name: x\nrobot: humanoid\nscene: 3\n", "scene"),
        ("{{{{", "YAML"),
        ("name: [unclosed\n", "YAML"),
    ],
)
def test_validate_bad_file_exits_2_with_one_paragraph(tmp_path: Path, content: str, needle: str) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(content)
    out = run("validate", str(bad))
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
    assert "bad.yaml" in out.stderr and needle in out.stderr
    assert out.stdout == ""
    assert "\n\n" not in out.stderr.strip()  # one paragraph


def test_validate_unknown_name_lists_the_bundled_ones() -> None:
    out = run("validate", "book_transfr")
    assert out.returncode == 2
    assert "book_transfer" in out.stderr and "Traceback" not in out.stderr


def test_show_writes_a_picture_of_robot_book_and_stack(tmp_path: Path) -> None:
    png = tmp_path / "scene.png"
    out = run("show", "book_transfer", "--png", str(png), "--width", "480", "--height", "360")
    assert out.returncode == 0, out.stderr
    import matplotlib.image

    img = matplotlib.image.imread(png)
    assert img.shape[:2] == (360, 480)
    assert img[..., :3].std() > 0.05  # not a blank frame


def test_overview_camera_sees_robot_book_stack_and_table() -> None:
    """Segmentation render from the `show` camera: each named thing covers visible pixels."""
    world = build(load("book_transfer"))
    renderer = mujoco.Renderer(world.model, height=360, width=480)
    renderer.enable_segmentation_rendering()
    renderer.update_scene(world.data, camera=overview_camera(world))
    seg = renderer.render()
    renderer.close()
    geom_ids = seg[..., 0][seg[..., 1] == mujoco.mjtObj.mjOBJ_GEOM]
    robot = np.isin(world.model.geom_bodyid[geom_ids], world.ids.robot_bodies).sum()
    book = (geom_ids == world.ids.object_geoms["book"]).sum()
    stack = (geom_ids == world.ids.obstacle_geoms["book_stack"]).sum()
    table = np.isin(geom_ids, world.ids.table_geoms).sum()
    total = seg.shape[0] * seg.shape[1]
    assert robot > 0.05 * total
    assert book > 100 and stack > 300 and table > 0.05 * total
