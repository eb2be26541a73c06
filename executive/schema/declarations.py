"""A scenario key declared once: what the reader checks and what the JSON Schema says.

A declaration holds what a key's value may be: its type, unit, range and the words that
describe it. ``read(node)`` checks a YAML value with the readers of
:class:`~executive.schema.yaml_nodes.Node` (a bad value fails naming the key path, the value
and the range); ``json_schema()`` says the same in JSON Schema (draft 2020-12) for editors
and ``docs/scenarios.md`` (:mod:`executive.scenario.json_schema`). The vocabulary:

* :class:`Number` (``to_radians`` for an angle written in degrees), :class:`Integer`,
  :class:`Choice`, :class:`Text`: one scalar;
* :class:`Vector`: a list of numbers, each with its own range, of one of a few lengths;
* :class:`Either`: one number or a list of them (an orientation);
* :class:`Alternatives`: a task's list of distinct alternative names;
* :class:`ListOf`: a list of one declaration's values (the scene's objects);
* :class:`Block`: a mapping of declared keys, read into a dataclass whose field defaults are
  the keys' defaults (a key absent or null keeps its default).

A range is ``[low, high]``, ``(low, high]`` with ``open_low``, or open at an end given None.
Plug-in task kinds declare their keys with the same vocabulary (:mod:`executive.plugin`).
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from executive.schema.yaml_nodes import Node

__all__ = [
    "Alternatives",
    "Block",
    "Choice",
    "Either",
    "Integer",
    "Key",
    "ListOf",
    "Number",
    "Text",
    "Vector",
    "json_number",
    "nullable",
    "number_text",
]


def json_number(value: float) -> float | int:
    """``value`` as JSON writes it best: an integral float as an int (10.0 -> 10)."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 2**53:
        return int(value)
    return value


def number_text(value: float) -> str:
    """A bound as the docs write it: 0.001, 10, 4294967295 (no exponent for whole numbers)."""
    value = json_number(value)
    return str(value) if isinstance(value, int) else f"{value:g}"


def nullable(schema: dict[str, Any]) -> dict[str, Any]:
    """``schema`` that also admits null: the readers take an optional key given as null for absent."""
    out = dict(schema)
    if "enum" in out:
        out["enum"] = [*out["enum"], None]
    if "type" in out:
        kinds = out["type"] if isinstance(out["type"], list) else [out["type"]]
        out["type"] = [*kinds, "null"]
    elif "oneOf" in out:
        out["oneOf"] = [*out["oneOf"], {"type": "null"}]
    return out


class Key(abc.ABC):
    """A declared key: ``description`` (words, as the docs say them) and ``unit`` ("" for none)."""

    description: str
    unit: str = ""

    @abc.abstractmethod
    def read(self, node: Node) -> Any:
        """The value at ``node``, checked (raises ScenarioError through ``node``, naming the key path)."""

    @abc.abstractmethod
    def value_schema(self) -> dict[str, Any]:
        """The JSON Schema of the value (without the description)."""

    def range_text(self) -> str:
        """The range as the docs write it (``[0, 0.2]``, ``(0, 1]``); "" for none."""
        return ""

    def to_yaml(self, value: Any) -> Any:
        """A read value (a default) as the file writes it (an angle back in degrees, a tuple as a list)."""
        return value

    def json_schema(self, default: Any = dataclasses.MISSING) -> dict[str, Any]:
        """The value's JSON Schema, described: ``title`` (the words), ``description`` (the words,
        unit, range and default, for an editor's hover), ``x-unit`` and ``x-range`` (for the docs)."""
        title = self.description.rstrip(".")
        words = [title + "."]
        notes: dict[str, Any] = {}
        if self.unit:
            words.append(f"Unit: {self.unit}.")
            notes["x-unit"] = self.unit
        if self.range_text():
            words.append(f"Range: {self.range_text()}.")
            notes["x-range"] = self.range_text()
        if default is not dataclasses.MISSING:
            notes["default"] = _json_value(default)
            words.append(f"Default: {_default_text(default)}.")
        return {"title": title, "description": " ".join(words), **notes, **self.value_schema()}


def _json_value(value: Any) -> Any:
    """``value`` with its integral floats as ints, inside lists and mappings too."""
    if isinstance(value, float):
        return json_number(value)
    if isinstance(value, list | tuple):
        return [_json_value(v) for v in value]
    if isinstance(value, dict):
        return {k: _json_value(v) for k, v in value.items()}
    return value


def _default_text(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return str(value).lower() if value is not None else "null"
    if isinstance(value, int | float):
        return number_text(value)
    if isinstance(value, list):
        return "[" + ", ".join(_default_text(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k}: {_default_text(v)}" for k, v in value.items()) + "}"
    return str(value)


@dataclasses.dataclass(frozen=True)
class Number(Key):
    """A finite number in ``[low, high]`` (``(low, high]`` with ``open_low``; None: no bound).

    ``to_radians``: written in degrees, read in radians.
    """

    description: str
    unit: str = ""
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    to_radians: bool = False

    def read(self, node: Node) -> float:
        low, high = self.low, self.high
        value = node.number(gt=low if self.open_low else None, ge=None if self.open_low else low, le=high)
        return math.radians(value) if self.to_radians else value

    def value_schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {"type": "number"}
        if self.low is not None:
            schema["exclusiveMinimum" if self.open_low else "minimum"] = json_number(self.low)
        if self.high is not None:
            schema["maximum"] = json_number(self.high)
        return schema

    def range_text(self) -> str:
        low, high = self.low, self.high
        if low is None and high is None:
            return ""
        if high is None:
            return f"{'>' if self.open_low else '>='} {number_text(low or 0.0)}"
        if low is None:
            return f"<= {number_text(high)}"
        return f"{'(' if self.open_low else '['}{number_text(low)}, {number_text(high)}]"

    def to_yaml(self, value: Any) -> Any:
        return json_number(round(math.degrees(value), 2) if self.to_radians else value)


@dataclasses.dataclass(frozen=True)
class Integer(Key):
    """An integer (not a bool, not a float) in ``[low, high]`` (None: no bound).

    ``expected``: the words of the message for a value that is not one (default: the range's).
    """

    description: str
    low: int | None = None
    high: int | None = None
    expected: str = ""
    unit: str = ""

    def read(self, node: Node) -> int:
        value = node.value
        if self.expected and (
            isinstance(value, bool)
            or not isinstance(value, int)
            or (self.low is not None and value < self.low)
            or (self.high is not None and value > self.high)
        ):
            node.expected(self.expected)
        return node.integer(ge=self.low, le=self.high)

    def value_schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {"type": "integer"}
        if self.low is not None:
            schema["minimum"] = self.low
        if self.high is not None:
            schema["maximum"] = self.high
        return schema

    def range_text(self) -> str:
        if self.high is None:
            return f">= {self.low}" if self.low is not None else ""
        return f"[{self.low}, {self.high}]" if self.low is not None else f"<= {self.high}"


@dataclasses.dataclass(frozen=True)
class Choice(Key):
    """One of a few names; ``choices`` may be a function (a registry's names, asked when used)."""

    description: str
    choices: Sequence[str] | Callable[[], Sequence[str]]
    unit: str = ""

    def names(self) -> tuple[str, ...]:
        """The valid names now."""
        return tuple(self.choices() if callable(self.choices) else self.choices)

    def read(self, node: Node) -> str:
        return node.choice(self.names())

    def value_schema(self) -> dict[str, Any]:
        return {"type": "string", "enum": list(self.names())}


@dataclasses.dataclass(frozen=True)
class Text(Key):
    """A string, not blank unless ``allow_empty``."""

    description: str
    allow_empty: bool = False
    unit: str = ""

    def read(self, node: Node) -> str:
        return node.string(allow_empty=self.allow_empty)

    def value_schema(self) -> dict[str, Any]:
        # Not blank: some character that is not white space.
        return {"type": "string"} if self.allow_empty else {"type": "string", "pattern": "\\S"}


@dataclasses.dataclass(frozen=True)
class Vector(Key):
    """A list of numbers, item ``i`` checked by ``items[i]``, of one of the ``lengths``.

    ``names``: the items' names for the docs (``x``, ``y``, ``z``); one item and several
    lengths: every item is checked by it (a size of 1 to 3 numbers).
    """

    description: str
    items: tuple[Number, ...]
    lengths: tuple[int, ...]
    names: tuple[str, ...] = ()
    unit: str = ""

    def _item(self, i: int) -> Number:
        return self.items[i] if i < len(self.items) else self.items[-1]

    def read(self, node: Node, lengths: Sequence[int] | None = None) -> tuple[float, ...]:
        """The numbers; ``lengths`` narrows the lengths allowed here (a box's size: 3)."""
        allowed = tuple(lengths) if lengths is not None else self.lengths
        if not isinstance(node.value, list) or len(node.value) not in allowed:
            what = " or ".join(str(n) for n in allowed)
            node.expected(f"a list of {what} number{'' if allowed == (1,) else 's'}")
        return tuple(self._item(i).read(item) for i, item in enumerate(node.items_list()))

    def value_schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {"type": "array"}
        if len(set(self.items)) == 1:
            schema["items"] = self.items[0].value_schema()
        else:
            schema["prefixItems"] = [item.value_schema() for item in self.items]
            schema["items"] = False
        schema["minItems"], schema["maxItems"] = min(self.lengths), max(self.lengths)
        return schema

    def range_text(self) -> str:
        ranges = [item.range_text() for item in self.items]
        if len(set(ranges)) == 1:
            return f"each {ranges[0]}" if len(self.lengths) > 1 or self.lengths[0] > 1 else ranges[0]
        names = self.names or tuple(f"[{i}]" for i in range(len(self.items)))
        return ", ".join(f"{name} {text}" for name, text in zip(names, ranges, strict=True))

    def to_yaml(self, value: Any) -> Any:
        return [self._item(i).to_yaml(v) for i, v in enumerate(value)]


@dataclasses.dataclass(frozen=True)
class Either(Key):
    """One number (``one``) or a list of numbers (``many``); ``expected``: the words for neither."""

    description: str
    one: Number
    many: Vector
    expected: str
    unit: str = ""

    def read(self, node: Node) -> Any:
        if isinstance(node.value, list):
            return self.many.read(node)
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            node.expected(self.expected)
        return self.one.read(node)

    def value_schema(self) -> dict[str, Any]:
        return {"oneOf": [self.one.value_schema(), self.many.value_schema()]}

    def range_text(self) -> str:
        return self.one.range_text()


@dataclasses.dataclass(frozen=True)
class Alternatives(Key):
    """A task's ``alternatives``: distinct names of ``names``, at least one."""

    description: str
    names: tuple[str, ...]
    unit: str = ""

    def read(self, node: Node) -> tuple[str, ...]:
        seen: list[str] = []
        for item in node.items_list(min_len=1):
            value = item.choice(self.names)
            if value in seen:
                item.fail(f"duplicate alternative '{value}'")
            seen.append(value)
        return tuple(seen)

    def value_schema(self) -> dict[str, Any]:
        item = {"type": "string", "enum": list(self.names)}
        return {"type": "array", "items": item, "minItems": 1, "uniqueItems": True}

    def to_yaml(self, value: Any) -> Any:
        return list(value)


@dataclasses.dataclass(frozen=True, eq=False)
class ListOf(Key):
    """A list of ``item`` values, at least ``min_len`` of them."""

    description: str
    item: Key
    min_len: int = 0
    unit: str = ""

    def read(self, node: Node) -> tuple[Any, ...]:
        return tuple(self.item.read(child) for child in node.items_list(self.min_len))

    def value_schema(self) -> dict[str, Any]:
        schema: dict[str, Any] = {"type": "array", "items": self.item.json_schema()}
        if self.min_len:
            schema["minItems"] = self.min_len
        return schema


@dataclasses.dataclass(frozen=True, eq=False)
class Block(Key):
    """A mapping of declared ``keys`` (``required`` ones and optional ones, nothing else).

    Args:
        description: what the block is.
        keys: YAML key -> its declaration, in the order the reader reads them (errors come in it).
        required: the keys that must be given.
        factory: the dataclass :meth:`read` builds (absent and null keys keep its defaults).
        fields: YAML key -> the dataclass field it fills, where the names differ (``object_yaw``:
            ``object_yaw_rad``).
        defaults: YAML key -> its default as written in the file, where the reader (not the
            dataclass) supplies it.
        conditions: JSON Schema conditions across the keys (``allOf``), for what a key's schema
            alone cannot say (a size's length follows the shape).
        check: what :meth:`read` does with the dataclass it built (a check across keys; it may
            return a corrected value).
    """

    description: str
    keys: Mapping[str, Key]
    required: tuple[str, ...] = ()
    factory: Callable[..., Any] | None = None
    fields: Mapping[str, str] = dataclasses.field(default_factory=dict)
    defaults: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    conditions: tuple[dict[str, Any], ...] = ()
    check: Callable[[Node, Any], Any] | None = None
    unit: str = ""

    def check_keys(self, node: Node) -> None:
        """Require a mapping of the declared keys only (the required ones are checked when read)."""
        node.check_keys(self.required, [k for k in self.keys if k not in self.required])

    def read_key(self, node: Node, key: str) -> Any:
        """The value of ``key`` read by its declaration (None: an optional key absent or null)."""
        child = node.get(key) if key in self.required else node.opt(key)
        return None if child is None else self.keys[key].read(child)

    def read(self, node: Node) -> Any:
        """The dataclass ``factory`` of the keys given (absent or null: its default), checked."""
        if self.factory is None:
            raise TypeError(f"block {self.description!r} declares no dataclass to read into")
        self.check_keys(node)
        kwargs: dict[str, Any] = {}
        for key in self.keys:
            value = self.read_key(node, key)
            if value is not None:
                kwargs[self.fields.get(key, key)] = value
        built = self.factory(**kwargs)
        return self.check(node, built) if self.check is not None else built

    def default(self, key: str) -> Any:
        """The default of ``key`` as the file writes it (``dataclasses.MISSING``: none)."""
        if key in self.defaults:
            return self.defaults[key]
        if key in self.required or self.factory is None or not dataclasses.is_dataclass(self.factory):
            return dataclasses.MISSING
        spec = self.keys[key]
        name = self.fields.get(key, key)
        found = next((f for f in dataclasses.fields(self.factory) if f.name == name), None)
        if found is None or isinstance(spec, Block):
            return dataclasses.MISSING
        if found.default is not dataclasses.MISSING:
            value = found.default
        elif found.default_factory is not dataclasses.MISSING:
            value = found.default_factory()
        else:
            return dataclasses.MISSING
        return dataclasses.MISSING if value is None else spec.to_yaml(value)

    def value_schema(self) -> dict[str, Any]:
        properties = {}
        for key, spec in self.keys.items():
            described = spec.json_schema(self.default(key))
            properties[key] = described if key in self.required else nullable(described)
        schema: dict[str, Any] = {"type": "object", "properties": properties}
        if self.required:
            schema["required"] = list(self.required)
        schema["additionalProperties"] = False
        if self.conditions:
            schema["allOf"] = list(self.conditions)
        return schema
