"""The push-contact model against MuJoCo: a finger that leaves the block's face mid-push.

A block (10 x 8 x 7 cm, its 8 cm face towards the pusher) rests on a table; a finger (3 x 4.4 x
9.5 cm, its tips 15 mm above the table, as a push plans them) on three position-servoed slide
joints (kp 2000 N/m) pushes it three 3 cm legs along +x. Mid-leg the finger's target swings up
by ``rise`` and across by ``lateral`` (a half sine per leg), as a planned push leg does when
the arm works at its joint ranges (docs/risk_models.md, "A push's stall"). Observed: the push
is lost when the block ends more than the place tolerance (2 cm) from where a straight push
leaves it, along or across. Predicted: :func:`executive.risk.push_contact.loss_probability`
of the leg's offsets against the face's half width (4 cm) and of the fingertips over the
block's top, with 2 mm of object position error and the tracking statics' 3 mm height spread.

Run: ``python benchmarks/bench_push_contact.py`` (about 25 s). Results: docs/risk_models.md,
"A push's stall".
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import mujoco

from executive.risk.push_contact import loss_probability
from executive.risk.tracking import UNMODELLED_SIGMA

__all__ = ["BLOCK", "PushRun", "main", "predicted_loss", "run_push"]

#: m: the block's full size (along the push, across it, height).
BLOCK = (0.10, 0.08, 0.07)
TIP = 0.015  # m, the fingertips above the table (executive.tasks.push.TIP_CLEARANCE)
LEG, LEGS, LEG_S = 0.03, 3, 1.5  # m per leg, legs, s per leg
GAP = 0.003  # m between the finger and the block's face at the start
TOLERANCE = 0.02  # m, the detectors' place tolerance
POSITION_SIGMA = 0.002  # m, the block's position error across the push

_XML = """
<mujoco>
  <option timestep="0.002" cone="elliptic" impratio="10"/>
  <worldbody>
    <geom name="table" type="plane" size="1 1 0.1" friction="{mu} 0.005 0.0001"/>
    <body name="block" pos="0 0 {hz}">
      <freejoint/>
      <geom type="box" size="{hx} {hy} {hz}" mass="{mass}" friction="{mu} 0.005 0.0001"/>
    </body>
    <body name="finger" pos="{x0} 0 {fz}" gravcomp="1">
      <joint name="fx" type="slide" axis="1 0 0" damping="40"/>
      <joint name="fy" type="slide" axis="0 1 0" damping="40"/>
      <joint name="fz" type="slide" axis="0 0 1" damping="40"/>
      <geom type="box" size="0.015 0.022 0.0475" mass="0.2" friction="1 0.005 0.0001"/>
    </body>
  </worldbody>
  <actuator>
    <position joint="fx" kp="2000"/><position joint="fy" kp="2000"/><position joint="fz" kp="2000"/>
  </actuator>
</mujoco>
"""


@dataclass(frozen=True)
class PushRun:
    """One push in MuJoCo: the block's end offset from a straight push's (m) and the finger's height
    above its planned end (m)."""

    along: float
    across: float
    finger_up: float

    @property
    def lost(self) -> bool:
        """The block ends beyond the place tolerance of where a straight push leaves it."""
        return math.hypot(self.along, self.across) > TOLERANCE


def run_push(mass: float, friction: float, rise: float, lateral: float) -> PushRun:
    """Push the block (``mass`` kg, ``friction`` with the table) with the finger's legs swinging
    ``rise`` m up and ``lateral`` m across mid-leg; where it ends."""
    hx, hy, hz = (s / 2.0 for s in BLOCK)
    x0 = -hx - 0.015 - GAP
    xml = _XML.format(mu=friction, hx=hx, hy=hy, hz=hz, mass=mass, x0=x0, fz=TIP + 0.0475)
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    steps = round(LEG_S / model.opt.timestep)
    for leg in range(LEGS):
        for i in range(1, steps + 1):
            s = i / steps
            bump = math.sin(math.pi * s)
            data.ctrl[:] = (LEG * (leg + s), lateral * bump, rise * bump)
            mujoco.mj_step(model, data)
    for _ in range(steps // 3):  # settle
        mujoco.mj_step(model, data)
    block = data.body("block").xpos
    straight = LEG * LEGS - GAP
    return PushRun(float(block[0]) - straight, float(block[1]), float(data.joint("fz").qpos[0]))


def predicted_loss(rise: float, lateral: float) -> float:
    """The model's P(the finger leaves the face) for a leg swinging ``rise`` up and ``lateral`` across."""
    over_top = TIP + rise - BLOCK[2]
    return loss_probability((0.0, lateral), BLOCK[1] / 2.0, over_top, POSITION_SIGMA, UNMODELLED_SIGMA)


def main() -> None:
    """The long grid: block mass x friction x the legs' rise (across 0) and lateral swing (rise 0)."""
    masses, frictions = (0.3, 0.6, 1.2, 1.8), (0.5, 0.8, 1.1)
    swings = [(r / 1000.0, 0.0) for r in range(0, 95, 5)] + [(0.0, a / 1000.0) for a in range(5, 75, 5)]
    agree = total = 0
    print("mass friction rise lateral | predicted P(lost) | observed: lost along across finger_up (mm)")
    for mass, friction, (rise, lateral) in itertools.product(masses, frictions, swings):
        run = run_push(mass, friction, rise, lateral)
        p = predicted_loss(rise, lateral)
        agree += int((p > 0.5) == run.lost)
        total += 1
        print(
            f"{mass:.1f} {friction:.1f} {rise * 1000:3.0f} {lateral * 1000:3.0f} | {p:.3f} | "
            f"{int(run.lost)} {run.along * 1000:+5.0f} {run.across * 1000:+5.0f} {run.finger_up * 1000:+4.0f}"
        )
    print(f"predicted (P > 0.5) = observed in {agree} of {total} cells")


if __name__ == "__main__":
    main()
