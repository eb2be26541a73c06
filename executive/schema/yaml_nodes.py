"""Read an untrusted YAML document into typed values, naming the key path of every error.

Two parts, shared by the scenario loader and the robot-profile loader:

* safe YAML loading (:func:`load_yaml_text`, :func:`load_yaml_file`): ``yaml.SafeLoader``
  only (no ``!!python/...`` tags), a size limit, a limit on the *expanded* size of the
  document (so alias "billion laughs" bombs are rejected before anything walks them),
  no recursive aliases, and every YAML error turned into a :class:`ScenarioError`
  with its line and column;
* :class:`Node`, a value plus the file and key path it came from (``scene.objects[1].size``),
  with readers that check the type and range and raise the loader's error class with
  ``expected ..., got ...`` messages and, for unknown keys, the nearest valid name.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import NoReturn

import yaml

from executive.errors import ScenarioError

__all__ = [
    "MAX_DOCUMENT_BYTES",
    "MAX_EXPANDED_NODES",
    "Node",
    "check_model_file",
    "describe",
    "load_yaml_file",
    "load_yaml_text",
    "suggest",
    "unknown_name",
]

#: How much of an MJCF file :func:`check_model_file` reads to tell a model from another file.
MODEL_HEAD_BYTES = 1 << 16
#: Largest scenario or profile file accepted.
MAX_DOCUMENT_BYTES = 1 << 20
#: Largest document accepted, counting every alias as a full copy of what it names.
MAX_EXPANDED_NODES = 100_000

ErrorType = type[ScenarioError]


def describe(value: object) -> str:
    """A short description of a value's type and content for error messages."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"bool {value}"
    if isinstance(value, int):
        if value.bit_length() > 64:
            return f"int with {value.bit_length()} bits"
        return f"int {value}"
    if isinstance(value, float):
        return f"float {value!r}"
    if isinstance(value, str):
        text = repr(value)
        return f"str {text[:60]}..." if len(text) > 60 else f"str {text}"
    if isinstance(value, dict):
        return f"a mapping with {len(value)} key{'s' if len(value) != 1 else ''}"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    return type(value).__name__


def suggest(word: str, valid: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest valid name, or ``""``."""
    close = difflib.get_close_matches(word, list(valid), n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def unknown_name(kind: str, word: str, valid: Sequence[str], label: str) -> str:
    """``"unknown <kind> 'word'; did you mean 'x'? <label>: a, b"`` (the suggestion only when close)."""
    return f"unknown {kind} '{word}'{suggest(word, valid) or ';'} {label}: {', '.join(valid) or '(none)'}"


def _quoted(names: Iterable[str]) -> str:
    return ", ".join(f"'{n}'" for n in names)


# ----------------------------------------------------------------------------- YAML


#: Scientific notation as people write it (``5e-2``, ``1E3``, ``-2.5e+4``): YAML 1.1 needs a dot and
#: a sign in the exponent, and reads ``5e-2`` or ``1e3`` as text; YAML 1.2 reads them as floats.
_FLOAT_12 = re.compile(r"^[-+]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)[eE][-+]?[0-9]+$")


class _GuardedLoader(yaml.SafeLoader):
    """A SafeLoader that rejects over-large (alias-expanded) and recursive documents and duplicate
    keys, and reads scientific notation without a dot (``5e-2``) as a float, as YAML 1.2 does."""

    def compose_document(self) -> yaml.Node | None:
        node = super().compose_document()
        if node is not None:
            _check_expansion(node)
            _check_duplicate_keys(node)
        return node


_GuardedLoader.add_implicit_resolver("tag:yaml.org,2002:float", _FLOAT_12, list("-+0123456789."))


def _check_duplicate_keys(root: yaml.Node) -> None:
    """Reject a mapping that names a key twice (YAML would keep the last one silently)."""
    seen_nodes: set[int] = set()
    stack: list[tuple[yaml.Node, str]] = [(root, "")]
    while stack:
        node, path = stack.pop()
        if id(node) in seen_nodes:
            continue
        seen_nodes.add(id(node))
        if isinstance(node, yaml.SequenceNode):
            stack.extend((child, f"{path}[{i}]") for i, child in enumerate(node.value))
        elif isinstance(node, yaml.MappingNode):
            first: dict[str, yaml.Node] = {}
            for key_node, value_node in node.value:
                key = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else f"<{key_node.id}>"
                where = f"{path}.{key}" if path else key
                if key in first and key != "<<":
                    raise _DuplicateKeyError(where, key, first[key].start_mark.line + 1, key_node.start_mark)
                first[key] = key_node
                stack.append((value_node, where))


class _DuplicateKeyError(yaml.MarkedYAMLError):
    """A key given twice in one mapping: names the key path and both lines."""

    def __init__(self, key_path: str, key: str, first_line: int, mark: yaml.Mark) -> None:
        super().__init__(
            problem=f"duplicate key '{key}' (first at line {first_line}, again at line "
            f"{mark.line + 1}); YAML would silently keep the last one: give it once",
            problem_mark=mark,
        )
        self.key_path = key_path


def _check_expansion(root: yaml.Node) -> None:
    """Count the nodes of the document as if every alias were expanded; reject cycles."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()

    def size(node: yaml.Node) -> int:
        key = id(node)
        if key in sizes:
            return sizes[key]
        if key in open_nodes:
            raise yaml.composer.ComposerError(
                None, None, "found a recursive alias (an anchor used inside itself)", node.start_mark
            )
        open_nodes.add(key)
        total = 1
        if isinstance(node, yaml.SequenceNode):
            for child in node.value:
                total += size(child)
                if total > MAX_EXPANDED_NODES:
                    break
        elif isinstance(node, yaml.MappingNode):
            for key_node, value_node in node.value:
                total += size(key_node) + size(value_node)
                if total > MAX_EXPANDED_NODES:
                    break
        open_nodes.discard(key)
        if total > MAX_EXPANDED_NODES:
            raise yaml.composer.ComposerError(
                None,
                None,
                f"the document expands to more than {MAX_EXPANDED_NODES} nodes "
                "(aliases count as copies); refusing an alias bomb",
                node.start_mark,
            )
        sizes[key] = total
        return total

    size(root)


def load_yaml_text(text: str, source: str, error: ErrorType = ScenarioError) -> Node:
    """Parse one YAML document that must be a mapping; return it as the root :class:`Node`."""
    if len(text) > MAX_DOCUMENT_BYTES:
        raise error(source, "", f"document too large: {len(text)} characters, limit {MAX_DOCUMENT_BYTES}")
    if not text.strip():
        raise error(source, "", "the document is empty; expected a mapping")
    try:
        data = yaml.load(text, Loader=_GuardedLoader)  # a SafeLoader subclass: safe
    except _DuplicateKeyError as exc:
        raise error(source, exc.key_path, str(exc.problem)) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        problem = "; ".join(part for part in (exc.context, exc.problem) if part) or "malformed YAML"
        raise error(source, "", f"invalid YAML at {where}{problem}") from None
    except yaml.YAMLError as exc:
        raise error(source, "", f"invalid YAML: {exc}") from None
    except RecursionError:
        raise error(source, "", "invalid YAML: nested too deeply") from None
    except Exception as exc:
        # PyYAML's constructors fail on some odd scalars with plain Python errors: ``!!int ''``
        # (IndexError), an int literal of 5000 digits (ValueError). Untrusted input: report, don't crash.
        raise error(source, "", f"invalid YAML: {type(exc).__name__}: {exc}") from None
    if data is None:
        raise error(source, "", "the document is empty; expected a mapping")
    if not isinstance(data, dict):
        raise error(source, "", f"expected a mapping at the top level, got {describe(data)}")
    return Node(data, source, "", error)


def load_yaml_file(path: Path, error: ErrorType = ScenarioError) -> Node:
    """Read and parse a YAML file (see :func:`load_yaml_text`)."""
    source = str(path)
    try:
        size = path.stat().st_size
        if size > MAX_DOCUMENT_BYTES:
            raise error(source, "", f"file too large: {size} bytes, limit {MAX_DOCUMENT_BYTES}")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise error(source, "", f"not UTF-8 text: {exc.reason} at byte {exc.start}") from None
    except OSError as exc:
        raise error(source, "", f"cannot read the file: {exc.strerror or exc}") from None
    return load_yaml_text(text, source, error)


# ----------------------------------------------------------------------------- Node


class Node:
    """A value from a document plus where it is (file and key path).

    Readers check the value and return plain Python values; on a mismatch they
    raise ``error(source, path, "expected ..., got ...")``.
    """

    __slots__ = ("error", "path", "source", "value")

    def __init__(self, value: object, source: str, path: str = "", error: ErrorType = ScenarioError) -> None:
        self.value = value
        self.source = source
        self.path = path
        self.error = error

    def __repr__(self) -> str:
        return f"Node({self.source}: {self.path or '<root>'} = {describe(self.value)})"

    def fail(self, problem: str) -> NoReturn:
        """Raise the loader's error at this node's key path."""
        raise self.error(self.source, self.path, problem)

    def expected(self, what: str) -> NoReturn:
        """Raise ``expected <what>, got <this value>``."""
        self.fail(f"expected {what}, got {describe(self.value)}")

    def child(self, key: str | int, value: object) -> Node:
        """A node for ``value`` found at ``key`` (a mapping key or a list index) under this one."""
        if isinstance(key, int):
            path = f"{self.path}[{key}]"
        else:
            path = f"{self.path}.{key}" if self.path else key
        return Node(value, self.source, path, self.error)

    # --- mappings

    def _mapping(self) -> dict[str, object]:
        if not isinstance(self.value, dict):
            self.expected("a mapping")
        for key in self.value:
            if not isinstance(key, str):
                self.fail(f"expected string keys, got key {describe(key)}")
        return self.value

    def is_mapping(self) -> bool:
        return isinstance(self.value, dict)

    def check_keys(self, required: Sequence[str] = (), optional: Sequence[str] = ()) -> None:
        """Require a mapping with no key outside ``required + optional``.

        A missing required key is reported when it is read with :meth:`get`, so a
        loader that reads keys in schema order reports errors in that order.
        """
        data = self._mapping()
        valid = [*required, *optional]
        for key in data:
            if key not in valid:
                self.child(key, data[key]).fail(unknown_name("key", key, valid, "valid keys"))

    def has(self, key: str) -> bool:
        return key in self._mapping()

    def get(self, key: str) -> Node:
        """The child at ``key``; it must be present."""
        data = self._mapping()
        if key not in data:
            self.child(key, None).fail(f"missing required key '{key}'")
        return self.child(key, data[key])

    def opt(self, key: str) -> Node | None:
        """The child at ``key``, or None when the key is absent or its value is null."""
        data = self._mapping()
        value = data.get(key)
        return None if value is None else self.child(key, value)

    def items(self) -> list[tuple[str, Node]]:
        """The (key, child) pairs of a mapping with string keys."""
        return [(key, self.child(key, value)) for key, value in self._mapping().items()]

    def single_key(self, what: str) -> tuple[str, Node]:
        """A mapping with exactly one key (e.g. ``{transfer: {...}}``): its key and value."""
        data = self._mapping()
        if len(data) != 1:
            self.expected(f"a mapping with exactly one key ({what})")
        key, value = next(iter(data.items()))
        return key, self.child(key, value)

    # --- lists

    def items_list(self, min_len: int = 0) -> list[Node]:
        """The elements of a list, at least ``min_len`` of them."""
        if not isinstance(self.value, list):
            self.expected("a list" if min_len == 0 else "a non-empty list")
        if len(self.value) < min_len:
            self.expected(f"a list of at least {min_len} item{'s' if min_len != 1 else ''}")
        return [self.child(i, v) for i, v in enumerate(self.value)]

    def numbers(
        self,
        lengths: int | Sequence[int],
        *,
        gt: float | None = None,
        ge: float | None = None,
        le: float | None = None,
    ) -> tuple[float, ...]:
        """A list of finite numbers whose length is one of ``lengths``, each within the bounds."""
        allowed = (lengths,) if isinstance(lengths, int) else tuple(lengths)
        what = " or ".join(str(n) for n in allowed)
        if not isinstance(self.value, list) or len(self.value) not in allowed:
            self.expected(f"a list of {what} number{'' if allowed == (1,) else 's'}")
        return tuple(item.number(gt=gt, ge=ge, le=le) for item in self.items_list())

    def strings(self, min_len: int = 0) -> tuple[str, ...]:
        """A list of non-empty strings."""
        return tuple(item.string() for item in self.items_list(min_len))

    # --- scalars

    def number(self, *, gt: float | None = None, ge: float | None = None, le: float | None = None) -> float:
        """A finite int or float (not a bool) within the given bounds."""
        value = self.value
        if isinstance(value, bool) or not isinstance(value, int | float):
            self.expected("a number")
        try:
            result = float(value)
        except OverflowError:
            self.expected("a finite number")
        if not math.isfinite(result):
            self.expected("a finite number")
        bounds = []
        if gt is not None:
            bounds.append(f"> {gt:g}")
        if ge is not None:
            bounds.append(f">= {ge:g}")
        if le is not None:
            bounds.append(f"<= {le:g}")
        if (
            (gt is not None and not result > gt)
            or (ge is not None and not result >= ge)
            or (le is not None and not result <= le)
        ):
            self.expected(f"a number {' and '.join(bounds)}")
        return result

    def positive(self) -> float:
        """A finite number > 0."""
        return self.number(gt=0.0)

    def non_negative(self) -> float:
        """A finite number >= 0."""
        return self.number(ge=0.0)

    def integer(self, *, ge: int | None = None, le: int | None = None) -> int:
        """An int (not a bool, not a float) >= ``ge`` and <= ``le``."""
        value = self.value
        if isinstance(value, bool) or not isinstance(value, int):
            self.expected("an integer")
        if ge is not None and value < ge:
            self.expected(f"an integer >= {ge}" + (f" and <= {le}" if le is not None else ""))
        if le is not None and value > le:
            self.expected(f"an integer {f'>= {ge} and ' if ge is not None else ''}<= {le}")
        return value

    def boolean(self) -> bool:
        """true or false (not 0/1, not a string)."""
        if not isinstance(self.value, bool):
            self.expected("true or false")
        return self.value

    def string(self, *, allow_empty: bool = False) -> str:
        """A string (non-empty unless ``allow_empty``)."""
        if not isinstance(self.value, str):
            self.expected("a string")
        if not allow_empty and not self.value.strip():
            self.expected("a non-empty string")
        return self.value

    def choice(self, choices: Sequence[str]) -> str:
        """A string that is one of ``choices``."""
        if not isinstance(self.value, str) or self.value not in choices:
            hint = suggest(self.value, choices) if isinstance(self.value, str) else ""
            self.fail(f"expected one of {_quoted(choices)}, got {describe(self.value)}{hint}")
        return self.value

    def file_path(self, base_dir: Path, what: str = "file") -> Path:
        """A path string resolved against ``base_dir``; the file must exist."""
        text = self.string()
        try:
            resolved = (base_dir / Path(text).expanduser()).resolve()
            exists = resolved.is_file()
        except (OSError, ValueError, RuntimeError) as exc:
            self.fail(f"invalid {what} path {text!r}: {exc}")
        if not exists:
            self.fail(f"{what} not found: {text!r} (resolved to {resolved})")
        return resolved


def check_model_file(node: Node, path: Path) -> None:
    """Fail at ``node`` unless ``path`` looks like an MJCF model (XML whose root is ``<mujoco>``)."""
    try:
        with path.open("rb") as handle:
            head = handle.read(MODEL_HEAD_BYTES)
    except OSError as exc:
        node.fail(f"cannot read the MJCF file {str(path)!r}: {exc.strerror or exc}")
    text = head.lstrip(b"\xef\xbb\xbf \t\r\n")
    if not text.startswith(b"<") or b"<mujoco" not in head:
        first = text[:40].decode("utf-8", "replace").splitlines()[0] if text else ""
        kind = "a YAML file" if path.suffix in (".yaml", ".yml") else f"a {path.suffix or 'plain'} file"
        node.fail(
            f"{str(path)!r} is not an MJCF model file (XML with a <mujoco> root element); "
            f"it is {kind} beginning {first!r}"
        )
