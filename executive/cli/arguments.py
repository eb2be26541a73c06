"""What the ``executive`` commands share: exit codes, argument types and help texts, loading.

Each command's module (:mod:`executive.cli.plan`, :mod:`executive.cli.validation`, ...) adds its
parser with these types, so a bad number reads the same everywhere ("must be at least 1, got 0;
valid: from 1 to 1024 (worker processes)").
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable

from executive.cli.output_paths import check_folder
from executive.schema.types import Scenario

__all__ = [
    "DECIDE_HELP",
    "EXIT_BAD_INPUT",
    "EXIT_FAILED",
    "EXIT_OK",
    "JOBS",
    "JOBS_LIMIT",
    "PIXELS",
    "ROLLOUTS",
    "ROLLOUTS_HELP",
    "SCENARIO_HELP",
    "SEED",
    "TASK_INDEX",
    "TCP_PORT",
    "THRESHOLD_HELP",
    "TRIALS",
    "check_jobs",
    "check_out",
    "load_gated",
    "load_scenario",
    "whole_number",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


def whole_number(low: int, high: int, what: str, high_text: str = "") -> Callable[[str], int]:
    """An argparse ``type=``: a whole number in ``[low, high]``, else a message giving the range
    (``high_text`` spells ``high`` where digits would not read well)."""
    valid = f"from {low} to {high_text or high} ({what})"

    def parse(text: str) -> int:
        try:
            value = int(text.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number {valid}, got {text!r}") from None
        if not low <= value <= high:
            bound = f"at least {low}" if value < low else f"at most {high_text or high}"
            raise argparse.ArgumentTypeError(f"must be {bound}, got {value}; valid: {valid}")
        return value

    parse.__name__ = what
    return parse


SEED = whole_number(0, 2**63 - 1, "a seed", "2**63-1")
PIXELS = whole_number(1, 16384, "pixels")
TCP_PORT = whole_number(0, 65535, "a TCP port on 127.0.0.1; 0: any free one")
ROLLOUTS = whole_number(0, 10_000, "rollouts per alternative; 0: off")
TRIALS = whole_number(1, 1_000_000, "trials")
JOBS = whole_number(1, 1024, "worker processes")
TASK_INDEX = whole_number(0, 10_000, "a task index, 0 for the first")
JOBS_LIMIT = "at most the usable cores, and the available memory over ~300 MB"

SCENARIO_HELP = "a scenario file path, or the name of a bundled scenario (see `executive list`)"
ROLLOUTS_HELP = (
    "physics rollouts per alternative on truths sampled from the uncertainty (overrides the "
    "scenario's risk.rollouts.count; 0: off, the dry runs still run)"
)
DECIDE_HELP = (
    "each trial first decides as the executive does, on its own estimate (plans, analytic risk, "
    "dry runs, risk.rollouts rollouts, fusion); its records score the numbers it decided with"
)
THRESHOLD_HELP = (
    "override risk.threshold: above it the lowest-risk alternative needs approval (>= 0 and below "
    "the largest value risk.ordering can take, so the gate can never be switched off)"
)


def load_scenario(name: str) -> Scenario:
    """A scenario by file path or bundled name (:func:`executive.scenario.load`)."""
    from executive.scenario import load

    return load(name)


def load_gated(args: argparse.Namespace) -> Scenario:
    """The scenario of ``run`` and ``plan`` with their ``--rollouts`` and ``--threshold`` applied."""
    from executive.decision.physics_check import with_rollouts
    from executive.scenario import with_threshold

    return with_threshold(with_rollouts(load_scenario(args.scenario), args.rollouts), args.threshold)


def check_out(args: argparse.Namespace) -> None:
    """``--out DIR`` (or, without it, the default ``runs/``) must be a folder this process can write."""
    if args.out:
        check_folder(args.out, "--out")
    else:
        check_folder("runs", "the default run folder (no --out)")


def check_jobs(args: argparse.Namespace) -> None:
    """``--jobs`` no more than this machine holds (an ExecutiveError naming the limit, exit 2;
    :mod:`executive.validation.worker_limit`). A Ray cluster at ``RAY_ADDRESS`` is not checked."""
    from executive.validation.worker_limit import check_jobs as check_machine_jobs

    if getattr(args, "backend", "local") == "ray" and os.environ.get("RAY_ADDRESS"):
        return
    check_machine_jobs(args.jobs)
