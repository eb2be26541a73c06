"""``executive schema [--markdown] [--kind package.module:Class ...]``: the scenario format.

Prints the JSON Schema (draft 2020-12) of a scenario with every task kind this installation
finds: the built-in kinds, installed plug-ins (entry points) and those named with ``--kind``
(whose module the flag allows); ``--markdown`` prints the scenario reference page made from it
(``docs/scenarios.md``). A plug-in that fails to load is left out with a warning on stderr.
See :mod:`executive.scenario.json_schema`.
"""

from __future__ import annotations

import argparse
import sys

from executive.errors import ExecutiveError
from executive.tasks.base import TaskKind

__all__ = ["add_parser", "run"]


def run(args: argparse.Namespace) -> int:
    """The command; 0 done (a ``--kind`` that cannot be loaded raises ExecutiveError: exit 2)."""
    from executive.scenario.json_schema import available_kinds, scenario_schema, schema_text
    from executive.scenario.schema_docs import schema_markdown
    from executive.tasks.registry import get

    kinds, problems = available_kinds()
    for problem in problems:
        print(f"executive schema: warning: left out: {problem}", file=sys.stderr)
    named: list[TaskKind] = [get(path, allow_modules=[_module(path)]) for path in args.kind]
    by_name = {kind.name: kind for kind in [*kinds, *named]}
    schema = scenario_schema([by_name[name] for name in sorted(by_name)])
    sys.stdout.write(schema_markdown(schema) if args.markdown else schema_text(schema))
    return 0


def _module(path: str) -> str:
    """The module of ``--kind package.module:Class`` (named on the command line: allowed to import).

    Raises:
        ExecutiveError: not of that form (dotted Python identifiers, a colon, a class name).
    """
    module, colon, name = path.partition(":")
    if not colon or not name.isidentifier() or not all(p.isidentifier() for p in module.split(".")):
        raise ExecutiveError(f"--kind {path!r}: expected package.module:Class")
    return module


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``schema`` to the ``executive`` command's subcommands."""
    p = sub.add_parser(
        "schema",
        help="print the JSON Schema of the scenario format (every key: unit, range, default, words)",
    )
    p.add_argument(
        "--markdown", action="store_true", help="print the scenario reference (docs/scenarios.md) instead"
    )
    p.add_argument(
        "--kind",
        action="append",
        default=[],
        metavar="MODULE:CLASS",
        help="also describe this plug-in task kind (repeatable; imports MODULE)",
    )
    p.set_defaults(func=run)
