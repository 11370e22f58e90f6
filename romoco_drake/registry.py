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
    """One registered component: its factory, a one-line description, its settings dataclass
    (``config``: the scenario section it is configured by, None for kinds without one) and
    kind-specific facts."""

    name: str
    factory: Callable[..., Any]
    description: str = ""
    facts: dict[str, Any] = field(default_factory=dict)
    config: type | None = None


class Registry(Mapping[str, Entry]):
    """The components of one kind, by name (a read-only mapping once built)."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, Entry] = {}

    def add(self, name: str, factory: Callable[..., Any], description: str = "", config: type | None = None,
            **facts: Any) -> None:
        """Registers ``name``; ``config`` is its settings dataclass (a dataclass with a ``name`` field)."""
        if name in self._entries:
            raise ValueError(f"{self.kind} '{name}' is registered twice")
        self._entries[name] = Entry(name, factory, description, facts, config)

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


PLUGIN_GROUP = "romoco_drake.plugins"


def load_plugins() -> list[str]:
    """Imports the user's component modules, which register themselves with ``add`` on import.

    They are the ``romoco_drake.plugins`` entry points of installed packages, and the entries of
    ``$ROMOCO_PLUGINS`` (``:``-separated module names or ``.py`` files), so that ``romoco run``
    and the benches can name a planner or controller the user wrote. Returns what was loaded;
    a plugin that fails to import is a one-line RomocoError.
    """
    import importlib
    import importlib.metadata
    import importlib.util
    import os
    import sys
    from pathlib import Path

    loaded = []
    targets = [(ep.name, ep.value) for ep in importlib.metadata.entry_points(group=PLUGIN_GROUP)]
    targets += [(t, t) for t in os.environ.get("ROMOCO_PLUGINS", "").split(os.pathsep) if t]
    for name, target in targets:
        try:
            if target.endswith(".py"):
                path = Path(target).resolve()
                spec = importlib.util.spec_from_file_location(f"romoco_plugin_{path.stem}", path)
                if spec is None or not path.is_file():
                    raise RomocoError(f"plugin '{target}': no such file")
                if spec.name in sys.modules:  # already registered in this process
                    continue
                module = importlib.util.module_from_spec(spec)
                sys.modules[spec.name] = module
                spec.loader.exec_module(module)
            else:
                importlib.import_module(target.partition(":")[0])
        except RomocoError:
            raise
        except Exception as e:  # a user's module: any import failure is reported in one line
            raise RomocoError(f"plugin '{name}' ({target}) failed to load: {type(e).__name__}: {e}") from None
        loaded.append(target)
    return loaded
