"""The single-support gain of the fall model (closed forms, no physics)."""

from __future__ import annotations

import numpy as np

from executive.risk.fall_batch import KnotPolygons
from executive.risk.fall_bias import support_probability
from executive.risk.fall_compliance import GAIN_CAP, shrink_polygons, single_support_gain


def test_gain_is_twice_the_static_amplification() -> None:
    # m g h = 1000 N m/rad against k = 4000: A = 1 / (1 - 0.25) = 4/3, peak 2 A = 8/3.
    gain = single_support_gain(100.0, 10.0, np.array([1.0, 0.0]), 4000.0)
    assert np.allclose(gain, [8.0 / 3.0, 2.0])


def test_an_ankle_no_stiffer_than_gravity_cannot_stand() -> None:
    assert single_support_gain(100.0, 10.0, np.array([4.0, 5.0]), 4000.0).tolist() == [GAIN_CAP, GAIN_CAP]


def test_shrunk_polygon_is_the_bias_through_the_gain() -> None:
    square = np.array([[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]])
    polygons = KnotPolygons({4: (np.array([0, 1]), np.stack([square, square]))})
    mus = np.zeros((2, 2))
    shrunk = shrink_polygons(polygons, mus, np.array([1.0, 2.0]))
    assert np.array_equal(shrunk.groups[4][1][0], square)
    cov = 0.03**2 * np.eye(2)
    p_shrunk, _, _ = support_probability(shrunk, mus, cov)
    p_wide, _, _ = support_probability(KnotPolygons({4: (np.array([0]), square[None])}), mus[:1], 4.0 * cov)
    assert np.isclose(p_shrunk, p_wide)
