"""The hold model in a grasp's own directions against standalone MuJoCo grips.

A grasp from above has gravity along the hand's approach axis (site z); a level grasp from a
side has it along the pads' lateral axis (site x); an oblique one between. The hold model
projects the load on the pad plane and takes its moment about the closing axis in the site
frame (:mod:`executive.risk.hold`), so its verdict must follow physics for any direction of
gravity in the pad plane. The standalone grip: a box between two pads (the bundled humanoid's
pad contact parameters), each pushed by a motor of constant force F, gravity turned by theta
in the pads' plane; the box's centre dx off the pads' centre along x. A box whose centre moves
more than 1 cm in 1 s slipped; under 2 mm it held (soft contacts creep a little inside the cone).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from executive.risk.hold import CarrySpan, Grip, contact_parameters, slip_critical_mass
from tests.conftest import PAD_GRIP_XML

G = 9.81
PAD_HALF = (0.015, 0.03)  # along x (lateral) and z (approach)
BOX_HALF = (0.06, 0.04, 0.06)


def _gravity(theta: float) -> np.ndarray:
    """Gravity in the site frame turned by ``theta`` from along -z (a grasp from above) towards -x."""
    return -G * np.array([math.sin(theta), 0.0, math.cos(theta)])


def _model(
    m: float, mu: float, theta: float, dx: float, half: tuple[float, float, float] = BOX_HALF
) -> mujoco.MjModel:
    gx, _, gz = _gravity(theta)
    bx, by, bz = half
    xml = PAD_GRIP_XML.format(
        gx=gx, gz=gz, ya=by + 0.005, yb=-by - 0.005, hx=PAD_HALF[0], hz=PAD_HALF[1], mu=mu, dx=dx,
        bx=bx, by=by, bz=bz, m=m,
    )  # fmt: skip
    return mujoco.MjModel.from_xml_string(xml)


def _moved(model: mujoco.MjModel, force: float, seconds: float = 1.0) -> float:
    """How far (m) the box's centre moved in ``seconds`` with the pads pressing ``force`` each."""
    data = mujoco.MjData(model)
    data.ctrl[:] = force
    mujoco.mj_forward(model, data)
    box = model.body("box").id
    start = data.xpos[box].copy()
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
    return float(np.linalg.norm(data.xpos[box] - start))


def _grip(model: mujoco.MjModel, force: float) -> Grip:
    """The standalone jaw as the hold model sees it (site frame = world frame, pads at the origin)."""
    pad, box = model.geom("pad_a").id, model.geom("box").id
    return Grip(
        side="test",
        force=force,
        pads=(pad, model.geom("pad_b").id),
        pad_centre=np.zeros(2),
        pad_half=np.array(PAD_HALF),
        contact=contact_parameters(model, pad, box),
        inv_weight=float(
            model.body_invweight0[model.geom_bodyid[pad], 0] + model.body_invweight0[model.body("box").id, 0]
        ),
        impratio=float(model.opt.impratio),
        half_width=BOX_HALF[1],
        pad_friction_wins=True,
    )


def _held_span(theta: float, dx: float, half: tuple[float, float, float] = BOX_HALF) -> CarrySpan:
    """One second held still, the site turned so that gravity lies at ``theta`` in its x-z plane."""
    c, s = math.cos(theta), math.sin(theta)
    site = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])  # world <- site: site^T e_z = (s, 0, c)
    span = CarrySpan("test", np.eye(3), np.array([dx, 0.0, 0.0]), np.array([half[0], half[2]]))
    for t in np.linspace(0.0, 1.0, 11):
        span.add(float(t), site, np.zeros(3), True)
    return span


GRID = [
    (theta, m, mu, force, dx)
    for theta in (0.0, math.radians(45.0), math.radians(90.0))
    for m in (0.6, 2.5, 8.0)
    for mu in (0.3, 1.0)
    for force in (20.0, 60.0)
    for dx in (0.0, 0.03)
]


def test_the_load_lies_in_the_pad_plane_whatever_the_grasp() -> None:
    # Without an offset the load is the weight wherever gravity lies in the pad plane: m g / (2 mu F).
    for theta in (0.0, 0.6, math.pi / 2):
        model = _model(1.0, 0.5, theta, 0.0)
        crit = float(slip_critical_mass(_held_span(theta, 0.0), _grip(model, 30.0), np.zeros(1), 0.5)[0])
        assert crit == pytest.approx(2.0 * 0.5 * 30.0 / G, rel=1e-6)


def test_slip_in_the_grasps_own_directions_matches_physics() -> None:
    # Judged only away from the boundary: load below 0.8 or above 1.25 of the capacity.
    judged = {"held": 0, "slipped": 0}
    for theta, m, mu, force, dx in GRID:
        model = _model(m, mu, theta, dx)
        crit = float(slip_critical_mass(_held_span(theta, dx), _grip(model, force), np.zeros(1), mu)[0])
        load_ratio = m / crit
        if 0.8 <= load_ratio <= 1.25:
            continue
        moved = _moved(model, force)
        if load_ratio < 0.8:
            assert moved < 0.002, (math.degrees(theta), m, mu, force, dx, load_ratio, moved)
            judged["held"] += 1
        else:
            assert moved > 0.01, (math.degrees(theta), m, mu, force, dx, load_ratio, moved)
            judged["slipped"] += 1
    assert judged["held"] >= 12 and judged["slipped"] >= 12, judged


#: A long box held near one end: its centre 10 cm along x from the pads' centre.
LONG_HALF, LONG_DX = (0.12, 0.04, 0.06), 0.10


def test_an_offset_load_turns_out_of_a_grasp_from_above_but_not_a_level_one() -> None:
    # Gravity along z (from above) has a moment about the closing axis through the lever along x;
    # along x (level, from a side) it has none. A mass 0.7 of the level grasp's critical mass:
    # the model says the level grasp holds and the one from above slips; so does physics.
    mu, force = 1.0, 30.0
    level = _model(1.0, mu, math.pi / 2, LONG_DX, LONG_HALF)
    g = _grip(level, force)
    level_crit = float(slip_critical_mass(_held_span(math.pi / 2, LONG_DX, LONG_HALF), g, np.zeros(1), mu)[0])
    assert level_crit == pytest.approx(2.0 * mu * force / G, rel=1e-6)
    above_crit = float(slip_critical_mass(_held_span(0.0, LONG_DX, LONG_HALF), g, np.zeros(1), mu)[0])
    # Howe & Cutkosky's ellipse: f_max = 2 mu F; tau_max = 2 F (mu r + mu_torsion), r the distance of the
    # patch's corner contacts from its centre (the pad's whole face here), mu_torsion the pad's 0.02.
    r, lever = math.hypot(*PAD_HALF), LONG_DX
    tau_max = 2.0 * force * (mu * r + 0.02)
    assert above_crit == pytest.approx(1.0 / math.hypot(G / (2 * mu * force), G * lever / tau_max), rel=1e-6)
    m = 0.7 * level_crit
    assert m / above_crit > 1.25
    assert _moved(_model(m, mu, math.pi / 2, LONG_DX, LONG_HALF), force) < 0.002
    assert _moved(_model(m, mu, 0.0, LONG_DX, LONG_HALF), force) > 0.01
