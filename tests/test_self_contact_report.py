"""The end-of-task report of a run whose robot touched itself with zero force (issue 15).

The detector's closest-call report named the largest self-contact only when its force
was above zero, and the report then unpacked the missing names: any run with a
zero-force self-contact crashed at the end of its task. The state here is MuJoCo's:
the two palms of the bundled humanoid within a contact margin of each other while the
left arm swings away, so the contact exists and the solver gives it no force.
"""

from __future__ import annotations

import mujoco
import numpy as np

from executive.monitoring.detectors import ClosestCall, FailureDetector
from executive.scenario import load
from executive.world.model import World, build


def _palms_touching_while_parting() -> tuple[World, int, int]:
    """The book world with the palms in contact (inside a 1 mm margin), the left arm moving away."""
    world = build(load("book_transfer"))
    m, d = world.model, world.data
    left, right = m.geom("left_palm_geom").id, m.geom("right_palm_geom").id
    mujoco.mj_forward(m, d)
    gap = mujoco.mj_geomDistance(m, d, left, right, 10.0, None)
    for g in (left, right):  # the palms see each other and nothing else
        m.geom_contype[g] = m.geom_conaffinity[g] = 2
    m.geom_margin[left] = gap + 1e-3
    d.qvel[m.jnt_dofadr[m.joint("left_shoulder_roll").id]] = 3.0  # the left hand swings outwards
    return world, left, right


def test_a_zero_force_self_contact_is_reported_by_name() -> None:
    world, left, right = _palms_touching_while_parting()
    m, d = world.model, world.data
    detector = FailureDetector(world)
    mujoco.mj_forward(m, d)
    force = np.zeros(6)
    palm_contacts = [i for i in range(d.ncon) if {int(g) for g in d.contact.geom[i]} == {left, right}]
    assert palm_contacts, "the palms are in contact"
    for i in palm_contacts:
        mujoco.mj_contactForce(m, d, i, force)
        assert force[0] == 0.0  # a real contact that pushes nothing
    assert detector.check() is None
    call = detector.closest_call
    assert call.self_contacts == len(palm_contacts)
    assert call.self_force == 0.0
    assert call.self_bodies == ("left_palm", "right_palm")
    text = call.describe()  # the end-of-task report: crashed here before the fix
    assert f"{len(palm_contacts)} self-contacts (largest left_palm-right_palm 0.0 N)" in text


def test_a_report_without_names_still_describes_itself() -> None:
    assert "2 self-contacts (largest 0.0 N)" in ClosestCall(self_contacts=2).describe()
