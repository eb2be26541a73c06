"""Where the G1's Dex3 holds a book (its pinch centre) against physics, and the placement term.

The pinch model (executive/risk/hand_grip.py ``pinch_centre``, executive/risk/pinch.py) says the
closed thumb-against-fingers hand holds an object where the two sides' servo forces balance,
off the hand site across the jaws. Here the left hand grasps and lifts a book (exact truth)
in MuJoCo and the book's centre is read in the site's frame. The bundled humanoid's slide jaws
have no shift. Skipped when the shared G1 model is absent (the g1_mjcf fixture).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_g1_dex3 import _lift as lift  # tests/ is on sys.path (pytest's default prepend import mode)

from executive.risk.pinch import closing_shift, placement_tolerance
from executive.scenario import load
from executive.world.model import build


def _held_offset(text: str, width: float) -> tuple[float, float]:
    """Lift a book ``width`` wide with the left hand (exact truth): the book's centre along the
    site's closing axis (m) in physics, and the model's closing shift on the estimate."""
    estimate, truth, result = lift(text, width)
    assert result.failure is None
    data, site = truth.data, truth.ids.hand_sites["left"]
    book = data.xpos[truth.ids.object_bodies["book"]]
    held = (book - data.site_xpos[site]) @ data.site_xmat[site].reshape(3, 3)
    return float(held[1]), closing_shift(estimate, "left", "book")


@pytest.mark.parametrize("width", [0.07, 0.09])
def test_the_dex3_holds_the_book_where_its_servo_forces_balance(g1_scenario_yaml: str, width: float) -> None:
    """The 9 cm book sits ~3.5 mm towards the thumb (the thumb's saturated servos press it
    onto the stiffer fingers, which stop near their closed pads), the 7 cm one ~6.5 mm towards
    the fingers. Within 1 mm: the model puts the fingers' face at their innermost mesh vertex
    at the closed targets, while MuJoCo's soft contacts let the pads sink in by a fraction of
    a millimetre and the finger servos give ~0.15 mm under the thumb's 23.6 N."""
    physics, model = _held_offset(g1_scenario_yaml, width)
    print(f"width {width}: held at {physics * 1e3:+.2f} mm, model {model * 1e3:+.2f} mm")
    assert abs(model) > 0.003 and np.sign(model) == np.sign(physics)
    assert model == pytest.approx(physics, abs=0.001)


def test_slide_jaws_do_not_shift_and_the_placement_bound_is_exact() -> None:
    """The bundled humanoid's symmetric jaws: shift 0, the placement bound tol itself; with a
    shift mu across the jaws the error along them may reach sqrt(tol^2 - mu^2)."""
    scenario = load("scenarios/book_transfer.yaml")
    world = build(scenario)
    obj = scenario.mission[0].object
    assert closing_shift(world, "left", obj) == 0.0 and closing_shift(world, "right", obj) == 0.0
    assert placement_tolerance(0.02, 0.0) == 0.02
    assert placement_tolerance(0.02, 0.012) == pytest.approx(0.016, abs=1e-15)
    assert placement_tolerance(0.02, 0.02) == 0.0 and placement_tolerance(0.02, 0.03) == 0.0
