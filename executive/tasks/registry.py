"""The registry of task kinds: the built-in ones, installed plug-ins, and dotted paths.

A kind is found by its YAML key (``transfer``) among, in order: kinds registered in
this process (:func:`register`), the built-in kinds, entry points in the group
``executive.task_kinds`` (``name = "package.module:Class"``), and last the TaskKind
subclasses already imported (a worker process that unpickled a plug-in's task). A scenario may also name
a class directly: ``kind: package.module:Class`` in a task block (see
:func:`resolve`); it is then registered under its name, which its tasks' ``kind`` gives
(a name another kind already has is refused). Kinds are imported only when first asked for.

A dotted path's module is imported only when the caller allows it (a scenario is data, and
importing a module runs its code): ``get("wave_kind:WaveKind", allow_modules=["wave_kind"])``,
or the module named in the environment variable ``EXECUTIVE_ALLOW_MODULES`` (comma-separated;
the CLI's ``--allow-module`` sets it for one command with :func:`allowing_modules`). A name
allows that module and its submodules. Anything else is refused before any import.
"""

from __future__ import annotations

import importlib
import inspect
import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from importlib import metadata

from executive.errors import ExecutiveError
from executive.schema.yaml_nodes import unknown_name
from executive.tasks.base import TaskKind

__all__ = [
    "ALLOW_ENV",
    "ENTRY_POINT_GROUP",
    "TaskKindError",
    "allowed_modules",
    "allowing_modules",
    "available",
    "get",
    "register",
    "resolve",
]

ENTRY_POINT_GROUP = "executive.task_kinds"
#: The environment variable naming the modules a dotted kind may import (comma-separated).
ALLOW_ENV = "EXECUTIVE_ALLOW_MODULES"

#: The kinds that ship with the package, by YAML key.
BUILT_IN: dict[str, str] = {
    "transfer": "executive.tasks.transfer:TransferKind",
    "pick": "executive.tasks.pick_place:PickKind",
    "place": "executive.tasks.pick_place:PlaceKind",
    "push": "executive.tasks.push:PushKind",
    "press": "executive.tasks.press:PressKind",
    "step": "executive.tasks.step:StepKind",
}

_registered: dict[str, TaskKind] = {}


class TaskKindError(ExecutiveError):
    """A task kind that cannot be found or loaded (the message says which and why)."""


def register(kind: TaskKind | type[TaskKind]) -> TaskKind:
    """Make ``kind`` available under its ``name`` in this process (replacing one of that name)."""
    instance = kind() if isinstance(kind, type) else kind
    if not instance.name:
        raise TaskKindError(f"task kind {type(instance).__name__} has no name")
    _registered[instance.name] = instance
    return instance


def _entry_points() -> dict[str, metadata.EntryPoint]:
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def available() -> list[str]:
    """Every kind name that :func:`get` can find, sorted."""
    built = [k for k in BUILT_IN if _importable(BUILT_IN[k])]
    return sorted({*_registered, *built, *_entry_points()})


def _importable(path: str) -> bool:
    return importlib.util.find_spec(path.split(":")[0]) is not None


def resolve(path: str) -> TaskKind:
    """The kind at ``package.module:Class`` (imported now).

    Raises:
        TaskKindError: the module cannot be imported, has no such class, or it is not a TaskKind.
    """
    module_name, sep, attr = path.partition(":")
    if not sep or not module_name or not attr:
        raise TaskKindError(f"'{path}' is not a dotted path of the form package.module:Class")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise TaskKindError(f"cannot import '{module_name}' for task kind '{path}': {error}") from None
    target = getattr(module, attr, None)
    if target is None:
        raise TaskKindError(f"module '{module_name}' has no '{attr}' (task kind '{path}')")
    return _instance(target, path)


def _instance(target: object, where: str) -> TaskKind:
    """``target`` itself or, a class, an instance of it; only a TaskKind is accepted."""
    not_kind = f"'{where}' is not a TaskKind (a subclass of executive.tasks.base.TaskKind)"
    if isinstance(target, type):
        if not issubclass(target, TaskKind):
            raise TaskKindError(not_kind)
        try:
            target = target()
        except Exception as error:  # a plug-in's own constructor, reported with its path
            raise TaskKindError(f"task kind '{where}' cannot be made: {error}") from None
    if not isinstance(target, TaskKind):
        raise TaskKindError(not_kind)
    return target


def allowed_modules(extra: Iterable[str] = ()) -> frozenset[str]:
    """The modules a dotted kind may import: ``extra`` and those :data:`ALLOW_ENV` names."""
    named = os.environ.get(ALLOW_ENV, "").split(",")
    return frozenset(m.strip() for m in (*named, *extra) if m.strip())


@contextmanager
def allowing_modules(modules: Iterable[str]) -> Iterator[None]:
    """Allow ``modules`` (besides those already allowed) while the block runs, in this process
    and the worker processes it starts (through :data:`ALLOW_ENV`); restored afterwards.

    Raises:
        TaskKindError: a name that is no module name (dotted Python identifiers).
    """
    modules = list(modules)
    for name in modules:
        if not all(part.isidentifier() for part in name.strip().split(".")):
            raise TaskKindError(f"--allow-module {name!r}: not a module name (dotted Python identifiers)")
    before = os.environ.get(ALLOW_ENV)
    added = allowed_modules(modules)
    if added:
        os.environ[ALLOW_ENV] = ",".join(sorted(added))
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(ALLOW_ENV, None)
        else:
            os.environ[ALLOW_ENV] = before


def _check_allowed(path: str, allow_modules: Iterable[str]) -> None:
    """Refuse a dotted path whose module is not allowed, before anything is imported.

    Raises:
        TaskKindError: the module is not allowed; the message says how to allow it.
    """
    module_name = path.partition(":")[0]
    allowed = allowed_modules(allow_modules)
    if any(module_name == m or module_name.startswith(m + ".") for m in allowed):
        return
    raise TaskKindError(
        f"task kind '{path}' would import the module '{module_name}', which is not allowed "
        f"(a scenario imports no module unless told to): allow it for this run with "
        f"--allow-module {module_name} or {ALLOW_ENV}={module_name}, or in code "
        f"load(..., allow_modules=['{module_name}'])"
    )


def get(name: str, allow_modules: Iterable[str] = ()) -> TaskKind:
    """The kind called ``name`` (or at ``package.module:Class``).

    Args:
        name: a kind's name, or a dotted path ``package.module:Class``.
        allow_modules: modules a dotted path may import (besides those :data:`ALLOW_ENV` names);
            a name allows the module and its submodules.

    Raises:
        TaskKindError: no kind of that name (the message lists those available), or a dotted
            path whose module is not allowed (nothing is imported then).
    """
    if ":" in name:
        module_name, _, attr = name.partition(":")
        if module_name and attr:
            _check_allowed(name, allow_modules)
        return _register_path(name)
    if name in _registered:
        return _registered[name]
    if name in BUILT_IN:
        return register(resolve(BUILT_IN[name]))
    entry = _entry_points().get(name)
    if entry is None:
        loaded = _imported(name)
        if loaded is None:
            raise TaskKindError(unknown_name("task kind", name, available(), "kinds"))
        return register(loaded)
    try:
        target = entry.load()
    except Exception as error:  # a plug-in's own import error, reported with its name
        problem = f"task kind '{name}' (entry point {entry.value}) fails to load: {error}"
        raise TaskKindError(problem) from None
    return register(_instance(target, f"entry point {entry.value}"))


def _register_path(path: str) -> TaskKind:
    """The kind at a dotted path, registered under its name (later asked for by its tasks' ``kind``).

    Raises:
        TaskKindError: it cannot be resolved, or its name is taken by a different kind.
    """
    kind = resolve(path)
    where = f"{type(kind).__module__}:{type(kind).__qualname__}"
    known = _registered.get(kind.name)
    taken = f"{type(known).__module__}:{type(known).__qualname__}" if known else BUILT_IN.get(kind.name)
    if taken is not None and taken != where:
        raise TaskKindError(f"task kind '{path}' is named '{kind.name}', the name of the kind {taken}")
    return known if known is not None else register(kind)


def _imported(name: str) -> TaskKind | None:
    """The kind called ``name`` among the TaskKind subclasses already imported (None: none is).

    A process that unpickles a task (a physics worker) imports the task's module, and with it
    a kind defined beside it that was registered in code or named by a dotted path elsewhere.

    Raises:
        TaskKindError: more than one class of that name is imported.
    """
    found: dict[str, type[TaskKind]] = {}
    stack = list(TaskKind.__subclasses__())
    while stack:
        cls = stack.pop()
        stack.extend(cls.__subclasses__())
        if cls.name == name and not inspect.isabstract(cls):
            found[f"{cls.__module__}:{cls.__qualname__}"] = cls
    if len(found) > 1:
        raise TaskKindError(f"task kind '{name}' is defined by {', '.join(sorted(found))}; register one")
    if not found:
        return None
    ((where, cls),) = found.items()
    return _instance(cls, where)
