"""The ``executive`` command.

Exit codes: 0 done, 1 a mission/run failed or was stopped (Ctrl-C, SIGTERM, SIGHUP:
a safe stop, :mod:`executive.cli.signals`), 2 bad input (a malformed scenario,
an unknown name, a model that does not compile, more --jobs than the machine holds).
Errors are one readable paragraph on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from executive import __version__
from executive.cli import replay as replay_command
from executive.cli import schema as schema_command
from executive.cli import tree as tree_command
from executive.cli.output_paths import check_file, check_folder
from executive.cli.signals import interrupted_text, interrupts_held, stop_reason, stop_signals_as_interrupt
from executive.console import PORT
from executive.errors import ExecutiveError
from executive.schema import catalog as registry
from executive.schema.failure_modes import ScenarioDeprecationWarning
from executive.schema.types import Scenario, Task
from executive.tasks.registry import ALLOW_ENV, allowing_modules
from executive.world.model import World, build

if TYPE_CHECKING:
    from executive.console.commands import RunConsole
    from executive.decision.assessment import AlternativeRisk
    from executive.report.render import VideoRecorder

__all__ = ["main"]

FloatArray = NDArray[np.float64]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_BAD_INPUT = 2


def _load(name: str) -> Scenario:
    from executive.scenario import load

    return load(name)


def _load_gated(args: argparse.Namespace) -> Scenario:
    """The scenario of ``run`` and ``plan`` with their ``--rollouts`` and ``--threshold`` applied."""
    from executive.decision.physics_check import with_rollouts
    from executive.scenario import with_threshold

    return with_threshold(with_rollouts(_load(args.scenario), args.rollouts), args.threshold)


def _cmd_list(args: argparse.Namespace) -> int:
    from executive.scenario import load

    print("Bundled scenarios:")
    for name in registry.list_scenarios():
        scenario = load(name)
        first = scenario.description.strip().split(". ")[0]
        print(f"  {name:<20} {first}")
    print("Bundled robots:")
    for name in registry.list_robots():
        print(f"  {name}")
    return EXIT_OK


def _cmd_validate(args: argparse.Namespace) -> int:
    scenario = _load(args.scenario)
    world = build(scenario)
    print(summary(scenario, world))
    return EXIT_OK


def summary(scenario: Scenario, world: World) -> str:
    """A short human-readable description of a scenario and its compiled world."""
    scene = scenario.scene
    lines = [
        f"scenario  {scenario.name}  ({scenario.source})",
        f"robot     {scenario.robot.name}: {world.robot_dof} actuated DoF, "
        f"{world.robot_mass:.1f} kg, model nq={world.model.nq} nv={world.model.nv} nu={world.model.nu}",
        f"table     top at {scene.table.height:.3f} m, "
        f"{scene.table.size[0]:.2f} x {scene.table.size[1]:.2f} m "
        f"centred at ({scene.table.position[0]:.2f}, {scene.table.position[1]:.2f})",
    ]
    for label, bodies in (("object", scene.objects), ("obstacle", scene.obstacles)):
        for b in bodies:
            mass = f", {b.mass:.2f} kg" if b.mass is not None else ""
            size = " x ".join(f"{s:.3f}" for s in b.size)
            pos = ", ".join(f"{p:.3f}" for p in b.position)
            lines.append(f"{label:<9} {b.name}: {b.shape} {size} m at ({pos}){mass}")
    for i, task in enumerate(scenario.mission):
        allowed = ", ".join(task.alternatives) or f"every one {task.kind} offers"
        lines.append(f"task {i}    {task.label()}; alternatives: {allowed}")
    u = scenario.uncertainty
    lines.append(
        f"uncertainty object {u.object_position * 1000:.0f} mm, "
        f"obstacle {u.obstacle_position * 1000:.0f} mm, "
        f"CoM {u.com * 1000:.0f} mm"
        + (
            f", base {u.base_position * 1000:.0f} mm {math.degrees(u.base_yaw_rad):.1f} deg"
            if u.base_position or u.base_yaw_rad
            else ""
        )
        + f" (1-sigma); risk threshold {scenario.risk.threshold}; "
        f"approval {scenario.approval.mode}"
    )
    return "\n".join(lines)


def _cmd_show(args: argparse.Namespace) -> int:
    from executive.report.render import render_png

    png = check_file(args.png, "--png")
    scenario = _load(args.scenario)
    world = build(scenario)
    out = render_png(world, png, width=args.width, height=args.height)
    print(summary(scenario, world))
    print(f"picture   {out} ({args.width}x{args.height})")
    return EXIT_OK


def _cmd_run(args: argparse.Namespace) -> int:
    _check_run_paths(args)
    scenario = _load_gated(args)
    if args.alternative is None:
        return _run_mission(scenario, args)
    return _run_one(scenario, args)


def _check_out(args: argparse.Namespace) -> None:
    """``--out DIR`` (or, without it, the default ``runs/``) must be a folder this process can write."""
    if args.out:
        check_folder(args.out, "--out")
    else:
        check_folder("runs", "the default run folder (no --out)")


def _check_run_paths(args: argparse.Namespace) -> None:
    """``run``'s output paths, before anything is planned: ``--out`` a writable folder, ``--video``
    a writable ``.gif`` file (else an ExecutiveError, exit 2). ``--alternative`` writes no run
    folder: the default one is not checked then."""
    if args.out or args.alternative is None:
        _check_out(args)
    if args.video:
        if Path(args.video).suffix.lower() != ".gif":
            raise ExecutiveError(
                f"--video {args.video}: only animated GIF (.gif) is written (Pillow, no ffmpeg needed)"
            )
        check_file(args.video, "--video")


def _run_mission(scenario: Scenario, args: argparse.Namespace) -> int:
    """The main job: plan every alternative, gate on risk, execute the lowest, re-check live."""
    import os

    from executive.cli.progress import MissionDisplay
    from executive.decision.audit import run_folder
    from executive.runtime.mission import Executive, freeze_startup_heap

    if args.viewer and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ExecutiveError("--viewer needs a display (DISPLAY is not set); use --video FILE.gif offscreen")
    folder = Path(args.out) if args.out else run_folder(scenario.name)
    truth: str | int | None = "exact" if args.exact else args.seed
    console = _open_console(args, scenario.name)
    approval = console.approval(args.approve) if console is not None else args.approve
    recorder = viewer = None
    with interrupts_held() as held:  # a stop signal while it is built stops it once built (the try)
        try:
            executive = Executive(
                scenario, approval=approval, truth=truth, out=folder, guard=not args.no_guard
            )
        except BaseException:
            if console is not None:
                console.close()
            raise
        if console is not None:
            console.attach(executive)
        freeze_startup_heap()  # no full garbage collection pause in the middle of a motion (its doc)
        display = MissionDisplay(executive, sys.stdout)
    try:
        if held:
            raise held[0]
        if args.video:
            from executive.report.render import VideoRecorder

            assert executive.truth is not None
            recorder = VideoRecorder(executive.truth, Path(args.video))
        if args.viewer:
            import mujoco.viewer

            assert executive.truth is not None
            viewer = mujoco.viewer.launch_passive(executive.truth.model, executive.truth.data)
        display.start()
        while not executive.done:
            executive.tick()
            display.update()
            if recorder is not None:
                recorder.capture()
            if viewer is not None:
                viewer.sync()
            if console is not None:
                console.pace(executive)
    except KeyboardInterrupt as interrupt:  # Ctrl-C, SIGTERM or SIGHUP (executive.cli.signals)
        reason, by = stop_reason(interrupt)
        executive.stop(reason, by=by)
    finally:
        if not executive.done:  # an unexpected error: still leave the robot holding and the log closed
            executive.stop("stopped by an error")
        if viewer is not None:
            viewer.close()
        if console is not None:
            console.close()
    display.finish()
    if recorder is not None:
        _save_video(recorder)
    return EXIT_OK if executive.outcome == "success" else EXIT_FAILED


def _open_console(args: argparse.Namespace, title: str) -> RunConsole | None:
    """``--console``: the page, started before anything is planned (None without the option)."""
    if not args.console:
        return None
    from executive.console.commands import open_for_run

    return open_for_run(args.console_port, title)


def _cmd_console(args: argparse.Namespace) -> int:
    from executive.console.commands import serve

    return serve(args.target, args.port)


def _save_video(recorder: VideoRecorder) -> None:
    """Write the video; a failure now (the path was checked before the run) is reported, and the
    mission's outcome (its exit code) stands."""
    try:
        print(f"video     {recorder.save()}")
    except (ExecutiveError, OSError) as exc:
        print(f"executive run: the video was not saved: {exc}", file=sys.stderr)


def _run_one(scenario: Scenario, args: argparse.Namespace) -> int:
    """One named alternative, no selection and no approval (for tests and comparisons)."""
    from executive.execution.runner import run_alternative

    task = scenario.mission[0]
    if args.alternative not in task.alternatives:
        raise ExecutiveError(
            f"{scenario.source}: task 0 has no alternative '{args.alternative}'; "
            f"its alternatives are: {', '.join(task.alternatives)}"
        )
    truth = "exact (truth = estimate)" if args.exact else f"sampled truth, seed {args.seed}"
    print(f"run {scenario.name}: {task.label()}, alternative {args.alternative}, {truth}")
    result = run_alternative(scenario, args.alternative, exact=args.exact, seed=args.seed)
    print(f"outcome   {result.outcome}: {result.message}")
    if result.outcome != "planning_failed":
        print(
            f"timing    planned {result.planned_duration_s:.1f} s of motion in {result.plan_s:.2f} s; "
            f"executed {result.sim_time_s:.1f} s simulated in {result.wall_s:.1f} s wall "
            f"(real-time factor {result.real_time_factor:.1f}), {result.ticks} ticks, "
            f"longest tick {result.max_tick_s * 1000:.2f} ms"
        )
    if result.placement_error_m is not None:
        print(f"placement {result.placement_error_m * 1000:.1f} mm from the target")
    return EXIT_OK if result.success else EXIT_FAILED


def _cmd_plan(args: argparse.Namespace) -> int:
    from executive.decision.assessment import assess_task
    from executive.decision.physics_check import PhysicsCheck
    from executive.report.plots import risk_json, risk_table

    if args.plot:
        check_folder(args.plot, "--plot")
    scenario = _load_gated(args)
    world = build(scenario)
    tasks = []
    physics = PhysicsCheck(scenario.risk.rollouts.jobs)
    physics.pool.warm()  # the workers start while the planner works
    q_start: FloatArray | None = None  # home; after a walk, where the chosen walk ends
    try:
        for i, task in enumerate(scenario.mission):
            label = f"{i}: {task.label()}"
            analytic = assess_task(world, task, q_start=q_start)
            if not args.json:  # the analytic answer at once, the physics check's after it
                print(risk_table(scenario, f"{label}, analytic", analytic))
                print(_checking_text(scenario, analytic), flush=True)
            alternatives, _ = physics.check(world, analytic, q_start=q_start)
            tasks.append((label, alternatives))
            q_start = _stance_after(scenario, world, task, alternatives, q_start)
            _print_plan(args, scenario, world, i, label, alternatives)
    finally:
        physics.close()
    if args.json:
        print(risk_json(scenario, tasks))
    return EXIT_OK


def _stance_after(
    scenario: Scenario,
    world: World,
    task: Task,
    alternatives: list[AlternativeRisk],
    q_start: FloatArray | None,
) -> FloatArray | None:
    """After a task that walks (its kind ``moves_base``, or its chosen alternative walks), the start
    of the next: where the chosen plan ends, the estimate's base put there; else ``q_start``."""
    from executive.report.plots import chosen_index
    from executive.tasks.registry import get as task_kind

    chosen = chosen_index(alternatives, scenario.risk.ordering)
    plan = alternatives[chosen].plan if chosen is not None else None
    if plan is None or not (task_kind(task.kind).moves_base or any(plan.walks.values())):
        return q_start
    end = plan.ordered_trajectories()[-1].qpos[-1].copy()
    world.data.qpos[world.base_qpos] = end[world.base_qpos]
    world.follows_base = True
    return end


def _checking_text(scenario: Scenario, analytic: list[AlternativeRisk]) -> str:
    feasible = [a.name for a in analytic if a.feasible]
    n = scenario.risk.rollouts.count
    rolls = f" and up to {n} rollouts each on sampled truths" if n else ""
    return f"checking {', '.join(feasible) or 'nothing'} in physics: a dry run on the estimate{rolls} ..."


def _print_plan(
    args: argparse.Namespace,
    scenario: Scenario,
    world: World,
    i: int,
    label: str,
    alternatives: list[AlternativeRisk],
) -> None:
    """One task's risk table (unless ``--json``) and its plots (``--plot DIR``)."""
    import mujoco

    from executive.report.plots import plot_alternatives, risk_table
    from executive.risk.fall import support_polygon

    if not args.json:
        print(risk_table(scenario, label, alternatives))
    if args.plot:
        mujoco.mj_forward(world.model, world.data)
        polygon = support_polygon(world, world.data, from_contacts=False)
        for path in plot_alternatives(scenario, alternatives, polygon, Path(args.plot) / f"task{i}"):
            if not args.json:
                print(f"plot      {path}")


def _cmd_campaign(args: argparse.Namespace) -> int:
    from executive.decision.physics_check import with_rollouts
    from executive.validation.campaign import run_campaign, table_text

    _check_jobs(args)
    _check_out(args)
    scenario = with_rollouts(_load(args.scenario), args.rollouts)
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


def _check_jobs(args: argparse.Namespace) -> None:
    """``--jobs`` no more than this machine holds (an ExecutiveError naming the limit, exit 2;
    :mod:`executive.validation.worker_limit`). A Ray cluster at ``RAY_ADDRESS`` is not checked."""
    from executive.validation.worker_limit import check_jobs

    if getattr(args, "backend", "local") == "ray" and os.environ.get("RAY_ADDRESS"):
        return
    check_jobs(args.jobs)


def _cmd_fidelity(args: argparse.Namespace) -> int:
    from executive.validation.fidelity import run_fidelity, table_text

    _check_jobs(args)
    _check_out(args)
    scenario = _load(args.scenario)
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
    )
    print(table_text(result.summary))
    print(f"suite folder {result.folder} (summary.json, table.md, reliability.png, variant-KK.yaml and -KK/)")
    if result.interrupted or not result.summary["complete"]:
        print(
            f"executive fidelity: interrupted. Complete it with: executive fidelity {args.scenario} "
            f"--variants {args.variants} --trials {args.trials} --seed {result.summary['seed']} "
            f"--rollouts {result.summary['rollouts']}{' --decide' if args.decide else ''} --resume "
            f"--out {result.folder}",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return EXIT_OK


def _whole_number(low: int, high: int, what: str, high_text: str = "") -> Callable[[str], int]:
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


_SEED = _whole_number(0, 2**63 - 1, "a seed", "2**63-1")
_PIXELS = _whole_number(1, 16384, "pixels")
_PORT = _whole_number(0, 65535, "a TCP port on 127.0.0.1; 0: any free one")
_ROLLOUTS = _whole_number(0, 10_000, "rollouts per alternative; 0: off")
_TRIALS = _whole_number(1, 1_000_000, "trials")
_JOBS = _whole_number(1, 1024, "worker processes")
_TASK = _whole_number(0, 10_000, "a task index, 0 for the first")
_JOBS_LIMIT = "at most the usable cores, and the available memory over ~300 MB"


_SCENARIO_HELP = "a scenario file path, or the name of a bundled scenario (see `executive list`)"
_ROLLOUTS_HELP = (
    "physics rollouts per alternative on truths sampled from the uncertainty (overrides the "
    "scenario's risk.rollouts.count; 0: off, the dry runs still run)"
)
_DECIDE_HELP = (
    "each trial first decides as the executive does, on its own estimate (plans, analytic risk, "
    "dry runs, risk.rollouts rollouts, fusion); its records score the numbers it decided with"
)
_THRESHOLD_HELP = (
    "override risk.threshold: above it the lowest-risk alternative needs approval (>= 0 and below "
    "the largest value risk.ordering can take, so the gate can never be switched off)"
)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="executive",
        description="Risk-gated behaviour-tree executive for humanoid robots.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_inspection(sub)
    _add_run(sub)
    _add_campaign(sub)
    _add_fidelity(sub)
    tree_command.add_parser(sub, _SCENARIO_HELP)
    replay_command.add_parser(sub, _PIXELS, _PORT)
    _add_console(sub)
    schema_command.add_parser(sub)
    for name, command in sub.choices.items():
        if name not in ("list", "schema"):  # every command that loads a scenario
            command.add_argument(
                "--allow-module",
                action="append",
                default=[],
                metavar="MODULE",
                help=f"let `kind: MODULE:Class` tasks import MODULE (repeatable; or {ALLOW_ENV}=M1,M2)",
            )
    return parser


def _add_inspection(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The commands that look without executing: list, validate, show, plan."""
    p = sub.add_parser("list", help="name the bundled scenarios and robots")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("validate", help="load a scenario, build its world, print a summary")
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("show", help="render the scenario's scene to a PNG (offscreen)")
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.add_argument("--png", required=True, help="output PNG file")
    p.add_argument("--width", type=_PIXELS, default=960, help="picture width in pixels (default 960)")
    p.add_argument("--height", type=_PIXELS, default=720, help="picture height in pixels (default 720)")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("plan", help="plan every alternative and print its predicted risk (no execution)")
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.add_argument("--json", action="store_true", help="print the table as JSON for machines")
    p.add_argument("--plot", metavar="DIR", help="write CoM/support-polygon and distance plots to DIR")
    p.add_argument("--rollouts", type=_ROLLOUTS, metavar="N", help=_ROLLOUTS_HELP)
    p.add_argument("--threshold", type=float, metavar="X", help=_THRESHOLD_HELP)
    p.set_defaults(func=_cmd_plan)


def _add_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The run command."""
    p = sub.add_parser(
        "run",
        help="run the mission: plan every alternative, gate on risk, execute the lowest-risk one in physics",
    )
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.add_argument("--rollouts", type=_ROLLOUTS, metavar="N", help=_ROLLOUTS_HELP)
    p.add_argument("--threshold", type=float, metavar="X", help=_THRESHOLD_HELP)
    p.add_argument(
        "--alternative",
        help="execute this alternative of task 0 only (left, right, left_to_right, ...): "
        "no selection, no approval",
    )
    p.add_argument("--exact", action="store_true", help="the truth equals the estimate (no sampled error)")
    p.add_argument(
        "--seed", type=_SEED, default=None, help="seed of the sampled truth (default: trials.seed)"
    )
    p.add_argument(
        "--approve",
        choices=("prompt", "auto", "deny"),
        default=None,
        help="approval above the risk threshold (default: the scenario's; prompt only on a terminal)",
    )
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/<timestamp>-<scenario>)")
    p.add_argument("--viewer", action="store_true", help="open the MuJoCo viewer (needs a display)")
    p.add_argument("--video", metavar="FILE.gif", help="record an offscreen video of the run")
    p.add_argument("--no-guard", action="store_true", help="run without the live risk guards")
    p.add_argument(
        "--console",
        action="store_true",
        help="the operator's console: a page on 127.0.0.1 showing the run live, approvals answered there "
        '(pip install ".[console]")',
    )
    p.add_argument("--console-port", type=_PORT, default=PORT, help=f"the console's port (default {PORT})")
    p.set_defaults(func=_cmd_run)


def _add_campaign(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The campaign command."""
    p = sub.add_parser(
        "campaign",
        help="Monte Carlo validation: N sampled truths per alternative executed in physics, "
        "predicted risk vs observed failures",
    )
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.add_argument(
        "--trials", type=_TRIALS, default=None, help="trials per alternative (default: trials.count)"
    )
    p.add_argument(
        "--jobs", type=_JOBS, default=1, help=f"parallel worker processes (default 1; {_JOBS_LIMIT})"
    )
    p.add_argument("--out", metavar="DIR", help="run folder (default runs/<timestamp>-<scenario>-campaign)")
    p.add_argument("--resume", action="store_true", help="complete the campaign in --out DIR")
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local processes (default) or Ray tasks (pip install .[cluster])",
    )
    p.add_argument("--seed", type=_SEED, default=None, help="seed of trial 0 (default: trials.seed)")
    p.add_argument("--task", type=_TASK, default=0, help="index of the mission's task (default 0)")
    p.add_argument("--alternatives", help="comma-separated subset of the task's alternatives (default: all)")
    p.add_argument("--decide", action="store_true", help=_DECIDE_HELP)
    p.add_argument("--rollouts", type=_ROLLOUTS, metavar="N", help=_ROLLOUTS_HELP)
    p.set_defaults(func=_cmd_campaign)


def _add_fidelity(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The fidelity command."""
    p = sub.add_parser(
        "fidelity",
        help="variation suite: K seeded variants of the scene, a campaign on each; does the risk "
        "ranking hold (predicted vs observed, regret of the per-trial choice)?",
    )
    p.add_argument("scenario", help=_SCENARIO_HELP)
    p.add_argument("--variants", type=int, default=10, help="number of scene variants K (default 10)")
    p.add_argument("--trials", type=int, default=10, help="trials per alternative and variant (default 10)")
    p.add_argument(
        "--jobs",
        type=_JOBS,
        default=1,
        help=f"parallel worker processes per campaign (default 1; {_JOBS_LIMIT})",
    )
    p.add_argument("--out", metavar="DIR", help="suite folder (default runs/<timestamp>-<scenario>-fidelity)")
    p.add_argument("--seed", type=_SEED, default=None, help="seed of the variants (default: trials.seed)")
    p.add_argument(
        "--rollouts",
        type=_ROLLOUTS,
        default=None,
        help="risk.rollouts.count of every variant (default: the scenario's with --decide, else 0: off)",
    )
    p.add_argument("--decide", action="store_true", help=_DECIDE_HELP)
    p.add_argument("--resume", action="store_true", help="complete the suite in --out DIR")
    p.set_defaults(func=_cmd_fidelity)


def _add_console(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The console command."""
    p = sub.add_parser(
        "console",
        help="the operator's console on 127.0.0.1: a run folder's decisions, or a scenario's alternatives "
        'planned and checked but not executed (pip install ".[console]")',
    )
    p.add_argument("target", help="a run folder, or " + _SCENARIO_HELP)
    p.add_argument("--port", type=_PORT, default=PORT, help=f"the page's port (default {PORT})")
    p.set_defaults(func=_cmd_console)


def _show_scenario_warning(command: str) -> Callable[..., None]:
    """``warnings.showwarning`` that prints a scenario's deprecation as one line (no source line)."""
    default = warnings.showwarning

    def show(message: Warning | str, category: type[Warning], *rest: object, **kw: object) -> None:
        if issubclass(category, ScenarioDeprecationWarning):
            print(f"executive {command}: warning: {message}", file=sys.stderr)
        else:
            default(message, category, *rest, **kw)  # type: ignore[arg-type]

    return show


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the console script; returns the exit code."""
    args = _parser().parse_args(argv)
    warnings.showwarning = _show_scenario_warning(args.command)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        with stop_signals_as_interrupt(), allowing_modules(getattr(args, "allow_module", ())):
            return func(args)
    except ExecutiveError as exc:
        print(f"executive {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # the reader went away (``| head``): nothing more to say to it
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit
        return EXIT_OK
    except OSError as exc:  # a path the checks could not foresee (a disk filled, a folder removed)
        print(f"executive {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as interrupt:  # Ctrl-C, SIGTERM or SIGHUP: exit 1 all three
        print(f"executive {args.command}: {interrupted_text(interrupt)}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
