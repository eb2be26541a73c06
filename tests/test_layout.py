"""The folders show the data flow: the package graph has no cycle, behaviours import nothing above them.

Every import counts, including those only for type checking and those inside
functions: each is a dependency a reader has to follow. Within a package, no module
imports itself back either (the module graph has no cycle).
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_FUNCTION_LINES = 80
MAX_CLASS_LINES = 400
MAX_MODULE_LINES = 700


def _package_of(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[0] == "behaviours":
        return "behaviours"
    return f"executive.{parts[1]}" if len(parts) > 2 else "executive"


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module]
        elif isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        for name in names:
            parts = name.split(".")
            if parts[0] == "behaviours":
                found.add("behaviours")
            elif parts[0] == "executive" and len(parts) > 1 and (ROOT / "executive" / parts[1]).is_dir():
                found.add(f"executive.{parts[1]}")
    return found


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for path in [*ROOT.glob("executive/**/*.py"), *ROOT.glob("behaviours/*.py")]:
        package = _package_of(path)
        graph[package] |= _imports(path) - {package}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph (as a path), or None (depth-first search, three colours)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt) :], nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        state[node] = 2
        stack.pop()
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


def test_the_package_graph_has_no_cycle() -> None:
    graph = _graph()
    assert len(graph) >= 12  # every package was found
    cycle = _cycle(graph)
    assert cycle is None, "packages import each other: " + " -> ".join(cycle or [])


def test_the_cycle_finder_finds_a_cycle() -> None:
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def _module_name(root: Path, path: Path) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_targets(node: ast.AST, package: str, modules: set[str]) -> list[str]:
    """The names ``node`` imports: a relative import resolved from ``package``, ``from pkg import
    name`` as ``pkg.name`` when that is one of ``modules``, else as ``pkg``."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if not isinstance(node, ast.ImportFrom):
        return []
    source = node.module or ""
    if node.level:
        parts = package.split(".")
        source = ".".join([*parts[: len(parts) - (node.level - 1)], *([source] if source else [])])
    return [f"{source}.{a.name}" if f"{source}.{a.name}" in modules else source for a in node.names]


def _module_graph(root: Path, paths: list[Path]) -> dict[str, set[str]]:
    """Which of the modules at ``paths`` (under ``root``) imports which: every import counts
    (top level, under TYPE_CHECKING, inside functions); a dotted name stands for the longest
    prefix of it that is one of the modules (``import a.b.c`` for ``a.b`` when ``c`` is a name)."""
    files = {_module_name(root, p): p for p in paths}

    def known(name: str) -> str:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name

    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        targets = [
            known(target)
            for node in ast.walk(ast.parse(path.read_text()))
            for target in _import_targets(node, package, set(files))
        ]
        graph[module] = set(targets) - {"", module}
    return graph


def test_no_module_imports_itself_back() -> None:
    """A function-level import of a module that imports you back is a cycle too."""
    graph = _module_graph(ROOT, [*ROOT.glob("executive/**/*.py"), *ROOT.glob("behaviours/*.py")])
    assert {"executive.tasks.base", "executive.tasks.registry"} <= graph["executive.tasks.steps"]
    cycle = _cycle(graph)
    assert cycle is None, "modules import each other: " + " -> ".join(cycle or [])


def test_the_module_graph_sees_every_import(tmp_path: Path) -> None:
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from pkg import b, helper\n")
    (package / "b.py").write_text("def f():\n    from . import a\n")
    (package / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pkg.a.name\n"
    )
    graph = _module_graph(tmp_path, sorted(package.glob("*.py")))
    assert graph == {"pkg": set(), "pkg.a": {"pkg", "pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": {"pkg.a"}}
    assert _cycle(graph) == ["pkg.a", "pkg.b", "pkg.a"]


def test_behaviours_import_nothing_that_imports_them() -> None:
    graph = _graph()
    importers = {p for p, deps in graph.items() if "behaviours" in deps}
    assert importers, "someone builds subtrees from behaviours"
    assert not graph["behaviours"] & importers


def test_every_package_is_installed() -> None:
    """pyproject.toml lists the packages to install: a folder missing there works here and fails installed."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    folders = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for p in [*ROOT.glob("executive/**/__init__.py"), *ROOT.glob("behaviours/__init__.py")]
    }
    assert folders <= listed, f"not installed: {sorted(folders - listed)}"


def test_no_library_function_is_longer_than_80_lines() -> None:
    long = []
    for path in [*ROOT.glob("executive/**/*.py"), *ROOT.glob("behaviours/*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, "\n".join(long)


def _too_long(paths: list[Path]) -> list[str]:
    """Modules over MAX_MODULE_LINES and classes over MAX_CLASS_LINES, one line each."""
    long = []
    for path in paths:
        text = path.read_text()
        if (n := len(text.splitlines())) > MAX_MODULE_LINES:
            long.append(
                f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}: module of {n} lines"
            )
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.ClassDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > MAX_CLASS_LINES:
                    long.append(f"{path.name}:{node.lineno} class {node.name} ({lines} lines)")
    return long


def test_no_class_over_400_lines_and_no_module_over_700() -> None:
    long = _too_long([*ROOT.glob("executive/**/*.py"), *ROOT.glob("behaviours/*.py")])
    assert not long, "split along its seams:\n" + "\n".join(long)


def test_the_size_check_sees_a_long_class_and_a_long_module(tmp_path: Path) -> None:
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_CLASS_LINES))
    (tmp_path / "big.py").write_text(f'"""Big."""\n\n\nclass Big:\n{body}\n' + "\n" * MAX_MODULE_LINES)
    (tmp_path / "small.py").write_text('"""Small."""\n\n\nclass Small:\n    x = 1\n')
    found = _too_long([tmp_path / "big.py", tmp_path / "small.py"])
    assert len(found) == 2 and "class Big (401 lines)" in found[1] and "module of" in found[0]


def test_every_module_says_what_it_is() -> None:
    missing = [
        str(path.relative_to(ROOT))
        for path in [*ROOT.glob("executive/**/*.py"), *ROOT.glob("behaviours/*.py")]
        if path.stat().st_size and not ast.get_docstring(ast.parse(path.read_text()))
    ]
    assert not missing


def test_a_source_checkout_finds_its_bundled_scenarios(monkeypatch: pytest.MonkeyPatch) -> None:
    """Run from a checkout (not installed), the scenarios are read in place, beside the package."""
    import importlib.util

    from executive.schema import catalog

    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None)
    catalog.bundled_root.cache_clear()
    try:
        assert catalog.bundled_root() == ROOT / "scenarios"
        assert "book_transfer" in catalog.list_scenarios()
    finally:
        catalog.bundled_root.cache_clear()
