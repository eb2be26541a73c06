"""Risk against payoff: the ``loss_and_time`` ordering ranks by the expected loss plus what the
planned time costs (``risk.loss_per_second``), in the plan, the stopping rule and the tables."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy import integrate, stats
from test_scenario import bundled_dict  # tests/ is on sys.path (pytest's prepend import mode)

from executive.console.risk_table import risk_table
from executive.decision.assessment import assess_task
from executive.decision.selector import risk_row
from executive.report.plots import risk_json
from executive.report.plots import risk_table as plan_table
from executive.risk.fusion import ModePosterior, choice_confidence
from executive.scenario import from_dict, max_ordering_value
from executive.world.model import build


def test_time_shifts_the_stopping_rule_by_each_alternative_s_time_loss() -> None:
    """Two alternatives with the same drop posterior, one 0.05 slower in time loss: P(the
    faster is within 0.02 of the best) against quadrature of the two shifted Beta laws."""
    post = [ModePosterior("drop", 3.0, 27.0, 2.0)]
    offsets = {"fast": 0.0, "slow": 0.05}
    best, confidence, _ = choice_confidence(
        {"fast": post, "slow": post}, "loss_and_time", 0.02, draws=200_000, seed=2, offsets=offsets
    )
    # value = 2 p + offset: P(2 p_f <= 2 p_s + 0.05 + 0.02) with p_f, p_s ~ Beta(3, 27)
    exact, _ = integrate.quad(lambda x: stats.beta.pdf(x, 3, 27) * stats.beta.sf(x - 0.035, 3, 27), 0, 1)
    assert best == "fast" and confidence == pytest.approx(exact, abs=0.004)


def test_a_slow_way_loses_to_a_quick_one_once_time_costs_enough() -> None:
    data = bundled_dict()
    data["mission"][0]["transfer"]["alternatives"] = ["left", "right"]  # the handover beats both on both
    data["risk"]["ordering"] = "loss_and_time"
    data["risk"]["loss_per_second"] = 0.0
    scenario = from_dict(data)
    alternatives = [a for a in assess_task(build(scenario), scenario.mission[0]) if a.risk is not None]
    assert len(alternatives) >= 2
    by_loss = min(alternatives, key=lambda a: a.risk.expected_loss)  # type: ignore[union-attr]
    by_time = min(alternatives, key=lambda a: a.plan.duration)  # type: ignore[union-attr]
    assert by_loss.name != by_time.name, "the bundled scene's lowest-risk way is also its quickest"
    # the rate at which the two tie: loss_a + r T_a = loss_b + r T_b
    dl = by_time.risk.expected_loss - by_loss.risk.expected_loss  # type: ignore[union-attr]
    dt = by_loss.plan.duration - by_time.plan.duration  # type: ignore[union-attr]
    tie = dl / dt
    for rate, winner in ((0.5 * tie, by_loss.name), (2.0 * tie, by_time.name)):
        data["risk"]["loss_per_second"] = rate
        s = from_dict(data)
        ranked = assess_task(build(s), s.mission[0])
        values = {a.name: a.risk.value("loss_and_time") for a in ranked if a.risk is not None}
        for a in ranked:
            if a.risk is not None:
                assert values[a.name] == pytest.approx(a.risk.expected_loss + rate * a.plan.duration)  # type: ignore[union-attr]
        assert min(values, key=values.__getitem__) == winner
    # shown in plan (text and JSON) and the console's table, beside the expected loss
    assert "loss+time" in plan_table(s, "0", ranked).splitlines()[1]
    row = json.loads(risk_json(s, [("0", ranked)]))["tasks"][0]["alternatives"][0]["risk"]
    assert row["loss_and_time"] == pytest.approx(row["expected_loss"] + row["time_loss"])
    rows = [risk_row(a, "loss_and_time") for a in ranked]
    assert "loss+time" in risk_table(rows, "loss_and_time", 1.0).splitlines()[0]
    # with time costing, no threshold is out of reach: the duration has no bound
    assert max_ordering_value(s.risk, s.scene)[0] == math.inf
    assert np.isfinite(max_ordering_value(from_dict(bundled_dict()).risk)[0])
