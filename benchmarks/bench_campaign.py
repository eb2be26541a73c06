"""Campaign throughput: trials/s with --jobs 2 against --jobs 1, measured in one run.

Target (issue #6): jobs 2 at least 1.7x the trials/s of jobs 1 on a 2-core machine.
Both campaigns run the same seeded trials (so the same physics); the ratio is printed
for the whole campaign (planning the alternatives, starting workers, trials, statistics)
and for the trial phase alone. Also checks that the two trials.jsonl files are equal.

    python benchmarks/bench_campaign.py [--trials 10]
"""

from __future__ import annotations

import argparse
import io
import os
import tempfile
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

from executive.scenario import load
from executive.validation.campaign import run_campaign


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10, help="trials per alternative")
    parser.add_argument("--scenario", default="book_transfer")
    args = parser.parse_args()
    scenario = load(args.scenario)
    rates = {}
    with tempfile.TemporaryDirectory() as tmp:
        for jobs in (1, 2):
            out = Path(tmp) / f"jobs{jobs}"
            result = run_campaign(scenario, trials=args.trials, jobs=jobs, out=out, stream=io.StringIO())
            s = result.summary
            rates[jobs] = (result.new_trials / result.elapsed_s, result.new_trials / s["trial_phase_s"])
            print(
                f"jobs {jobs}: {result.new_trials} trials in {result.elapsed_s:.1f} s "
                f"({rates[jobs][0]:.3f} trials/s; trial phase {s['trial_phase_s']:.1f} s, "
                f"{rates[jobs][1]:.3f} trials/s); failures "
                + ", ".join(f"{a['name']} {a['failures']['any']}/{a['trials']}" for a in s["alternatives"])
            )
        same = (Path(tmp) / "jobs1" / "trials.jsonl").read_bytes() == (
            Path(tmp) / "jobs2" / "trials.jsonl"
        ).read_bytes()
    whole, phase = rates[2][0] / rates[1][0], rates[2][1] / rates[1][1]
    print(f"speed-up jobs 2 / jobs 1: whole campaign {whole:.2f}x, trial phase {phase:.2f}x (target >= 1.7x)")
    print(f"same trials.jsonl for jobs 1 and 2: {same}")
    print(f"machine: {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
