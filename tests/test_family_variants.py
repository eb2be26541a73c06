"""Scene variants of every bundled family: the glovebox, pick_place_push, the G1 book scene.

Each task kind says which of its block's points a variant moves (``TaskKind.varied_points``);
each family's ranges file says what moves and by how much. References: the base scenario's own
numbers (what a fixed body must keep, what a followed point must move by), MuJoCo's geometry of
the compiled variant (``mj_geomDistance``), the loader's own checks (a variant loads back).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest

from executive.cli.main import main
from executive.errors import ScenarioError
from executive.scenario import load
from executive.schema.readers import vertical_half_extent
from executive.schema.types import Scenario
from executive.tasks.press import PressTask
from executive.validation.variants import (
    Variant,
    base_document,
    make_variant,
    scene_problem,
    varied_points,
    write_variant,
)
from executive.validation.variation_ranges import VariationRanges, family_ranges_path, load_ranges
from executive.world.model import build

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"


def _family(name: str) -> tuple[Scenario, VariationRanges]:
    base = load(SCENARIOS / f"{name}.yaml")
    path = family_ranges_path(base.source)
    assert path == SCENARIOS / "variation" / f"{name}.yaml"
    return base, load_ranges(path)


def _draw(base: Scenario, ranges: VariationRanges, count: int, seed: int = 7) -> list[Variant]:
    document = base_document(base)
    return [make_variant(base, document, seed, k, ranges) for k in range(count)]


@pytest.fixture(scope="module")
def glovebox() -> tuple[Scenario, VariationRanges, list[Variant]]:
    base, ranges = _family("glovebox")
    return base, ranges, _draw(base, ranges, 8)


@pytest.fixture(scope="module")
def pick_place_push() -> tuple[Scenario, VariationRanges, list[Variant]]:
    base, ranges = _family("pick_place_push")
    return base, ranges, _draw(base, ranges, 8)


def _gaps(scenario: Scenario) -> dict[tuple[str, str], float]:
    """MuJoCo's distance between every object and every other named body of the compiled scene."""
    world = build(scenario)
    model, data = world.model, world.data
    mujoco.mj_forward(model, data)
    names = [b.name for b in (*scenario.scene.objects, *scenario.scene.obstacles)]
    ids = {n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) for n in names}
    out = {}
    for obj in scenario.scene.objects:
        for other in names:
            if other != obj.name:
                out[(obj.name, other)] = mujoco.mj_geomDistance(
                    model, data, ids[obj.name], ids[other], 1.0, np.zeros(6)
                )
    return out


# --- the glovebox: the cell stays, the can and the controls move --------------------------------


def test_glovebox_variants_keep_the_cell_and_move_the_can_and_controls(
    glovebox: tuple[Scenario, VariationRanges, list[Variant]],
) -> None:
    base, ranges, variants = glovebox
    before = {b.name: b for b in base.scene.obstacles}
    (can,) = base.scene.objects
    controls = {"bagout_control", "seal_control"}
    moved_controls = 0
    for v in variants:
        scene = v.scenario.scene
        assert scene.table == base.scene.table  # the glovebox floor is the cell's
        for body in scene.obstacles:
            old = before[body.name]
            shift = np.subtract(body.position, old.position)
            if body.name in controls:
                assert np.all(np.abs(shift[:2]) <= ranges.shift_m[body.name] + 1e-9) and abs(shift[2]) < 1e-9
                moved_controls += bool(np.any(shift))
            else:  # walls, ports, rims, window
                assert body.position == pytest.approx(old.position, abs=1e-9), f"{v.index} moved {body.name}"
                assert dataclasses.replace(body, position=old.position) == old
        (new,) = scene.objects
        assert np.all(np.abs(np.subtract(new.position[:2], can.position[:2])) <= ranges.position_m + 1e-9)
        assert ranges.mass_kg[0] <= new.mass <= ranges.mass_kg[1]  # type: ignore[operator]
        assert ranges.friction[0] <= new.friction <= ranges.friction[1]
        for s_new, s_old in zip(new.size, can.size, strict=True):
            assert ranges.scale[0] - 1e-9 <= s_new / s_old <= ranges.scale[1] + 1e-9
        target = np.subtract(v.scenario.mission[1].to[:2], base.mission[1].to[:2])  # type: ignore[attr-defined]
        assert np.all(np.abs(target) <= ranges.target_shift + 1e-9)
    assert moved_controls == 2 * len(variants)


def test_a_press_point_moves_exactly_as_its_control(
    glovebox: tuple[Scenario, VariationRanges, list[Variant]],
) -> None:
    """The press kind's point follows its target: on the control's top face in every variant."""
    base, _, variants = glovebox
    for v in variants:
        obstacles = {b.name: b for b in v.scenario.scene.obstacles}
        old_obstacles = {b.name: b for b in base.scene.obstacles}
        for old_task, task in zip(base.mission, v.scenario.mission, strict=True):
            if not isinstance(task, PressTask):
                continue
            assert isinstance(old_task, PressTask)
            moved = np.subtract(obstacles[task.target].position, old_obstacles[task.target].position)
            assert np.subtract(task.point, old_task.point) == pytest.approx(moved, abs=1e-6)
            top = obstacles[task.target].position[2] + obstacles[task.target].size[2] / 2
            assert task.point[2] == pytest.approx(top, abs=1e-6)


def test_glovebox_variants_are_valid_in_mujoco_and_load_back(
    glovebox: tuple[Scenario, VariationRanges, list[Variant]], tmp_path: Path
) -> None:
    _, ranges, variants = glovebox
    for v in variants[:4]:
        gaps = _gaps(v.scenario)
        assert min(gaps.values()) >= ranges.clearance_m - 1e-6, min(gaps.items(), key=lambda kv: kv[1])
    v = variants[1]
    loaded = write_variant(v, tmp_path / "variant.yaml")
    assert [t.label() for t in loaded.mission] == [t.label() for t in v.scenario.mission]
    assert loaded.scene.objects[0].position == pytest.approx(v.scenario.scene.objects[0].position, abs=1e-6)
    assert loaded.scene.obstacles == v.scenario.scene.obstacles


# --- pick_place_push: every object and every target --------------------------------------------


def test_pick_place_push_variants_move_every_object_and_target(
    pick_place_push: tuple[Scenario, VariationRanges, list[Variant]],
) -> None:
    base, ranges, variants = pick_place_push
    objects = {b.name: b for b in base.scene.objects}
    targets = [(i, p) for i, t in enumerate(base.mission) for p in varied_points(t)]
    assert [(i, p.key, p.places) for i, p in targets] == [
        (1, "to", "book"),
        (2, "to", "box"),
        (3, "to", "block"),
    ]  # the pick names no point: its book moves with the scene
    for v in variants:
        dz = v.scenario.scene.table.height - base.scene.table.height
        assert abs(dz) <= ranges.table_height_m + 1e-9
        for body in v.scenario.scene.objects:
            old = objects[body.name]
            assert np.all(
                np.abs(np.subtract(body.position[:2], old.position[:2])) <= ranges.position_m + 1e-9
            )
            assert (
                abs(math.degrees(body.orientation_rad[2] - old.orientation_rad[2])) <= ranges.yaw_deg + 1e-6
            )
            half = vertical_half_extent(body.shape, body.size, body.orientation_rad)
            assert body.position[2] - half == pytest.approx(v.scenario.scene.table.height, abs=1e-6)
        (stack,), (old_stack,) = v.scenario.scene.obstacles, base.scene.obstacles
        assert np.all(
            np.abs(np.subtract(stack.position[:2], old_stack.position[:2])) <= ranges.obstacle_m + 1e-9
        )  # type: ignore[operator]
        for i, _ in targets:
            shift = np.subtract(v.scenario.mission[i].to[:2], base.mission[i].to[:2])  # type: ignore[attr-defined]
            assert np.all(np.abs(shift) <= ranges.target_shift + 1e-9) and np.any(shift)
        gaps = _gaps(v.scenario)
        assert min(gaps.values()) >= ranges.clearance_m - 1e-6


def test_a_target_is_checked_against_the_scene_the_tasks_before_left(
    pick_place_push: tuple[Scenario, VariationRanges, list[Variant]],
) -> None:
    """The transfer's target is where the book lay: free only because the pick and the place took
    the book elsewhere first. The same target with the book never picked is refused."""
    base, ranges, _ = pick_place_push
    resting = {b.name for b in (*base.scene.objects, *base.scene.obstacles)}
    assert scene_problem(base, resting, ranges.clearance_m) is None
    no_pick = dataclasses.replace(base, mission=base.mission[2:])
    assert str(scene_problem(no_pick, resting, ranges.clearance_m)).startswith(
        "target: box at its target is within"
    )


def test_variants_are_reproducible_from_the_seed(
    pick_place_push: tuple[Scenario, VariationRanges, list[Variant]],
) -> None:
    base, ranges, variants = pick_place_push
    again = _draw(base, ranges, 3)
    assert [v.document for v in again] == [v.document for v in variants[:3]]
    assert [v.redraws for v in again] == [v.redraws for v in variants[:3]]
    assert _draw(base, ranges, 1, seed=8)[0].document != variants[0].document


def test_fixed_bodies_stay_and_the_other_draws_do_not_change() -> None:
    """Fixing the stack leaves it where it is, and every other draw as it was (the same stream)."""
    base = load("book_transfer")
    document = base_document(base)
    free = make_variant(base, document, 3, 0)
    fixed = make_variant(base, document, 3, 0, VariationRanges(fixed=("book_stack",)))
    (stack,), (old,) = fixed.scenario.scene.obstacles, base.scene.obstacles
    dz = fixed.scenario.scene.table.height - base.scene.table.height
    assert stack.position == pytest.approx((*old.position[:2], old.position[2] + dz))
    if free.redraws == fixed.redraws == 0:
        assert fixed.draws["objects"] == free.draws["objects"]


# --- the G1 -------------------------------------------------------------------------------------


def test_g1_variants_are_valid(g1_scenario_yaml: str, tmp_path: Path) -> None:
    path = tmp_path / "g1_book_transfer.yaml"
    path.write_text(g1_scenario_yaml, encoding="utf-8")
    base = load(path)
    ranges = load_ranges(ROOT / "benchmarks" / "variation" / "g1_book_transfer.yaml")
    variants = _draw(base, ranges, 4)
    (book,) = base.scene.objects
    for v in variants:
        (obj,) = v.scenario.scene.objects
        assert ranges.mass_kg[0] <= obj.mass <= ranges.mass_kg[1]  # type: ignore[operator]
        assert obj.size[1] <= book.size[1] * ranges.scale[1] + 1e-9  # within the Dex3 pinch
        assert min(_gaps(v.scenario).values()) >= ranges.clearance_m - 1e-6
        assert v.scenario.robot == base.robot  # the shared model, by its absolute path


# --- malformed ranges ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "key", "words"),
    [
        ("yaw: 10\n", "yaw", "unknown key"),
        ("mass_kg: [2.0, 1.0]\n", "mass_kg", "low <= high"),
        ("scale: [0.9]\n", "scale", "a list of 2 numbers"),
        ("friction: [0, 1]\n", "friction[0]", "a number > 0"),
        ("position_m: -0.1\n", "position_m", "a number >= 0"),
        ("max_redraws: 1.5\n", "max_redraws", "an integer"),
        ("fixed: walls\n", "fixed", "a list"),
        ("shift_m: {seal_control: x}\n", "shift_m.seal_control", "a number"),
    ],
)
def test_malformed_ranges_are_refused_by_name(tmp_path: Path, text: str, key: str, words: str) -> None:
    path = tmp_path / "ranges.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as caught:
        load_ranges(path)
    assert caught.value.key_path == key and words in caught.value.problem
    assert str(path) in str(caught.value)


def test_a_body_the_ranges_name_must_be_in_the_scene() -> None:
    base = load("book_transfer")
    with pytest.raises(
        ScenarioError, match="no body 'bookstack' in book_transfer; its bodies are: book, book_stack"
    ):
        make_variant(base, base_document(base), 0, 0, VariationRanges(fixed=("bookstack",)))


def test_fidelity_refuses_bad_ranges_and_task_by_name(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "ranges.yaml"
    bad.write_text("obstacle_m: [0.1]\n", encoding="utf-8")
    for argv, message in (
        (["--ranges", str(bad)], "obstacle_m"),
        (["--task", "3"], "--task 3: glovebox has tasks 0-2"),
    ):
        out = tmp_path / f"suite-{len(message)}"
        assert (
            main(
                [
                    "fidelity",
                    str(SCENARIOS / "glovebox.yaml"),
                    "--variants",
                    "1",
                    "--trials",
                    "1",
                    "--out",
                    str(out),
                    *argv,
                ]
            )
            == 2
        )
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err


def test_fidelity_runs_a_later_task_of_a_family(tmp_path: Path) -> None:
    """The glovebox's seal press (task 2), one variant, one trial per hand, in physics."""
    import json

    out = tmp_path / "suite"
    argv = ["fidelity", str(SCENARIOS / "glovebox.yaml"), "--task", "2", "--variants", "1", "--trials", "1"]
    assert main([*argv, "--jobs", "1", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["task"] == 2 and summary["alternatives"] == ["right", "left"]
    assert summary["ranges_file"] == str(SCENARIOS / "variation" / "glovebox.yaml")
    assert summary["ranges"]["obstacle_m"] == 0.0
    (row,) = summary["per_variant"]
    assert [a["name"] for a in row["alternatives"]] == ["right", "left"]
    assert sum(a["trials"] + a["infeasible"] + a["errors"] for a in row["alternatives"]) == 2
    variant = load(out / row["yaml"])
    seal = {b.name: b for b in variant.scene.obstacles}["seal_control"]
    assert (
        variant.mission[2].point[:2]
        == pytest.approx(  # type: ignore[attr-defined]
            np.add((0.60, -0.30), np.subtract(seal.position[:2], (0.60, -0.30)))
        )
    )
