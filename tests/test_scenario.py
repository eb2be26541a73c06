"""Loading valid scenarios: the bundled one's values, unit conversion, defaults, path resolution."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
import yaml

from executive import scenario
from executive.schema import catalog as registry
from executive.schema.types import RiskConfig, Scenario, SceneVariation, TrialsConfig, Uncertainty


def bundled_dict() -> dict:
    return yaml.safe_load(registry.scenario_path("book_transfer").read_text())


def test_bundled_book_transfer_values() -> None:
    bundled_root = registry.bundled_root()
    s = scenario.load("book_transfer")
    assert s.name == "book_transfer"
    assert s.description.startswith("Pick the book on the left")
    assert s.source == bundled_root / "book_transfer.yaml"
    assert s.robot.name == "humanoid"
    assert s.robot.mjcf == (bundled_root / "robots" / "humanoid" / "humanoid.xml").resolve()
    assert s.robot.profile == bundled_root / "robots" / "humanoid" / "profile.yaml"
    table = s.scene.table
    assert table.position == (0.62, 0.0)
    assert table.size == (0.60, 1.30, 0.04)
    assert table.height == 0.80
    assert table.yaw_rad == 0.0
    (book,) = s.scene.objects
    assert (book.name, book.shape, book.size, book.mass, book.friction) == (
        "book",
        "box",
        (0.22, 0.11, 0.05),
        0.6,
        1.0,
    )
    # z omitted: resting on the table top, centre half the thickness above it
    assert book.position == pytest.approx((0.52, 0.26, 0.80 + 0.025))
    (stack,) = s.scene.obstacles
    assert stack.mass is None
    assert stack.position == pytest.approx((0.62, 0.0, 0.80 + 0.15))
    assert s.uncertainty.object_yaw_rad == pytest.approx(3.0 * math.pi / 180.0)
    assert s.uncertainty.object_position == 0.01
    assert s.uncertainty.object_mass == 0.10
    assert s.risk.d_safety == 0.05
    assert s.risk.collision.exponent == 2.0
    assert s.risk.fall.circle_radius is None
    assert s.risk.weights == (("collision", 1.0), ("fall", 2.0), ("drop", 1.0), ("tracking", 1.0))
    assert dict(s.risk.severity.body_parts) == {"head": 3.0, "hand": 1.5, "forearm": 1.0}
    assert s.risk.ordering == "expected_loss"
    assert s.risk.threshold == 0.3
    assert (s.approval.mode, s.approval.timeout_s) == ("deny", 60.0)
    (task,) = s.mission
    assert task.kind == "transfer"
    assert task.object == "book"
    assert task.to == (0.52, -0.26, None)
    assert task.to_yaw_rad is None
    assert task.alternatives == ("left", "right", "left_to_right")
    assert s.trials == TrialsConfig(
        count=10,
        seed=0,
        scene_variation=SceneVariation(
            object_position=0.01,
            object_yaw_rad=math.radians(3.0),
            obstacle_position=0.01,
            perception_scale=(0.5, 2.0),
        ),
    )


@pytest.mark.parametrize("name", registry.list_scenarios())
def test_every_bundled_scenario_loads(name: str) -> None:
    assert isinstance(scenario.load(name), Scenario)


def test_angles_are_converted_to_radians() -> None:
    data = bundled_dict()
    data["scene"]["table"]["yaw"] = 90
    data["scene"]["objects"][0]["orientation"] = [10, -20, 30]
    del data["scene"]["objects"][0]["yaw_symmetry"]  # a tilted box has no symmetry about the vertical
    data["scene"]["obstacles"][0]["orientation"] = 45
    data["uncertainty"]["object_yaw"] = 6
    data["risk"]["grasp"] = {"angle_scale": 5, "angle_max": 40}
    data["mission"][0]["transfer"]["to_yaw"] = -90
    s = scenario.from_dict(data)
    deg = math.pi / 180.0
    assert s.scene.table.yaw_rad == pytest.approx(math.pi / 2)
    assert s.scene.objects[0].orientation_rad == pytest.approx((10 * deg, -20 * deg, 30 * deg))
    assert s.scene.obstacles[0].orientation_rad == pytest.approx((0.0, 0.0, math.pi / 4))
    assert s.uncertainty.object_yaw_rad == pytest.approx(6 * deg)
    assert s.risk.grasp.angle_scale_rad == pytest.approx(5 * deg)
    assert s.risk.grasp.angle_max_rad == pytest.approx(40 * deg)
    assert s.mission[0].to_yaw_rad == pytest.approx(-math.pi / 2)


def test_z_defaults_onto_the_table_top_for_each_shape_and_tilt() -> None:
    data = bundled_dict()
    data["scene"]["objects"] = [
        {"name": "can", "shape": "cylinder", "size": [0.03, 0.2], "position": [0.6, 0.35], "mass": 0.3},
        # lying on its side (roll 90 deg): half height is the radius
        {
            "name": "log",
            "shape": "cylinder",
            "size": [0.03, 0.2],
            "position": [0.45, 0.45],
            "orientation": [90, 0, 0],
            "mass": 0.3,
        },
        {"name": "ball", "shape": "sphere", "size": [0.04], "position": [0.75, 0.3], "mass": 0.1},
        # a box rolled 90 deg stands on its y face (the bodies keep clear of each other: an overlap
        # is rejected since issue 15)
        {
            "name": "book",
            "shape": "box",
            "size": [0.16, 0.11, 0.045],
            "position": [0.48, 0.2],
            "orientation": [90, 0, 0],
            "mass": 0.6,
        },
        {"name": "given", "shape": "box", "size": [0.1, 0.1, 0.1], "position": [0.5, -0.4, 0.85], "mass": 1},
    ]
    # an obstacle beside the table rests on the floor; "given" rests on the table at the z it gives
    data["scene"]["obstacles"] = [
        {"name": "bin", "shape": "box", "size": [0.3, 0.3, 0.4], "position": [0.0, 1.2]},
    ]
    s = scenario.from_dict(data)
    z = {b.name: b.position[2] for b in (*s.scene.objects, *s.scene.obstacles)}
    assert z["can"] == pytest.approx(0.80 + 0.1)
    assert z["log"] == pytest.approx(0.80 + 0.03)
    assert z["ball"] == pytest.approx(0.80 + 0.04)
    assert z["book"] == pytest.approx(0.80 + 0.055)
    assert z["given"] == 0.85
    assert z["bin"] == pytest.approx(0.2)


def test_optional_blocks_take_the_dataclass_defaults() -> None:
    data = bundled_dict()
    for key in ("description", "uncertainty", "risk", "approval", "trials"):
        del data[key]
    del data["scene"]["obstacles"]
    del data["mission"][0]["transfer"]["alternatives"]
    s = scenario.from_dict(data)
    assert s.description == ""
    assert s.uncertainty == Uncertainty()
    assert s.risk == RiskConfig()
    assert s.trials == TrialsConfig()
    assert s.scene.obstacles == ()
    assert s.mission[0].alternatives == ("left", "right", "left_to_right", "left_sidestep", "right_sidestep")


def test_partial_risk_blocks_keep_the_other_defaults() -> None:
    data = bundled_dict()
    data["risk"] = {"weights": {"fall": 3.5}, "fall": {"circle_radius": 0.02}, "severity": {"fall": 20}}
    s = scenario.from_dict(data)
    assert s.risk.weights == (("collision", 1.0), ("fall", 3.5), ("drop", 1.0), ("tracking", 1.0))
    assert s.risk.fall.circle_radius == 0.02
    assert s.risk.fall.sigmas == 2.0
    assert s.risk.severity.fall == 20.0
    assert s.risk.severity.body_parts == RiskConfig().severity.body_parts


def test_paths_resolve_relative_to_the_scenario_file(tmp_path: Path) -> None:
    models = tmp_path / "models"
    models.mkdir()
    (models / "robot.xml").write_text("<mujoco/>\n")
    folder = tmp_path / "missions"
    folder.mkdir()
    data = bundled_dict()
    data["robot"] = {"mjcf": "../models/robot.xml", "profile": "unitree_g1"}
    path = folder / "g1_books.yaml"
    path.write_text(yaml.safe_dump(data))

    s = scenario.load(path)
    assert s.robot.name == "unitree_g1"
    assert s.robot.mjcf == (models / "robot.xml").resolve()
    assert s.robot.profile == registry.robot_profile_path("unitree_g1")
    assert s.source == path.resolve()
    # the same text from a string resolves against base_dir
    assert scenario.loads(path.read_text(), base_dir=folder).robot.mjcf == (models / "robot.xml").resolve()


def test_profile_given_by_relative_path_resolves_its_own_mjcf(tmp_path: Path) -> None:
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "model.xml").write_text("<mujoco/>\n")
    profile = yaml.safe_load(registry.robot_profile_path("humanoid").read_text())  # type: ignore[union-attr]
    profile["name"] = "my_robot"
    profile["mjcf"] = "model.xml"  # relative to the profile file
    (tmp_path / "robot" / "profile.yaml").write_text(yaml.safe_dump(profile))
    data = bundled_dict()
    data["robot"] = {"profile": "robot/profile.yaml"}
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(data))
    s = scenario.load(tmp_path / "s.yaml")
    assert s.robot.name == "my_robot"
    assert s.robot.mjcf == (tmp_path / "robot" / "model.xml").resolve()
    assert s.robot.profile == (tmp_path / "robot" / "profile.yaml").resolve()


def test_robot_by_name_mapping_equals_robot_by_string() -> None:
    data = bundled_dict()
    data["robot"] = {"name": "humanoid"}
    assert scenario.from_dict(data).robot == scenario.load("book_transfer").robot


def test_scenario_dataclasses_are_frozen() -> None:
    s = scenario.load("book_transfer")
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.scene.table.height = 1.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.scene.objects[0].mass = 2.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.risk.collision.exponent = 3.0  # type: ignore[misc]
    assert isinstance(s.scene.objects, tuple)
    assert isinstance(s.mission, tuple)
