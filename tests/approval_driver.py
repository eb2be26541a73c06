"""Run one approval prompt on this process's terminal, as the executive would (for tests/test_approval.py).

Builds a request with three alternatives (two feasible, one not), submits it to a
:class:`TerminalChannel` on stdin/stdout, polls ``pending.decision`` the way the selector
does every tick, and prints the decision as one line ``DECISION {json}``.

    python tests/approval_driver.py [--timeout S] [--twice]

``--timeout S`` gives the request a deadline; ``--twice`` then submits a second request
(no deadline) to the same channel after the first is resolved, to show that a prompt
ended by a timeout does not keep reading the terminal.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from executive.decision.approval import (
    AlternativeRisk,
    ApprovalRequest,
    PendingApproval,
    TerminalChannel,
)

REQUEST = ApprovalRequest(
    task="task0: transfer book to (0.52, -0.26)",
    alternatives=(
        AlternativeRisk(
            "left_to_right",
            True,
            {
                "collision": 0.0,
                "fall": 0.0012,
                "drop": 0.0019,
                "tracking": 0.0,
                "combined": 0.0031,
                "expected_loss": 0.41,
            },
            0.41,
        ),
        AlternativeRisk(
            "left",
            True,
            {
                "collision": 0.0248,
                "fall": 0.0015,
                "drop": 0.0014,
                "tracking": 0.0,
                "combined": 0.0277,
                "expected_loss": 0.52,
            },
            0.52,
        ),
        AlternativeRisk("right", False, {}, None, reason="right hand cannot reach"),
    ),
    recommended="left_to_right",
    threshold=0.3,
    ordering="expected_loss",
    reason="lowest expected_loss 0.41 (left_to_right) is above the threshold 0.3",
)


def decide(channel: TerminalChannel, timeout_s: float | None) -> None:
    pending = PendingApproval(REQUEST, timeout_s)
    channel.submit(pending)
    while (decision := pending.decision) is None:  # the selector's per-tick poll
        time.sleep(0.01)
    print("DECISION " + json.dumps(decision.as_dict()), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--timeout", type=float, default=None)
    parser.add_argument("--twice", action="store_true")
    args = parser.parse_args()
    channel = TerminalChannel(operator="tester")
    decide(channel, args.timeout)
    if args.twice:
        decide(channel, None)


if __name__ == "__main__":
    main()
