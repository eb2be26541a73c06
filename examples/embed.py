"""Embedding the executive in a host controller's 100 Hz loop, with a callback approver.

    python examples/embed.py [SCENARIO] [--threshold X] [--deny]

The host owns the loop: every 10 ms of robot time it calls ``executive.tick()``
(which never blocks: planning runs in a worker thread, approvals are answered
through the callback) and would do its own work in between. Here the executive
steps the bundled MuJoCo physics itself (``control_dt=0.01``: one tick, one
100 Hz control period). ``--threshold`` lowers the scenario's risk threshold so
the approver is asked; ``--deny`` makes it refuse.

Prints the decisions as they are logged, the approver's view of the request,
and the tick statistics the host cares about (longest tick vs the 10 ms period).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time

from executive import (
    ApprovalDecision,
    ApprovalRequest,
    CallbackChannel,
    Executive,
    freeze_startup_heap,
    load,
)
from executive.decision.audit import now_iso

PERIOD_S = 0.01  # the host's control period: 100 Hz


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--threshold", type=float, default=None, help="override risk.threshold")
    parser.add_argument("--deny", action="store_true", help="the approver refuses")
    args = parser.parse_args(argv)

    scenario = load(args.scenario)
    if args.threshold is not None:
        scenario = dataclasses.replace(
            scenario, risk=dataclasses.replace(scenario.risk, threshold=args.threshold)
        )

    def approver(request: ApprovalRequest) -> ApprovalDecision:
        """The host's policy: approve the recommended alternative if its collision risk is small."""
        rows = {a.name: a for a in request.alternatives}
        best = rows[request.recommended] if request.recommended else None
        print(f"[host] approval asked: {request.reason}")
        ok = best is not None and not args.deny and best.risk.get("collision", 1.0) < 0.05
        return ApprovalDecision(
            "approve" if ok else "abort",
            request.recommended if ok else None,
            by="callback:embed-example",
            at=now_iso(),
            note="collision probability below 5 %" if ok else "refused by the host's policy",
        )

    executive = Executive(
        scenario, approval=CallbackChannel(approver, name="embed-example"), truth="exact", control_dt=PERIOD_S
    )
    freeze_startup_heap()  # built once: keep the 27-57 ms full garbage collections out of the loop
    seen = 0
    longest = 0.0
    start = time.perf_counter()
    while not executive.done:
        t0 = time.perf_counter()
        executive.tick()  # one 10 ms control period
        longest = max(longest, time.perf_counter() - t0)
        for entry in executive.log.entries[seen:]:
            if entry["kind"] in ("selection", "approval", "execute", "failure", "outcome"):
                detail = entry.get("reason") or entry.get("alternative") or entry.get("outcome") or ""
                print(f"[{entry['at']}] {entry['kind']}: {detail}")
        seen = len(executive.log.entries)
    summary = executive.summary()
    wall = time.perf_counter() - start
    print(
        f"outcome {summary['outcome']}; {summary['sim_time_s']:.1f} s of robot time in {wall:.1f} s wall; "
        f"{summary['ticks']} ticks, longest tick (tree + physics) {longest * 1000:.1f} ms, "
        f"tree alone {summary['max_tick_s'] * 1000:.1f} ms"
    )
    return 0 if summary["outcome"] == "success" else 1


if __name__ == "__main__":
    sys.exit(main())
