"""The robots stand on their own in physics, in the book scene, holding their keyframe.

Issue thresholds: 30 s for the embedded humanoid (pelvis height within 2 cm,
trunk tilt under 2 degrees, no MuJoCo warnings); 5 s for the Unitree G1.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from executive.scenario import load, loads
from executive.world.model import World, build


def _stand(world: World, seconds: float) -> dict[str, float]:
    m, d = world.model, world.data
    world.reset()
    ctrl = world.home_ctrl()
    base, torso = world.ids.base_body, world.ids.torso_body
    z0 = float(d.xpos[base][2])
    robot = set(world.ids.robot_geoms)
    feet = {g for geoms in world.ids.foot_geoms.values() for g in geoms}
    worst = {"pelvis_dz": 0.0, "tilt_deg": 0.0, "bad_contacts": 0.0, "env_contacts": 0.0}
    for _ in range(round(seconds / m.opt.timestep)):
        d.ctrl[:] = ctrl
        mujoco.mj_step(m, d)
        worst["pelvis_dz"] = max(worst["pelvis_dz"], abs(float(d.xpos[base][2]) - z0))
        # trunk tilt: angle between the torso's z axis and the world's
        tilt = np.degrees(np.arccos(np.clip(d.xmat[torso].reshape(3, 3)[2, 2], -1.0, 1.0)))
        worst["tilt_deg"] = max(worst["tilt_deg"], float(tilt))
        for c in d.contact[: d.ncon]:
            pair = {int(c.geom1), int(c.geom2)}
            touches_robot = bool(pair & robot)
            if touches_robot and not (pair & feet and world.ids.floor_geom in pair):
                worst["bad_contacts"] += 1  # any contact but sole-floor, self-contacts included
                if not pair <= robot:
                    worst["env_contacts"] += 1  # the robot touching the scene elsewhere than its soles
    worst["warnings"] = float(sum(w.number for w in d.warning))
    worst["finite"] = float(np.isfinite(d.qpos).all())
    return worst


def test_embedded_humanoid_stands_30_s_in_the_book_scene() -> None:
    world = build(load("book_transfer"))
    result = _stand(world, 30.0)
    assert result["finite"] == 1.0
    assert result["pelvis_dz"] < 0.02, result
    assert result["tilt_deg"] < 2.0, result
    assert result["warnings"] == 0.0, result
    assert result["bad_contacts"] == 0.0, result  # not even a self-contact


def test_unitree_g1_stands_5_s_in_the_book_scene(g1_scenario_yaml: str) -> None:
    scenario = loads(g1_scenario_yaml, source="g1_book_transfer.yaml")
    world = build(scenario)
    assert world.profile.name == "unitree_g1"
    assert world.robot_mass == pytest.approx(34.39, abs=0.05)  # menagerie's stated mass
    result = _stand(world, 5.0)
    assert result["finite"] == 1.0
    assert result["pelvis_dz"] < 0.02, result
    assert result["tilt_deg"] < 2.0, result
    assert result["warnings"] == 0.0, result
    # Menagerie's G1 has thumb-palm self-contacts at its own keyframe; the scene must not be touched.
    assert result["env_contacts"] == 0.0, result
