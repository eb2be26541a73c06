"""``executive tree SCENARIO [--dot FILE] [--svg FILE] [--ascii] [--no-guard]``: the mission's tree.

Prints the behaviour tree ``executive run`` builds for the scenario, every alternative's
subtree expanded (:func:`executive.report.tree_view.mission_tree`), as py_trees draws it;
``--dot`` writes its Graphviz source, ``--svg`` a drawing (Graphviz's ``dot`` program needed:
without it, exit 2 with how to install it).
"""

from __future__ import annotations

import argparse

from executive.cli.output_paths import check_file
from executive.errors import ExecutiveError

__all__ = ["add_parser", "run"]


def run(args: argparse.Namespace) -> int:
    """The command; 0 done (errors are raised as ExecutiveError: exit 2 in ``main``)."""
    from executive.report.tree_view import dot_program, dot_source, mission_tree, text, write_svg
    from executive.scenario import load

    dot = check_file(args.dot, "--dot") if args.dot else None
    svg = check_file(args.svg, "--svg") if args.svg else None
    if svg is not None:
        dot_program()  # Graphviz is there, before anything is built
    scenario = load(args.scenario)
    tree = mission_tree(scenario, guard=not args.no_guard)
    print(text(tree.root, unicode=not args.ascii), end="")
    for note in tree.notes:
        print(f"note      {note}")
    print(
        "(alternatives in the task's order: a run ranks them by risk and drops the infeasible; "
        "tasks after the first are laid out with the hands holding what the earlier tasks' steps leave "
        "in them, the objects where the scene starts them)"
    )
    if dot is not None:
        try:
            dot.parent.mkdir(parents=True, exist_ok=True)
            dot.write_text(dot_source(tree.root), encoding="utf-8")
        except OSError as exc:
            raise ExecutiveError(f"--dot {dot}: not written ({exc.strerror or exc})") from None
        print(f"dot       {dot}")
    if svg is not None:
        print(f"svg       {write_svg(tree.root, svg)}")
    return 0


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser], scenario_help: str) -> None:
    """Add ``tree`` to the ``executive`` command's subcommands."""
    p = sub.add_parser(
        "tree",
        help="print the mission's behaviour tree, every alternative's subtree expanded (py_trees' display)",
    )
    p.add_argument("scenario", help=scenario_help)
    p.add_argument("--dot", metavar="FILE", help="also write the tree's Graphviz source (dot) to FILE")
    p.add_argument("--svg", metavar="FILE", help="also draw the tree as SVG (needs Graphviz's dot program)")
    p.add_argument("--ascii", action="store_true", help="ASCII, not unicode (py_trees.display.ascii_tree)")
    p.add_argument("--no-guard", action="store_true", help="the tree of `executive run --no-guard`")
    p.set_defaults(func=run)
