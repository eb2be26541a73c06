"""`executive plan`: every alternative planned and assessed, one chosen, machine-readable output."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(sys.executable).parent / "executive"


def test_plan_json_lists_every_alternative_with_probabilities(tmp_path: Path) -> None:
    cmd = [str(SCRIPT)] if SCRIPT.exists() else [sys.executable, "-m", "executive.cli.main"]
    out = subprocess.run(
        [*cmd, "plan", "book_transfer", "--json", "--plot", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")},
    )
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
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
