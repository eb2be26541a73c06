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
from executive.cli import plan as plan_command
from executive.cli import replay as replay_command
from executive.cli import schema as schema_command
from executive.cli import tree as tree_command
from executive.cli import validation as validation_commands
from executive.cli.arguments import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    PIXELS,
    ROLLOUTS,
    ROLLOUTS_HELP,
    SCENARIO_HELP,
    SEED,
    TCP_PORT,
    THRESHOLD_HELP,
    check_out,
    load_gated,
    load_scenario,
)
from executive.cli.output_paths import check_file
from executive.cli.signals import interrupted_text, interrupts_held, stop_reason, stop_signals_as_interrupt
from executive.console import PORT
from executive.errors import ExecutiveError
from executive.schema import catalog as registry
from executive.schema.failure_modes import ScenarioDeprecationWarning
from executive.schema.types import Scenario
from executive.tasks.registry import ALLOW_ENV, allowing_modules
from executive.world.model import World, build

if TYPE_CHECKING:
    from executive.console.commands import RunConsole
    from executive.report.render import VideoRecorder

__all__ = ["main"]

FloatArray = NDArray[np.float64]


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
    scenario = load_scenario(args.scenario)
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
    scenario = load_scenario(args.scenario)
    world = build(scenario)
    out = render_png(world, png, width=args.width, height=args.height)
    print(summary(scenario, world))
    print(f"picture   {out} ({args.width}x{args.height})")
    return EXIT_OK


def _cmd_run(args: argparse.Namespace) -> int:
    _check_run_paths(args)
    scenario = load_gated(args)
    if args.alternative is None:
        return _run_mission(scenario, args)
    return _run_one(scenario, args)


def _check_run_paths(args: argparse.Namespace) -> None:
    """``run``'s output paths, before anything is planned: ``--out`` a writable folder, ``--video``
    a writable ``.gif`` file (else an ExecutiveError, exit 2). ``--alternative`` writes no run
    folder: the default one is not checked then."""
    if args.out or args.alternative is None:
        check_out(args)
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


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="executive",
        description="Risk-gated behaviour-tree executive for humanoid robots.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_inspection(sub)
    _add_run(sub)
    plan_command.add_parser(sub)
    validation_commands.add_parsers(sub)
    tree_command.add_parser(sub, SCENARIO_HELP)
    replay_command.add_parser(sub, PIXELS, TCP_PORT)
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
    """The commands that look without executing: list, validate, show."""
    p = sub.add_parser("list", help="name the bundled scenarios and robots")
    p.set_defaults(func=_cmd_list)

    p = sub.add_parser("validate", help="load a scenario, build its world, print a summary")
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("show", help="render the scenario's scene to a PNG (offscreen)")
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument("--png", required=True, help="output PNG file")
    p.add_argument("--width", type=PIXELS, default=960, help="picture width in pixels (default 960)")
    p.add_argument("--height", type=PIXELS, default=720, help="picture height in pixels (default 720)")
    p.set_defaults(func=_cmd_show)


def _add_run(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The run command."""
    p = sub.add_parser(
        "run",
        help="run the mission: plan every alternative, gate on risk, execute the lowest-risk one in physics",
    )
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument("--rollouts", type=ROLLOUTS, metavar="N", help=ROLLOUTS_HELP)
    p.add_argument("--threshold", type=float, metavar="X", help=THRESHOLD_HELP)
    p.add_argument(
        "--alternative",
        help="execute this alternative of task 0 only (left, right, left_to_right, ...): "
        "no selection, no approval",
    )
    p.add_argument("--exact", action="store_true", help="the truth equals the estimate (no sampled error)")
    p.add_argument("--seed", type=SEED, default=None, help="seed of the sampled truth (default: trials.seed)")
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
    p.add_argument("--console-port", type=TCP_PORT, default=PORT, help=f"the console's port (default {PORT})")
    p.set_defaults(func=_cmd_run)


def _add_console(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The console command."""
    p = sub.add_parser(
        "console",
        help="the operator's console on 127.0.0.1: a run folder's decisions, or a scenario's alternatives "
        'planned and checked but not executed (pip install ".[console]")',
    )
    p.add_argument("target", help="a run folder, or " + SCENARIO_HELP)
    p.add_argument("--port", type=TCP_PORT, default=PORT, help=f"the page's port (default {PORT})")
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
