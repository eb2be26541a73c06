"""`executive plan`: every alternative planned and assessed, one chosen, machine-readable output.

The bundled book_transfer is planned once for this module (``plan --json --plot``, with the
scenario's own rollouts) and each test reads that one output.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from executive.scenario import load

SCRIPT = Path(sys.executable).parent / "executive"


@pytest.fixture(scope="module")
def planned(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], Path]:
    """``executive plan book_transfer --json --plot DIR`` as a subprocess: its JSON and DIR."""
    plots = tmp_path_factory.mktemp("plots")
    cmd = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main"]
    out = subprocess.run(
        [*cmd, "plan", "book_transfer", "--json", "--plot", str(plots)],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout), plots


def test_plan_json_lists_every_alternative_with_probabilities(planned: tuple[dict[str, Any], Path]) -> None:
    doc, tmp_path = planned
    (task,) = doc["tasks"]
    names = [a["name"] for a in task["alternatives"]]
    assert names == ["left", "right", "left_to_right"]
    feasible = [a for a in task["alternatives"] if a["feasible"]]
    assert sum(a["chosen"] for a in task["alternatives"]) == (1 if feasible else 0)
    for alt in feasible:
        risk = alt["risk"]
        for key in ("collision", "fall", "drop", "combined"):
            assert 0.0 <= risk[key] <= 1.0, (alt["name"], key, risk[key])
        lower, upper = risk["combined_bounds"]
        assert lower - 1e-12 <= risk["combined"] <= upper + 1e-12
        assert max(risk["collision"], risk["fall"], risk["drop"]) <= risk["combined"] + 1e-12
        assert (tmp_path / "task0" / f"{alt['name']}_com.png").is_file()
        assert (tmp_path / "task0" / f"{alt['name']}_distance.png").is_file()
    chosen = next(a for a in feasible if a["chosen"])
    assert chosen["risk"]["expected_loss"] == min(a["risk"]["expected_loss"] for a in feasible)
    # The seed study's finding: the handover keeps farthest from the stack and is the least risky.
    assert chosen["name"] == "left_to_right"
    risk = {a["name"]: a["risk"] for a in feasible}
    for one_arm in ("left", "right"):
        assert risk["left_to_right"]["combined"] < risk[one_arm]["combined"]
        assert risk["left_to_right"]["weighted_sum"] < risk[one_arm]["weighted_sum"]
        # Each one-arm alternative carries the book across the body and its CoM comes nearer the
        # support polygon's edge (min margin ~95 mm vs ~111 mm, sigma 10 mm): a higher P(fall),
        # though every one is tiny (~1e-21 vs ~1e-28). Not the 2.2e-16 floor of 1 - P(inside).
        # Their carry also lowers the pelvis ~4 cm, ~6 sigma above the safe posture's fall floor
        # (executive/robot/posture.py): ~1e-9.
        assert 0.0 < risk["left_to_right"]["fall"] < risk[one_arm]["fall"] < 1e-8


def test_plan_cli_shows_the_dry_runs(planned: tuple[dict[str, Any], Path]) -> None:
    """Every alternative's dry run succeeded; the gate's verdict and the rollouts are the scenario's."""
    doc, _ = planned
    rows = doc["tasks"][0]["alternatives"]
    assert all(r["physics"]["dry_run"]["outcome"] == "success" for r in rows)
    chosen = next(r for r in rows if r["chosen"])
    threshold = load("book_transfer").risk.threshold
    assert chosen["needs_approval"] == (chosen["risk"]["expected_loss"] > threshold)
    cfg = load("book_transfer").risk.rollouts
    # each alternative between the minimum and the cap, and why it got no more
    assert all(cfg.min_count <= r["physics"]["rollouts"] <= cfg.count for r in rows)
    assert all(r["physics"]["stopped"] in ("clear", "count", "budget") for r in rows)
