"""The per-process robot cache (executive/world/model_cache.py) changes no world, only how fast it builds.

* a cached build equals an uncached one: every array of the compiled model and 300 physics
  steps from the home pose, bit for bit, for the bundled humanoid and the shared G1, estimate
  and truth (a truth with a CoM offset uses the cached masses);
* a changed MJCF (modified, or only touched) and a changed mesh file are read again;
* the cache holds at most ``CAPACITY`` robots;
* later G1 builds are several times faster than the first of the process, and a cached truth
  build (one compile) beats an uncached one (two compiles).
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
from pathlib import Path

import mujoco
import numpy as np
import pytest

from executive.scenario import load
from executive.scenario.loader import loads
from executive.schema.types import Scenario
from executive.world import model_cache
from executive.world.model import Perturbation, World, build, sample_perturbation

REPO = Path(__file__).resolve().parents[1]
HUMANOID_MJCF = REPO / "scenarios" / "robots" / "humanoid" / "humanoid.xml"


def _arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """Every numeric array of a compiled model, by attribute name."""
    out = {}
    for name in dir(model):
        if name.startswith("_"):
            continue
        value = getattr(model, name)
        if isinstance(value, np.ndarray):
            out[name] = value
    return out


def _assert_same_world(a: World, b: World) -> None:
    arrays_a, arrays_b = _arrays(a.model), _arrays(b.model)
    assert arrays_a.keys() == arrays_b.keys()
    for name, value in arrays_a.items():
        assert np.array_equal(value, arrays_b[name], equal_nan=value.dtype.kind == "f"), name
    assert (a.model.nq, a.model.nbody, a.model.ngeom, a.model.nmesh) == (
        b.model.nq,
        b.model.nbody,
        b.model.ngeom,
        b.model.nmesh,
    )
    assert a.ids == b.ids
    for world in (a, b):
        world.data.ctrl[:] = world.home_ctrl()
        for _ in range(300):
            mujoco.mj_step(world.model, world.data)
    assert np.array_equal(a.data.qpos, b.data.qpos)
    assert np.array_equal(a.data.qvel, b.data.qvel)
    assert float(np.abs(a.data.qpos - a.home_qpos()).max()) > 0.0  # the run moved something


def _cached_equals_uncached(scenario: Scenario) -> None:
    truth = sample_perturbation(scenario, np.random.default_rng(7))
    assert truth.com_offset != (0.0, 0.0)
    model_cache.clear()
    for pert in (None, truth, truth):  # the second truth uses the cached masses
        with model_cache.disabled():
            reference = build(scenario, pert)
        _assert_same_world(build(scenario, pert), reference)
    assert model_cache.size() == 1


def test_cached_humanoid_world_equals_uncached() -> None:
    _cached_equals_uncached(load("book_transfer"))


def test_cached_g1_world_equals_uncached(g1_scenario_yaml: str) -> None:
    _cached_equals_uncached(loads(g1_scenario_yaml))


def _humanoid_copy(tmp_path: Path) -> tuple[Path, Scenario]:
    """The bundled book scene with its humanoid read from a copy of the MJCF in ``tmp_path``."""
    mjcf = tmp_path / "humanoid.xml"
    shutil.copy(HUMANOID_MJCF, mjcf)
    scenario = load("book_transfer")
    return mjcf, dataclasses.replace(scenario, robot=dataclasses.replace(scenario.robot, mjcf=mjcf))


def _bump_mtime(path: Path) -> None:
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))


def test_a_changed_mjcf_is_read_again(tmp_path: Path) -> None:
    mjcf, scenario = _humanoid_copy(tmp_path)
    model_cache.clear()
    first = build(scenario)
    key = str(mjcf.resolve())
    spec_before = model_cache._entries[key].spec
    build(scenario)
    assert model_cache._entries[key].spec is spec_before  # unchanged: not read again
    _bump_mtime(mjcf)  # touched only: read again, the same world
    _assert_same_world(build(scenario), build(scenario))
    assert model_cache._entries[key].spec is not spec_before
    text = mjcf.read_text()
    assert text.count('timestep="0.002"') == 1
    mjcf.write_text(text.replace('timestep="0.002"', 'timestep="0.001"'))
    _bump_mtime(mjcf)
    changed = build(scenario)
    assert first.model.opt.timestep == 0.002
    assert changed.model.opt.timestep == 0.001
    with model_cache.disabled():
        assert build(scenario).model.opt.timestep == 0.001


_MESH_ROBOT = """<mujoco><compiler meshdir="meshes"/>
  <asset><mesh name="block" file="block.obj"/></asset>
  <worldbody><body name="b"><freejoint/><geom type="mesh" mesh="block"/></body></worldbody>
</mujoco>"""


def _write_block(path: Path, half: float) -> None:
    corners = [(x, y, z) for x in (-half, half) for y in (-half, half) for z in (-half, half)]
    faces = [(1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (3, 7, 8, 4), (1, 5, 7, 3), (2, 4, 8, 6)]
    lines = [f"v {x} {y} {z}" for x, y, z in corners] + ["f " + " ".join(map(str, f)) for f in faces]
    path.write_text("\n".join(lines) + "\n")


def test_a_changed_mesh_file_is_read_again(tmp_path: Path) -> None:
    (tmp_path / "meshes").mkdir()
    mjcf = tmp_path / "robot.xml"
    mjcf.write_text(_MESH_ROBOT)
    mesh = tmp_path / "meshes" / "block.obj"
    _write_block(mesh, 0.05)
    model_cache.clear()
    # A block of side 2h: vertices at +-h, volume 8 h^3 (default density 1000 kg/m^3).
    small = model_cache.robot_spec(mjcf).compile()
    assert np.abs(small.mesh_vert).max() == pytest.approx(0.05, rel=1e-6)
    assert small.body_mass[1] == pytest.approx(1000 * 0.1**3, rel=1e-6)
    _write_block(mesh, 0.10)
    _bump_mtime(mesh)
    big = model_cache.robot_spec(mjcf).compile()
    assert np.abs(big.mesh_vert).max() == pytest.approx(0.10, rel=1e-6)
    assert big.body_mass[1] == pytest.approx(1000 * 0.2**3, rel=1e-6)


def test_the_cache_is_bounded(tmp_path: Path) -> None:
    model_cache.clear()
    for i in range(model_cache.CAPACITY + 2):
        copy = tmp_path / f"humanoid_{i}.xml"
        shutil.copy(HUMANOID_MJCF, copy)
        model_cache.robot_spec(copy)
        assert model_cache.size() == min(i + 1, model_cache.CAPACITY)
    assert str((tmp_path / "humanoid_0.xml").resolve()) not in model_cache._entries


def _best(n: int, fn: object) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()  # type: ignore[operator]
        times.append(time.perf_counter() - t0)
    return min(times)


def test_later_g1_builds_are_faster(g1_scenario_yaml: str) -> None:
    scenario = loads(g1_scenario_yaml)
    truth = sample_perturbation(scenario, np.random.default_rng(7))
    model_cache.clear()
    mujoco.mj_clearCache(mujoco.mj_getCache())  # as a fresh process: no mesh decoded yet
    first = _best(1, lambda: build(scenario, truth))
    later = _best(3, lambda: build(scenario, truth))
    assert first / later > 3.0, (first, later)
    with model_cache.disabled():
        uncached = _best(5, lambda: build(scenario, truth))
    cached = _best(5, lambda: build(scenario, truth))
    assert uncached / cached > 1.15, (uncached, cached)
    assert isinstance(truth, Perturbation)
