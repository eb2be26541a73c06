"""``executive campaign`` and ``executive fidelity``: the validation commands.

A campaign executes every alternative of one task on sampled truths and scores the predictions
against what physics did (:mod:`executive.validation.campaign`); a fidelity suite runs one on each
of K seeded variants of the scene (:mod:`executive.validation.fidelity`).
"""

from __future__ import annotations

import argparse
import sys

from executive.cli.arguments import (
    DECIDE_HELP,
    EXIT_FAILED,
    EXIT_OK,
    JOBS,
    JOBS_LIMIT,
    ROLLOUTS,
    ROLLOUTS_HELP,
    SCENARIO_HELP,
    SEED,
    TASK_INDEX,
    TRIALS,
    check_jobs,
    check_out,
    load_scenario,
)

__all__ = ["add_parsers", "run_campaign_command", "run_fidelity_command"]


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The campaign and fidelity commands."""
    _add_campaign(sub)
    _add_fidelity(sub)


def _add_campaign(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The campaign command."""
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo validation: N sampled truths per alternative executed in physics, "
        "predicted risk vs observed failures",
    )
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument(
        "--trials", type=TRIALS, default=None, help="trials per alternative (default: trials.count)"
    )
    p.add_argument(
        "--jobs", type=JOBS, default=1, help=f"parallel worker processes (default 1; {JOBS_LIMIT})"
    )
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/<timestamp>-<scenario>-campaign)")
    p.add_argument("--resume", action="store_true", help="complete the campaign in --out DIR")
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local processes (default) or Ray tasks (pip install .[cluster])",
    )
    p.add_argument("--seed", type=SEED, default=None, help="seed of trial 0 (default: trials.seed)")
    p.add_argument("--task", type=TASK_INDEX, default=0, help="index of the mission's task (default 0)")
    p.add_argument("--alternatives", help="comma-separated subset of the task's alternatives (default: all)")
    p.add_argument("--decide", action="store_true", help=DECIDE_HELP)
    p.add_argument("--rollouts", type=ROLLOUTS, metavar="N", help=ROLLOUTS_HELP)
    p.set_defaults(func=run_campaign_command)


def _add_fidelity(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The fidelity command."""
    p = sub.add_parser(
        "fidelity",
        help="variation suite: K seeded variants of the scene, a campaign on each; does the risk "
        "ranking hold (predicted vs observed, regret of the per-trial choice)?",
    )
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument("--variants", type=int, default=10, help="number of scene variants K (default 10)")
    p.add_argument("--trials", type=int, default=10, help="trials per alternative and variant (default 10)")
    p.add_argument(
        "--jobs",
        type=JOBS,
        default=1,
        help=f"parallel worker processes per campaign (default 1; {JOBS_LIMIT})",
    )
    p.add_argument("--out", metavar="DIR", help="suite folder (default runs/<timestamp>-<scenario>-fidelity)")
    p.add_argument("--seed", type=SEED, default=None, help="seed of the variants (default: trials.seed)")
    p.add_argument(
        "--rollouts",
        type=ROLLOUTS,
        default=None,
        help="risk.rollouts.count of every variant (default: the scenario's with --decide, else 0: off)",
    )
    p.add_argument("--decide", action="store_true", help=DECIDE_HELP)
    p.add_argument(
        "--task", type=TASK_INDEX, default=0, help="index of the task each campaign runs (default 0)"
    )
    p.add_argument(
        "--ranges",
        metavar="FILE",
        help="variation ranges (YAML; default: variation/<scenario stem>.yaml beside the scenario "
        "file if there, else the built-in ranges)",
    )
    p.add_argument("--resume", action="store_true", help="complete the suite in --out DIR")
    p.set_defaults(func=run_fidelity_command)


def run_campaign_command(args: argparse.Namespace) -> int:
    """``executive campaign``: run (or resume) a campaign and print its table."""
    from executive.decision.physics_check import with_rollouts
    from executive.validation.campaign import run_campaign, table_text

    check_jobs(args)
    check_out(args)
    scenario = with_rollouts(load_scenario(args.scenario), args.rollouts)
    alternatives = [a.strip() for a in args.alternatives.split(",")] if args.alternatives else None
    result = run_campaign(
        scenario,
        trials=args.trials,
        jobs=args.jobs,
        out=args.out,
        resume=args.resume,
        backend=args.backend,
        seed=args.seed,
        task_index=args.task,
        alternatives=alternatives,
        stream=sys.stdout,
        decide=args.decide,
    )
    print(table_text(result.summary))
    rate = result.trials_per_s
    print(
        f"trials    {result.new_trials} run in {result.elapsed_s:.1f} s wall "
        f"({rate:.2f} trials/s on {args.jobs} job(s), {args.backend}); {len(result.records)} in all"
    )
    print(f"run folder {result.folder} (trials.jsonl, summary.json, table.md, reliability.png)")
    if result.interrupted or not result.summary["complete"]:
        print(
            f"executive campaign: interrupted; {len(result.records)} trial(s) kept. Complete it with: "
            f"executive campaign {args.scenario} --trials {result.summary['trials_per_alternative']} "
            f"{'--decide ' if args.decide else ''}{_rollouts_option(args)}--resume --out {result.folder}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return EXIT_OK


def _rollouts_option(args: argparse.Namespace) -> str:
    return "" if args.rollouts is None else f"--rollouts {args.rollouts} "


def run_fidelity_command(args: argparse.Namespace) -> int:
    """``executive fidelity``: run (or resume) a variation suite and print its table."""
    from executive.validation.fidelity import run_fidelity, table_text

    check_jobs(args)
    check_out(args)
    scenario = load_scenario(args.scenario)
    result = run_fidelity(
        scenario,
        variants=args.variants,
        trials=args.trials,
        jobs=args.jobs,
        out=args.out,
        seed=args.seed,
        rollouts=args.rollouts,
        resume=args.resume,
        stream=sys.stdout,
        decide=args.decide,
        task_index=args.task,
        ranges=args.ranges,
    )
    print(table_text(result.summary))
    print(f"suite folder {result.folder} (summary.json, table.md, reliability.png, variant-KK.yaml and -KK/)")
    if result.interrupted or not result.summary["complete"]:
        print(
            f"executive fidelity: interrupted. Complete it with: executive fidelity {args.scenario} "
            f"--variants {args.variants} --trials {args.trials} --seed {result.summary['seed']} "
            f"--rollouts {result.summary['rollouts']}{' --decide' if args.decide else ''} --task {args.task} "
            f"{f'--ranges {args.ranges} ' if args.ranges else ''}--resume "
            f"--out {result.folder}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return EXIT_OK
