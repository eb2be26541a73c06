"""Embedding the executive in a host controller's 100 Hz loop, with a callback approver.

    python examples/embed.py [SCENARIO] [--threshold X] [--deny]

The host owns the loop and keeps its period: every 10 ms it calls ``executive.tick()`` and
sleeps until the next period (its own work would go in between). ``tick()`` never blocks:
planning, risk assessment, dry runs and rollouts run in the executive's planning worker
process, approvals are answered through the callback, and a tick only takes the results in.
The executive is built with ``pace_waiting=False``, since the host keeps the time itself. Here
the executive steps the bundled MuJoCo physics itself (``control_dt=0.01``: one tick, one 100 Hz
control period), so robot time follows the wall clock. ``--threshold`` lowers the scenario's
risk threshold so the approver is asked; ``--deny`` makes it refuse.

Prints the decisions as they are logged, the approver's view of the request, and the tick
statistics the host cares about: per phase (planning, executing) the median, 99th percentile
and longest ``tick()`` against the 10 ms period, and the periods the loop overran.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from executive import (
    ApprovalDecision,
    ApprovalRequest,
    CallbackChannel,
    Executive,
    freeze_startup_heap,
    load,
)
from executive.decision.audit import now_iso
from executive.scenario import with_threshold

PERIOD_S = 0.01  # the host's control period: 100 Hz


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", nargs="?", default="book_transfer")
    parser.add_argument("--threshold", type=float, default=None, help="override risk.threshold")
    parser.add_argument("--deny", action="store_true", help="the approver refuses")
    args = parser.parse_args(argv)

    scenario = with_threshold(load(args.scenario), args.threshold)  # checked as the file's value

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
        scenario,
        approval=CallbackChannel(approver, name="embed-example"),
        truth="exact",
        control_dt=PERIOD_S,
        pace_waiting=False,  # the host keeps the period
    )
    freeze_startup_heap()  # built once: keep the 27-57 ms full garbage collections out of the loop
    ticks: dict[str, list[float]] = {}
    seen = overruns = 0
    start = next_at = time.perf_counter()
    while not executive.done:
        task = executive.current_task
        phase = task.phase if task is not None else "idle"
        t0 = time.perf_counter()
        executive.tick()  # one 10 ms control period
        ticks.setdefault(phase, []).append(time.perf_counter() - t0)
        for entry in executive.log.entries[seen:]:
            if entry["kind"] in ("selection", "approval", "execute", "failure", "outcome", "planning_worker"):
                detail = entry.get("reason") or entry.get("alternative") or entry.get("outcome") or ""
                print(f"[{entry['at']}] {entry['kind']}: {detail}")
        seen = len(executive.log.entries)
        next_at += PERIOD_S  # the host's own work would go here, then sleep to the next period
        delay = next_at - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        else:
            overruns += 1
            next_at = time.perf_counter()
    summary = executive.summary()
    print(
        f"outcome {summary['outcome']}; {summary['sim_time_s']:.1f} s of robot time in "
        f"{time.perf_counter() - start:.1f} s wall; {summary['ticks']} ticks, {overruns} periods overrun"
    )
    for phase, values in ticks.items():
        ms = np.array(values) * 1e3
        print(
            f"  {phase:<18}{len(ms):>6} ticks: median {np.median(ms):.2f} ms, "
            f"99th percentile {np.percentile(ms, 99):.2f} ms, longest {ms.max():.2f} ms (period 10 ms)"
        )
    return 0 if summary["outcome"] == "success" else 1


if __name__ == "__main__":
    sys.exit(main())
