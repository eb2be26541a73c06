"""Fall risk: support polygon geometry, CoM-outside probabilities, capture point, trajectories.

Reference values are derived independently in each test (product formulas for a centred
rectangle, hand-computed distances, Monte Carlo sampling), not taken from the module.
"""

from __future__ import annotations

import itertools
import math
import warnings

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr

from executive.planning.timing import Trajectory
from executive.risk.fall import (
    assess_fall,
    capture_point,
    clip_polygon,
    convex_hull,
    edge_probabilities,
    halfplanes,
    persistent_bias_probability,
    polygon_area,
    probability_outside,
    probability_outside_mc,
    seed_fall_risk,
    signed_margin,
    support_polygon,
)
from executive.scenario import load
from executive.schema.types import FallRiskConfig, RiskConfig, Uncertainty
from executive.world.model import World, build

# Rectangle +-0.10 x +-0.05 m, counter-clockwise.
RECT = np.array([[-0.10, -0.05], [0.10, -0.05], [0.10, 0.05], [-0.10, 0.05]])
SIGMA = 0.03


def _hexagon() -> np.ndarray:
    """An irregular convex hexagon (counter-clockwise), a foot-print-like shape."""
    return np.array([[-0.12, -0.04], [0.02, -0.09], [0.13, -0.05], [0.15, 0.03], [0.04, 0.10], [-0.10, 0.06]])


# ----------------------------------------------------------------------------- probabilities


def test_centred_rectangle_exact_and_boole() -> None:
    cov = SIGMA**2 * np.eye(2)
    # Independent axes: P(inside) = P(|X| < 0.10) P(|Y| < 0.05), P(|X| < t) = 1 - 2 Phi(-t / sigma).
    expected = 1.0 - (1.0 - 2.0 * ndtr(-0.10 / SIGMA)) * (1.0 - 2.0 * ndtr(-0.05 / SIGMA))
    exact = probability_outside(RECT, [0.0, 0.0], cov)
    quad = probability_outside(RECT, [0.0, 0.0], cov, method="quadrature")
    print(f"exact (Owen's T) {exact:.10f}, quadrature {quad:.10f}, product formula {expected:.10f}")
    assert exact == pytest.approx(0.09636, abs=1e-3)
    assert exact == pytest.approx(expected, abs=1e-10)
    assert quad == pytest.approx(expected, abs=1e-10)
    # Boole: two edges at 0.10 and two at 0.05: 2 Phi(-10/3) + 2 Phi(-5/3).
    p = edge_probabilities(RECT, [0.0, 0.0], cov)
    boole = float(np.sum(p))
    assert boole == pytest.approx(2.0 * ndtr(-0.10 / SIGMA) + 2.0 * ndtr(-0.05 / SIGMA), abs=1e-12)
    assert boole == pytest.approx(0.09644, abs=1e-4)
    assert float(np.max(p)) <= exact <= boole
    print(f"Boole {boole:.6f}, max edge {np.max(p):.6f}")


@pytest.mark.parametrize("method", ["owens_t", "quadrature"])
@pytest.mark.parametrize("sigma", [0.01, 0.005, 0.002])
def test_small_tail_probabilities_keep_their_relative_accuracy(method: str, sigma: float) -> None:
    """Far inside the polygon P(outside) is tiny; 1 - P(inside) would give 0 or 2.2e-16 noise."""
    # Independent axes: P(outside) = 1 - (1 - 2 p_x)(1 - 2 p_y) = 2 p_x + 2 p_y - 4 p_x p_y, all tails.
    px, py = ndtr(-0.10 / sigma), ndtr(-0.05 / sigma)
    expected = 2.0 * px + 2.0 * py - 4.0 * px * py
    got = probability_outside(RECT, [0.0, 0.0], sigma**2 * np.eye(2), method=method)  # type: ignore[arg-type]
    assert got == pytest.approx(expected, rel=1e-9)
    # A correlated covariance off-centre: inside Boole's bracket, and (tails nearly disjoint)
    # within 1e-6 relative of the Boole sum.
    cov = sigma**2 * np.array([[1.0, 0.3], [0.3, 0.5]])
    p = edge_probabilities(_hexagon(), [0.01, 0.0], cov)
    got = probability_outside(_hexagon(), [0.01, 0.0], cov, method=method)  # type: ignore[arg-type]
    assert np.max(p) * (1.0 - 1e-12) <= got <= np.sum(p) * (1.0 + 1e-12)
    assert got == pytest.approx(np.sum(p), rel=1e-6)


def test_hexagon_correlated_exact_matches_monte_carlo() -> None:
    poly = _hexagon()
    mean = np.array([0.05, 0.02])
    cov = np.array([[0.04**2, 0.6 * 0.04 * 0.025], [0.6 * 0.04 * 0.025, 0.025**2]])
    exact = probability_outside(poly, mean, cov)
    quad = probability_outside(poly, mean, cov, method="quadrature")
    mc = probability_outside_mc(poly, mean, cov, np.random.default_rng(0), 1_000_000)
    p = edge_probabilities(poly, mean, cov)
    print(
        f"hexagon: exact {exact:.6f}, quadrature {quad:.6f}, MC {mc.probability:.6f} +- {mc.stderr:.6f}, "
        f"Boole [{np.max(p):.6f}, {min(1.0, p.sum()):.6f}]"
    )
    assert quad == pytest.approx(exact, abs=1e-9)
    assert abs(exact - mc.probability) < 3.0 * mc.stderr
    assert float(np.max(p)) <= exact <= min(1.0, float(np.sum(p)))


@pytest.mark.parametrize("mean", [(0.10, 0.0), (0.10, 0.05), (0.3, 0.2), (-0.02, 0.049)])
def test_mean_on_or_beyond_the_boundary(mean: tuple[float, float]) -> None:
    cov = SIGMA**2 * np.eye(2)
    # Independent axes again, now off-centre: P(inside) = prod (Phi((hi - m)/s) - Phi((lo - m)/s)).
    px = ndtr((0.10 - mean[0]) / SIGMA) - ndtr((-0.10 - mean[0]) / SIGMA)
    py = ndtr((0.05 - mean[1]) / SIGMA) - ndtr((-0.05 - mean[1]) / SIGMA)
    assert probability_outside(RECT, mean, cov) == pytest.approx(1.0 - px * py, abs=1e-10)
    assert probability_outside(RECT, mean, cov, method="quadrature") == pytest.approx(1.0 - px * py, abs=1e-9)


def test_zero_covariance_is_an_indicator() -> None:
    zero = np.zeros((2, 2))
    assert probability_outside(RECT, [0.0, 0.0], zero) == 0.0
    assert probability_outside(RECT, [0.2, 0.0], zero) == 1.0
    np.testing.assert_array_equal(edge_probabilities(RECT, [0.2, 0.0], zero), [0.0, 1.0, 0.0, 0.0])


def test_persistent_bias_over_knots() -> None:
    """One bias e, two knots at +-0.05 m in x: safe iff |e_x| < 0.05 and |e_y| < 0.05."""
    cov = SIGMA**2 * np.eye(2)
    exact, upper = persistent_bias_probability([RECT, RECT], [[0.05, 0.0], [-0.05, 0.0]], cov)
    inside_1d = 1.0 - 2.0 * ndtr(-0.05 / SIGMA)
    assert exact == pytest.approx(1.0 - inside_1d**2, abs=1e-10)
    worst = probability_outside(RECT, [0.05, 0.0], cov)
    assert exact > worst + 0.03  # two-sided motion: more than the worst knot
    assert exact <= upper
    # Nested case (same knot twice): exactly the knot's probability.
    same, _ = persistent_bias_probability([RECT, RECT], [[0.05, 0.0], [0.05, 0.0]], cov)
    assert same == pytest.approx(worst, abs=1e-12)


# ----------------------------------------------------------------------------- geometry


def test_halfplanes_of_the_rectangle() -> None:
    a, b = halfplanes(RECT)
    np.testing.assert_allclose(a, [[0, -1], [1, 0], [0, 1], [-1, 0]], atol=1e-15)
    np.testing.assert_allclose(b, [0.05, 0.10, 0.05, 0.10], atol=1e-15)


def test_signed_margin_hand_values() -> None:
    # Inside at (0.02, 0.01): distances to the edges x=0.10: 0.08, x=-0.10: 0.12, y=0.05: 0.04, y=-0.05: 0.06.
    assert signed_margin(RECT, [0.02, 0.01]) == pytest.approx(0.04, abs=1e-15)
    assert signed_margin(RECT, [0.0, 0.0]) == pytest.approx(0.05, abs=1e-15)
    # Outside near the edge x = 0.10, within its span: -(0.12 - 0.10).
    assert signed_margin(RECT, [0.12, 0.01]) == pytest.approx(-0.02, abs=1e-15)
    # Outside near the vertex (0.10, 0.05): -sqrt(0.03^2 + 0.04^2) = -0.05 (not -0.04 to the line y = 0.05).
    assert signed_margin(RECT, [0.13, 0.09]) == pytest.approx(-0.05, abs=1e-15)
    # On the boundary.
    assert signed_margin(RECT, [0.10, 0.0]) == pytest.approx(0.0, abs=1e-15)
    # A triangle (0,0), (1,0), (0,1): at the centroid the hypotenuse x + y = 1 is nearest,
    # (1 - 2/3)/sqrt 2 = 0.2357 < 1/3 (the legs).
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert signed_margin(tri, [1 / 3, 1 / 3]) == pytest.approx((1 / 3) / math.sqrt(2.0), abs=1e-12)
    assert signed_margin(tri, [0.45, 0.45]) == pytest.approx((1.0 - 0.9) / math.sqrt(2.0), abs=1e-12)


# Coordinates in metres on a 1 nm grid (the hull treats turns below 1e-12 extent^2 as straight).
_COORD = st.floats(-1.0, 1.0, allow_nan=False).map(lambda v: round(v, 9))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(_COORD, _COORD), min_size=3, max_size=40))
def test_convex_hull_contains_all_points_and_is_convex(points: list[tuple[float, float]]) -> None:
    pts = np.array(points)
    hull = convex_hull(pts)
    # Every hull vertex is one of the points.
    assert all(np.any(np.all(pts == v, axis=1)) for v in hull)
    if len(hull) < 3:
        # Degenerate input: all points on one line through the (at most 2) extremes.
        if len(hull) == 2:
            d = hull[1] - hull[0]
            cross = d[0] * (pts[:, 1] - hull[0, 1]) - d[1] * (pts[:, 0] - hull[0, 0])
            assert np.all(np.abs(cross) <= 1e-9)
        return
    # Strictly convex and counter-clockwise: every turn is a left turn.
    nxt, nxt2 = np.roll(hull, -1, axis=0), np.roll(hull, -2, axis=0)
    turns = (nxt[:, 0] - hull[:, 0]) * (nxt2[:, 1] - hull[:, 1]) - (nxt[:, 1] - hull[:, 1]) * (
        nxt2[:, 0] - hull[:, 0]
    )
    assert np.all(turns > 0.0)
    assert polygon_area(hull) > 0.0
    # Every point is inside or on the boundary.
    assert min(signed_margin(hull, p) for p in pts) >= -1e-9


def test_clip_polygon_half_plane() -> None:
    clipped = clip_polygon(RECT, [1.0, 0.0], 0.0)  # keep x <= 0
    assert polygon_area(clipped) == pytest.approx(0.10 * 0.10, abs=1e-15)
    assert clip_polygon(RECT, [1.0, 0.0], -0.2).shape == (0, 2)
    np.testing.assert_array_equal(clip_polygon(RECT, [1.0, 0.0], 0.2), RECT)


# ----------------------------------------------------------------------------- seed and capture point


def test_seed_circle_risk() -> None:
    r, b = 0.04, 2.0
    assert seed_fall_risk(0.05, r, b) == 0.0  # circle inside
    assert seed_fall_risk(r, r, b) == 0.0  # circle touches the edge
    assert seed_fall_risk(0.0, r, b) == pytest.approx(0.25)  # half out: (1/2)^2
    assert seed_fall_risk(-r, r, b) == pytest.approx(1.0)  # entirely out
    assert seed_fall_risk(-1.0, r, b) == 1.0
    assert seed_fall_risk(-0.001, 0.0, b) == 1.0 and seed_fall_risk(0.001, 0.0, b) == 0.0
    values = [seed_fall_risk(m, r, b) for m in np.linspace(0.06, -0.06, 50)]
    assert all(x <= y for x, y in itertools.pairwise(values))


def test_capture_point() -> None:
    com = np.array([0.03, -0.01, 0.9])
    np.testing.assert_array_equal(capture_point(com, np.zeros(3)), com[:2])
    # omega = sqrt(9.81 / 0.9) = 3.3015 1/s; xi_x = 0.03 + 0.33015 / 3.3015 = 0.13.
    omega = math.sqrt(9.81 / 0.9)
    xi = capture_point(com, [0.1 * omega, 0.0, -0.5])
    np.testing.assert_allclose(xi, [0.13, -0.01], atol=1e-12)
    assert signed_margin(RECT, xi) == pytest.approx(-0.03, abs=1e-12)


# ----------------------------------------------------------------------------- the bundled humanoid


@pytest.fixture(scope="module")
def world() -> World:
    return build(load("book_transfer"))


def test_humanoid_support_polygon_geometry_vs_contacts(world: World) -> None:
    world.reset()
    from_geometry = support_polygon(world, world.data, from_contacts=False)
    # Two soles 0.26 x 0.15 m, centres 0.27 m apart in y: a 0.26 x 0.42 m rectangle.
    assert polygon_area(from_geometry) == pytest.approx(0.26 * 0.42, rel=0.02)
    data = mujoco.MjData(world.model)
    mujoco.mj_resetDataKeyframe(world.model, data, world.ids.keyframe)
    for _ in range(round(1.0 / world.model.opt.timestep)):
        mujoco.mj_step(world.model, data)
    from_physics = support_polygon(world, data, from_contacts=True)
    a_geo, a_phys = polygon_area(from_geometry), polygon_area(from_physics)
    print(
        f"support area: geometry {a_geo:.5f} m^2, contacts after 1 s {a_phys:.5f} m^2 ({data.ncon} contacts)"
    )
    assert a_phys == pytest.approx(a_geo, rel=0.05)
    com = data.subtree_com[world.ids.base_body][:2]
    assert signed_margin(from_physics, com) > 0.1


def _lean_trajectory(world: World, knots: int = 25, duration: float = 1.5) -> Trajectory:
    """Keyframe -> waist pitched forward with the arms raised ahead (min-jerk blend in qpos)."""
    model = world.model
    q0 = world.home_qpos()
    q1 = q0.copy()
    for name, value in (("waist_pitch", 0.6), ("left_shoulder_pitch", -1.2), ("right_shoulder_pitch", -1.2)):
        q1[model.jnt_qposadr[model.joint(name).id]] = value
    times = np.linspace(0.0, duration, knots)
    u = times / duration
    s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
    qpos = (1.0 - s)[:, None] * q0 + s[:, None] * q1
    data = mujoco.MjData(model)
    com = np.zeros((knots, 3))
    for k, q in enumerate(qpos):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        com[k] = data.subtree_com[world.ids.base_body]
    return Trajectory(name="lean", times=times, qpos=qpos, hand_paths={}, com_path=com, carried=None)


def test_assess_fall_on_a_forward_lean(world: World) -> None:
    traj = _lean_trajectory(world)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = assess_fall(world, traj, RiskConfig(), Uncertainty(com=0.03))
    assert report.mode == "fall"
    assert report.severity == RiskConfig().severity.fall
    for key in ("margin", "seed_risk", "probability", "capture_margin", "com_x", "com_y"):
        assert report.traces[key].shape == traj.times.shape
    margin, prob = report.traces["margin"], report.traces["probability"]
    print(
        "margin (m):",
        np.round(margin[::4], 4),
        "\nprobability:",
        np.round(prob[::4], 5),
        f"\ntrajectory P {report.probability:.6f} bounds {report.probability_bounds}",
        f"seed {report.seed_score:.4f}",
        f"\nmin capture margin {report.details['min_capture_margin']:.4f} m",
    )
    # The CoM moves forward towards the front edge: the margin falls, the probability rises.
    assert np.all(np.diff(report.traces["com_x"]) >= -1e-9)
    assert np.all(np.diff(margin) <= 1e-9)
    assert np.all(np.diff(prob) >= -1e-12)
    assert prob[-1] > 100.0 * max(prob[0], 1e-6)
    # Sorted by margin, the probability is non-increasing in the margin.
    order = np.argsort(margin)
    assert np.all(np.diff(prob[order]) <= 1e-12)
    # The CoM is recomputed from qpos: it agrees with the trajectory's own com_path.
    assert float(report.details["com_path_mismatch"]) < 1e-9
    # Persistent bias, one-way motion: the support part of the probability is the worst knot's
    # (nearly).
    lo, hi = report.probability_bounds
    assert lo <= report.probability <= hi
    assert report.details["probability_support"] == pytest.approx(float(np.max(prob)), abs=1e-4)
    # The waist pitch of 0.6 rad tilts the torso past the safe posture's fall tilt (the detector's
    # limit): that is a fall whatever the CoM does.
    tilt = float(np.degrees(0.6))
    assert report.details["max_trunk_tilt_deg"] == pytest.approx(tilt, abs=0.5)
    assert tilt > world.profile.safe_posture.fall_tilt_deg and report.probability == 1.0
    assert report.details["min_margin"] == pytest.approx(float(margin[-1]))
    assert report.seed_score == pytest.approx(float(np.max(report.traces["seed_risk"])))
    # A moving CoM's capture point leads it: smaller capture margin mid-motion.
    mid = len(traj.times) // 2
    assert report.traces["capture_margin"][mid] < margin[mid]
    assert report.traces["capture_margin"][0] == pytest.approx(margin[0], abs=1e-3)


def test_assess_fall_without_uncertainty_uses_the_circle(world: World) -> None:
    traj = _lean_trajectory(world, knots=8)
    config = RiskConfig(fall=FallRiskConfig(circle_radius=0.05, exponent=1.0))
    report = assess_fall(world, traj, config, Uncertainty())
    margin = report.traces["margin"]
    expected = [seed_fall_risk(m, 0.05, 1.0) for m in margin]
    np.testing.assert_allclose(report.traces["seed_risk"], expected)
    inside = bool(np.all(margin > 0.0))
    assert report.details["probability_support"] == (0.0 if inside else 1.0)


def test_convex_hull_examples() -> None:
    # A square with interior points and a point on an edge: the 4 corners, CCW from the lowest x.
    pts = [(0, 0), (1, 0), (1, 1), (0, 1), (0.5, 0.5), (0.5, 0.0), (0.2, 0.7)]
    np.testing.assert_array_equal(convex_hull(pts), [[0, 0], [1, 0], [1, 1], [0, 1]])
    # Collinear points: the two extremes.
    np.testing.assert_array_equal(convex_hull([(0, 0), (2, 2), (1, 1), (3, 3)]), [[0, 0], [3, 3]])


# Two box soles' bottom corners (x, y) at one knot of a planned book_transfer motion: the soles'
# x coordinates differ by floating-point rounding only (1e-16). The monotone chain with a
# tolerance on the turn test dropped the right sole's outer-back corner (-0.126.., -0.21) as
# "collinear", leaving that corner 13 cm outside the support polygon.
_SOLES_AT_A_KNOT = np.array(
    [
        [-0.12624852856246319, 0.060000000000000095],
        [-0.12624852856246319, 0.21000000000000013],
        [0.13375147013753694, 0.060000000000000095],
        [0.13375147013753694, 0.21000000000000013],
        [-0.1262485285624631, -0.20999999999999994],
        [-0.1262485285624631, -0.05999999999999997],
        [0.13375147013753685, -0.20999999999999994],
        [0.13375147013753685, -0.05999999999999997],
    ]
)


def _check_hull_against_scipy(points: np.ndarray, hull: np.ndarray) -> None:
    """Independent reference: qhull (scipy.spatial.ConvexHull) area and vertices, plus containment."""
    from scipy.spatial import ConvexHull

    ref = ConvexHull(points)
    # Every hull vertex is an input point, and the polygon is counter-clockwise and convex.
    assert all(np.any(np.all(points == v, axis=1)) for v in hull)
    nxt, nxt2 = np.roll(hull, -1, axis=0), np.roll(hull, -2, axis=0)
    turns = (nxt[:, 0] - hull[:, 0]) * (nxt2[:, 1] - hull[:, 1]) - (nxt[:, 1] - hull[:, 1]) * (
        nxt2[:, 0] - hull[:, 0]
    )
    assert np.all(turns > 0.0)
    # Same area as qhull's (ConvexHull.volume is the area in 2D).
    assert polygon_area(hull) == pytest.approx(ref.volume, rel=1e-12, abs=1e-15)
    # Every input point (so every qhull vertex) is inside or on the boundary (to rounding).
    a, b = halfplanes(hull)
    assert float(np.max(points @ a.T - b)) <= 1e-12
    # Every qhull vertex is within rounding of one of ours (no corner cut off).
    for v in points[ref.vertices]:
        assert float(np.min(np.hypot(*(hull - v).T))) <= 1e-12


def test_convex_hull_keeps_corners_whose_x_differ_by_rounding() -> None:
    hull = convex_hull(_SOLES_AT_A_KNOT)
    # The two soles span x in [-0.12625, 0.13375], y in [-0.21, 0.21]: a rectangle.
    assert len(hull) == 4
    assert polygon_area(hull) == pytest.approx((0.13375147013753694 + 0.12624852856246319) * 0.42, rel=1e-12)
    _check_hull_against_scipy(_SOLES_AT_A_KNOT, hull)
    # A CoM midway between the soles' front and back edges: its margin is the rectangle's half
    # length (the front and back edges are the nearest), not the distance to a cut corner's chord.
    lo, hi = float(np.min(_SOLES_AT_A_KNOT[:, 0])), float(np.max(_SOLES_AT_A_KNOT[:, 0]))
    assert signed_margin(hull, [(lo + hi) / 2.0, 0.0]) == pytest.approx((hi - lo) / 2.0, abs=1e-12)


def test_convex_hull_with_one_ulp_jitters_of_two_soles() -> None:
    """Each corner's x and y moved by -1, 0 or +1 ulp (random combinations): always the rectangle."""
    rng = np.random.default_rng(7)
    base = np.array([[x, y] for x in (-0.126, 0.134) for y in (0.06, 0.21, -0.21, -0.06)])
    area = 0.26 * 0.42
    for _ in range(400):
        steps = rng.integers(-1, 2, size=base.shape)
        pts = np.where(
            steps > 0, np.nextafter(base, np.inf), np.where(steps < 0, np.nextafter(base, -np.inf), base)
        )
        hull = convex_hull(pts)
        assert len(hull) == 4, (pts.tolist(), hull.tolist())
        assert polygon_area(hull) == pytest.approx(area, rel=1e-12)
        _check_hull_against_scipy(pts, hull)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(-np.pi, np.pi),
    st.lists(st.integers(-3, 3), min_size=16, max_size=16),
    st.floats(0.0, 0.4),
)
def test_convex_hull_of_rotated_jittered_soles_matches_qhull(yaw: float, ulps: list[int], gap: float) -> None:
    """Two rotated soles whose coordinates carry a few ulps of rounding noise: same hull as qhull."""
    corners = np.array([[x, y] for x in (-0.13, 0.13) for y in (0.06, 0.06 + gap, -0.06, -0.06 - gap)])
    rot = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
    pts = corners @ rot.T
    noise = np.array(ulps, dtype=float).reshape(8, 2) * np.spacing(np.abs(pts))
    pts = pts + noise
    hull = convex_hull(pts)
    assert len(hull) == 4  # the outer rectangle of the two soles
    _check_hull_against_scipy(pts, hull)


def test_batched_knot_evaluation_matches_the_per_knot_functions() -> None:
    """fall_batch evaluates many knots at once; each number must be the per-knot function's."""
    from executive.risk.fall_batch import (
        edge_probabilities_batch,
        hulls,
        probability_outside_batch,
        signed_margin_batch,
    )

    rng = np.random.default_rng(3)
    # Soles drifting by rounding-sized and millimetre-sized amounts, one knot with a lifted foot.
    base = np.array([[x, y] for x in (-0.126, 0.134) for y in (0.06, 0.21, -0.21, -0.06)])
    count = 40
    points = base[None] + rng.normal(0.0, 1e-15, (count, 8, 2))
    points[20:] += rng.normal(0.0, 2e-3, (count - 20, 8, 2))
    on_ground = np.ones((count, 8), dtype=bool)
    on_ground[30, :4] = False  # the first foot lifted: a 4-point polygon
    polys = hulls(points, on_ground)
    cov = np.array([[4e-4, 1e-4], [1e-4, 2e-4]])
    means = rng.normal(0.0, 0.08, (count, 2))
    means[5] = [0.5, 0.0]  # outside
    for k in range(count):
        ref = convex_hull(points[k][on_ground[k]])
        got = polys.polygon(k)
        assert polygon_area(got) == pytest.approx(polygon_area(ref), rel=1e-12)
        a, b = halfplanes(got)
        assert float(np.max(points[k][on_ground[k]] @ a.T - b)) <= 1e-12
    for knots, verts in polys.groups.values():
        mu = means[knots]
        margins = signed_margin_batch(verts, mu)
        p_edges = edge_probabilities_batch(verts, mu, cov)
        p_out = probability_outside_batch(verts, mu, cov)
        for j in range(len(knots)):
            assert margins[j] == pytest.approx(signed_margin(verts[j], mu[j]), abs=1e-15)
            np.testing.assert_allclose(p_edges[j], edge_probabilities(verts[j], mu[j], cov), rtol=1e-12)
            assert p_out[j] == pytest.approx(probability_outside(verts[j], mu[j], cov), rel=1e-11, abs=1e-15)
    np.testing.assert_array_equal(
        probability_outside_batch(RECT[None], np.array([[0.3, 0.0]]), np.zeros((2, 2))), [1.0]
    )
