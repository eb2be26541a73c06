"""Scenarios: YAML read into typed values (located errors), bundled scenarios and robots.

``load`` (a file or a bundled name), ``loads``, ``from_dict`` and ``with_threshold`` (a
``risk.threshold`` set from elsewhere, checked as the file's) are available here
(imported from :mod:`executive.scenario.loader` on first use, so that the loader's own
imports of this package's modules form no cycle).
"""

from __future__ import annotations

from typing import Any

__all__ = ["APPROVAL_MODES", "from_dict", "load", "loads", "max_ordering_value", "with_threshold"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from executive.scenario import loader

        return getattr(loader, name)
    raise AttributeError(f"module 'executive.scenario' has no attribute '{name}'")
