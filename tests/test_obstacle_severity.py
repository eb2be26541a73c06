"""An obstacle's own severity, clearance and category (issue 17): closed forms and the planner.

A sphere (the "hand", radius 2 cm) slides along x past the -y face of box ``a`` and the +y face
of box ``b`` (10 cm cubes), staying within both faces, so every near pair has the face's normal
and the first-order probability of touching a body is ``Phi(-d / sigma)`` in closed form (one
half-plane: collision_probability's single-event case). The seed metric scores each body against
its own ``d_safety``. The planner test plans book_transfer with the stack given its own clearance
and measures the least distance to it with coal over the planned knots.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.stats import norm

from executive import scenario
from executive.cli.main import main
from executive.planning.planner import Planner
from executive.risk.collision import CollisionModel, CollisionSetup, assess_collision
from executive.risk.report import RiskReport
from executive.schema import catalog
from executive.schema.types import RiskConfig, Severity
from executive.tasks.steps import plan_alternative
from executive.world.model import build

GAP_A, GAP_B, SIGMA = 0.03, 0.04, 0.01  # m: the hand's gap to each face, the boxes' 1-sigma
XML = f"""
<mujoco>
  <worldbody>
    <body name="a" pos="0.5 {0.07 + GAP_A} 0"><geom name="a" type="box" size="0.05 0.05 0.05"/></body>
    <body name="b" pos="0.5 {-(0.07 + GAP_B)} 0"><geom name="b" type="box" size="0.05 0.05 0.05"/></body>
    <body name="hand">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="y" type="slide" axis="0 1 0"/>
      <joint name="z" type="slide" axis="0 0 1"/>
      <geom name="hand" type="sphere" size="0.02"/>
    </body>
  </worldbody>
</mujoco>
"""
SOURCE = catalog.scenario_path("book_transfer").read_text()


@dataclasses.dataclass(frozen=True)
class _Path:
    """The hand's straight path along x, within both faces (x in [0.47, 0.53])."""

    times: np.ndarray = dataclasses.field(default_factory=lambda: np.linspace(0.0, 1.0, 31))
    carried: tuple[str, str] | None = None

    @property
    def qpos(self) -> np.ndarray:
        x = np.linspace(0.47, 0.53, len(self.times))
        return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


def _report(
    clearance: dict[str, float] | None = None,
    severity: dict[str, float] | None = None,
    breach: tuple[str, ...] = (),
) -> RiskReport:
    """The collision report of the hand's path, the boxes given their own keys by name."""
    model = mujoco.MjModel.from_xml_string(XML)
    body = {name: int(model.body(name).id) for name in ("a", "b")}
    setup = CollisionSetup(
        robot_geoms=(int(model.geom("hand").id),),
        env_geoms=(int(model.geom("a").id), int(model.geom("b").id)),
        env_sigma={body["a"]: SIGMA, body["b"]: SIGMA},
        env_clearance={body[n]: v for n, v in (clearance or {}).items()},
        env_severity={body[n]: v for n, v in (severity or {}).items()},
        breach_bodies=frozenset(body[n] for n in breach),
    )
    config = RiskConfig(d_safety=0.05, severity=Severity(collision=3.0))
    return assess_collision(CollisionModel.from_setup(model, setup, config), _Path())


P_A, P_B = float(norm.cdf(-GAP_A / SIGMA)), float(norm.cdf(-GAP_B / SIGMA))


def test_the_probability_is_the_union_of_the_single_obstacle_closed_forms() -> None:
    report = _report()
    assert report.probability == pytest.approx(1.0 - (1.0 - P_A) * (1.0 - P_B), rel=1e-9)
    # Default severities: the collision severity, exactly as before the keys existed.
    assert report.severity == 3.0
    assert "breach_probability" not in report.details


def test_each_obstacle_is_scored_against_its_own_d_safety() -> None:
    # a nearer (3 cm) but passable at 2 cm: its seed risk is 0; b (4 cm, d_safety 5 cm) scores.
    report = _report(clearance={"a": 0.02})
    assert report.details["peak_term"] == pytest.approx((1.0 - GAP_B / 0.05) ** 2, rel=1e-9)
    assert report.details["min_distance"] == pytest.approx(GAP_A, abs=1e-9)  # still the nearest
    # a's window never under 8 cm: (1 - 3/8)^2, and the time inside is the whole path.
    report = _report(clearance={"a": 0.08})
    assert report.details["peak_term"] == pytest.approx((1.0 - GAP_A / 0.08) ** 2, rel=1e-9)
    assert report.details["exposure_term"] == 1.0
    # The touch probability does not depend on d_safety.
    assert report.probability == pytest.approx(1.0 - (1.0 - P_A) * (1.0 - P_B), rel=1e-9)


def test_the_expected_loss_weights_each_obstacle_by_its_severity() -> None:
    union = 1.0 - (1.0 - P_A) * (1.0 - P_B)

    def loss(s_a: float, s_b: float) -> float:
        return _report(severity={"a": s_a, "b": s_b}).expected_loss

    # P x sum_b P_b s_b / sum_b P_b (body-part factor 1: the hand geom is in no part)
    assert loss(50.0, 3.0) == pytest.approx(union * (P_A * 50.0 + P_B * 3.0) / (P_A + P_B), rel=1e-9)
    share_a = union * P_A * 50.0 / (P_A + P_B)
    assert loss(100.0, 3.0) - loss(50.0, 3.0) == pytest.approx(share_a, rel=1e-9)  # doubled share
    assert loss(3.0, 3.0) == pytest.approx(union * 3.0, rel=1e-12)


def test_a_breach_obstacle_is_reported_on_its_own() -> None:
    report = _report(severity={"a": 100.0}, breach=("a",))
    assert report.details["breach_probability"] == pytest.approx(P_A, rel=1e-9)
    assert report.details["breach_expected_loss"] == pytest.approx(P_A * 100.0, rel=1e-9)
    assert report.details["breach_bodies"] == "a"
    assert report.probability > float(report.details["breach_probability"])  # b is touchable too


def _with_stack(keys: str) -> scenario.Scenario:
    """book_transfer with ``keys`` (YAML lines) added to its stack."""
    lines = "".join(f"      {line}\n" for line in keys.split(";"))
    return scenario.loads(
        SOURCE.replace("      # Optional, per obstacle", lines + "      # Optional, per obstacle")
    )


def test_the_scene_keys_reach_the_collision_model() -> None:
    world = build(_with_stack("severity: 100;clearance: 0.05;category: breach"))
    stack = int(world.model.geom_bodyid[world.ids.obstacle_geoms["book_stack"]])
    setup = CollisionModel(world).setup
    assert setup.env_clearance == {stack: 0.05}
    assert setup.env_severity == {stack: 100.0}
    assert setup.breach_bodies == frozenset({stack})


@pytest.mark.parametrize("side", ["left", "right"])
def test_the_planner_keeps_an_obstacles_own_clearance(side: str) -> None:
    def least_distance(clearance: float | None) -> float:
        s = _with_stack(f"clearance: {clearance}") if clearance else scenario.loads(SOURCE)
        world = build(s)
        plan = plan_alternative(Planner(world), world, s.mission[0], side)
        model = CollisionModel(world)
        stack = int(world.model.geom_bodyid[world.ids.obstacle_geoms["book_stack"]])
        near = [
            p.distance
            for traj in plan.ordered_trajectories()
            for knot in model.profile(traj).knots
            for p in knot.near
            if p.env_body == stack
        ]
        return min(near, default=math.inf)

    # The one-arm carry passes the stack at about the planner's 2 cm; with 5 cm of its own it
    # keeps 5 cm (less the knots' check tolerance, 2 mm).
    assert least_distance(None) < 0.04
    assert least_distance(0.05) >= 0.05 - 0.002


@pytest.mark.parametrize(
    ("keys", "message"),
    [("clearance: -0.02", "> 0"), ("severity: 0", "> 0"), ("category: window", "expected one of")],
)
def test_bad_keys_are_refused_with_their_key_path(
    keys: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(
        SOURCE.replace("      # Optional, per obstacle", f"      {keys}\n      # Optional, per obstacle")
    )
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: scene.obstacles[0].{keys.split(':')[0]}" in err, err
    assert message in err and "Traceback" not in err


def test_the_risk_table_and_the_decision_rows_give_the_breach() -> None:
    from executive.decision.assessment import assess_task
    from executive.decision.selector import risk_row
    from executive.report.plots import risk_json, risk_table

    s = _with_stack("severity: 100;category: breach")
    rows = assess_task(build(s), s.mission[0])
    table = risk_table(s, "transfer", rows)
    data = json.loads(risk_json(s, [("transfer", rows)]))["tasks"][0]["alternatives"]
    for alt, machine in zip(rows, data, strict=True):
        assert alt.risk is not None
        collision = alt.risk.components["collision"]
        breach = risk_row(alt, s.risk.ordering)["breach"]
        assert breach == machine["risk"]["breach"]
        assert breach["bodies"] == "book_stack"
        # The stack is the only breach body: its probability is at most the collision's, and
        # its loss at most the collision's (severity 100 weighted in, never more than all of it).
        assert 0.0 <= breach["probability"] <= collision.probability
        assert breach["expected_loss"] <= collision.expected_loss + 1e-12
        assert f"breach (book_stack): P {breach['probability']:.4f}" in table
    plain = scenario.loads(SOURCE)
    assert "breach" not in risk_table(plain, "transfer", assess_task(build(plain), plain.mission[0]))


def test_the_live_guard_keeps_an_obstacles_own_limit() -> None:
    """The carry planned with the planner's 2 cm passes the stack at about 2.5 cm: the default
    guard (1 cm) lets it pass; with the stack's own 5 cm clearance the guard's limit for the stack
    is max(5 - 1, 5 / 2) = 4 cm and it trips there, naming the stack and its own distance."""
    from executive.monitoring.live_risk import LiveRiskMonitor, obstacle_guard_limits

    plain = scenario.loads(SOURCE)
    world = build(plain)
    plan = plan_alternative(Planner(world), world, plain.mission[0], "left")
    traj = plan.trajectories["left.transfer"]
    own = _with_stack("clearance: 0.05")
    verdicts = {}
    for label, s in (("default", plain), ("own", own)):
        estimate = build(s)
        monitor = LiveRiskMonitor(estimate, s.risk.guard)
        allow = monitor.collision.step_allow("left", "carry", "book", (), traj.carried)
        stack = int(estimate.model.geom_bodyid[estimate.ids.obstacle_geoms["book_stack"]])
        if label == "own":
            assert obstacle_guard_limits(estimate, s.risk.guard) == {stack: pytest.approx(0.04)}
        distance = [
            min(
                (
                    p.distance
                    for p in monitor.collision.knot(q, carried="book", allow=allow).near
                    if p.env_body == stack
                ),
                default=math.inf,
            )
            for q in traj.qpos
        ]
        k = int(np.argmin(distance))
        verdicts[label] = (
            distance[k],
            monitor.check(
                traj.qpos[k],
                traj.qpos,
                traj.times,
                float(traj.times[k]),
                carried="book",
                allow=allow,
                com_margin=None,
            ),
        )
    (d_plain, plain_verdict), (d_own, own_verdict) = verdicts["default"], verdicts["own"]
    assert d_plain == pytest.approx(d_own, abs=1e-12)
    assert 0.02 < d_plain < 0.04
    print(
        f"stack {d_plain * 1000:.1f} mm; default: {plain_verdict.reason or 'ok'}; own: {own_verdict.reason}"
    )
    assert plain_verdict.ok, plain_verdict.reason
    assert not own_verdict.ok and own_verdict.env_body == "book_stack"
    assert "limit 40 mm, its own from its clearance)" in own_verdict.reason
    assert own_verdict.min_distance <= d_own + 1e-9  # the pair's own distance (now or ahead)


def test_a_fidelity_variant_keeps_an_obstacles_own_keys(tmp_path: Path) -> None:
    from executive.validation.variants import base_document, make_variant

    path = tmp_path / "breach.yaml"
    keys = "      severity: 30\n      clearance: 0.04\n      category: breach\n"
    path.write_text(SOURCE.replace("      # Optional, per obstacle", keys + "      # Optional, per obstacle"))
    base = scenario.load(path)
    stack = make_variant(base, base_document(base), 0, 0).scenario.scene.obstacles[0]
    assert (stack.severity, stack.clearance, stack.category) == (30.0, 0.04, "breach")
