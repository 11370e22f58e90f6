"""Name → factory registries, one per component kind (planners, controllers, estimators).

A component is listed in exactly one place, its registry; scenario validation, the CLI's
overrides, ``romoco list`` and the benches all read the registries, so adding a component is
one ``add`` call. Pure Python: the ``rom`` layer (no pydrake) keeps its planner registry too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any

from romoco_drake.errors import RomocoError


@dataclass(frozen=True)
class Entry:
    """One registered component: its factory, a one-line description and kind-specific facts."""

    name: str
    factory: Callable[..., Any]
    description: str = ""
    facts: dict[str, Any] = field(default_factory=dict)


class Registry(Mapping[str, Entry]):
    """The components of one kind, by name (a read-only mapping once built)."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, Entry] = {}

    def add(self, name: str, factory: Callable[..., Any], description: str = "", **facts: Any) -> None:
        if name in self._entries:
            raise ValueError(f"{self.kind} '{name}' is registered twice")
        self._entries[name] = Entry(name, factory, description, facts)

    def __getitem__(self, name: str) -> Entry:
        """The entry called ``name``; an unknown name is a one-line RomocoError (see :meth:`check`)."""
        return self._entries[self.check(name)]

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def check(self, name: str, where: str = "") -> str:
        """``name`` if registered, else a one-line RomocoError listing the known names."""
        if name not in self._entries:
            raise RomocoError(f"{where}unknown {self.kind} '{name}' (known: {', '.join(self._entries)})")
        return name
