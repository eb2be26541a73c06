"""``executive replay RUN_DIR [--video FILE] [--console]``: a run played back from its record.

Reads a run folder's per-tick record (:mod:`executive.execution.tick_record`). Without
``--video`` it prints a summary per phase (:func:`executive.report.replay.phase_summary`);
with it, it renders the recorded run offscreen into a video of the world it ran in
(:func:`executive.report.replay.render_video`); with ``--console``, it serves the operator's
page with a time slider over the record (:func:`executive.console.commands.serve_replay`). A
killed run replays up to its last whole tick. A missing or unreadable record, or a path that
cannot be written: exit 2 naming it.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

from executive.cli.output_paths import check_file
from executive.console import PORT
from executive.errors import ExecutiveError

__all__ = ["add_parser", "run"]


def run(args: argparse.Namespace) -> int:
    """The command; 0 done (errors are raised as ExecutiveError: exit 2 in ``main``)."""
    from executive.execution.tick_record import load_record
    from executive.report.replay import encoder, phase_summary, rebuild_world, render_video

    if args.console:
        from executive.console.server import require_viser

        require_viser()  # a missing extra fails before anything is read or rendered
    video = None
    if args.video:
        video = check_file(args.video, "--video")
        encoder(video)  # a known type, its encoder installed
        if video.suffix.lower() != ".gif" and (args.width % 2 or args.height % 2):
            raise ExecutiveError(f"--width {args.width} --height {args.height}: H.264 needs even sizes")
    record = load_record(args.run_dir)
    print(phase_summary(record))
    if video is None:
        return _console(args)
    world = rebuild_world(record, args.scenario)
    frames, seconds = render_video(
        record, world, video, fps=args.fps, width=args.width, height=args.height, shadows=args.shadows
    )
    size = f"{args.width}x{args.height}"
    print(f"video     {video}: {frames} frames at {args.fps:g} fps, {size}, rendered in {seconds:.1f} s")
    return _console(args)


def _console(args: argparse.Namespace) -> int:
    """``--console``: the record on the operator's page, until Ctrl-C (without it: 0 at once)."""
    if not args.console:
        return 0
    from executive.console.commands import serve_replay

    return serve_replay(args.run_dir, args.console_port, args.scenario)


def _fps(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected frames per second (a number), got {text!r}") from None
    if not 0.1 <= value <= 240:
        raise argparse.ArgumentTypeError(f"must be from 0.1 to 240 frames per second, got {text}")
    return value


def add_parser(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    pixels: Callable[[str], int],
    port: Callable[[str], int],
) -> None:
    """Add ``replay`` to the ``executive`` command's subcommands (``pixels``, ``port``: main's parsers)."""
    p = sub.add_parser(
        "replay",
        help="play a run folder's per-tick record back: a summary per phase, or a video (--video)",
    )
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run folder (executive run --out DIR)")
    p.add_argument(
        "--video",
        metavar="FILE",
        help="render the run offscreen to FILE: .mp4 .mkv .avi .mov (pip install '.[video]') or .gif",
    )
    p.add_argument("--fps", type=_fps, default=25.0, help="video frames per second (default 25)")
    p.add_argument("--width", type=pixels, default=640, help="video width in pixels (default 640)")
    p.add_argument("--height", type=pixels, default=480, help="video height in pixels (default 480)")
    p.add_argument("--shadows", action="store_true", help="draw shadows and reflections (slow on the CPU)")
    p.add_argument(
        "--scenario", metavar="FILE", help="the run's scenario, if its file is not where the run read it"
    )
    p.add_argument(
        "--console",
        action="store_true",
        help="play it back on the operator's console (a page on 127.0.0.1 with a time slider; "
        'pip install ".[console]")',
    )
    p.add_argument("--console-port", type=port, default=PORT, help=f"the console's port (default {PORT})")
    p.set_defaults(func=run)
