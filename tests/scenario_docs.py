"""Editing scenario documents (parsed YAML) by key path, for the malformed-scenario tests."""

from __future__ import annotations

from typing import Any

Doc = dict[str, Any]


def walk(data: Doc, path: str) -> tuple[Any, str | int]:
    """The container holding ``path`` (dotted, with [i] indices) and the last key.

    Missing mappings on the way are created (a key path may name a block the document omits).
    """
    parts: list[str | int] = []
    for part in path.split("."):
        name, *indices = part.replace("]", "").split("[")
        if name:
            parts.append(name)
        parts.extend(int(i) for i in indices)
    node: Any = data
    for part in parts[:-1]:
        node = node.setdefault(part, {}) if isinstance(node, dict) else node[part]
    return node, parts[-1]
