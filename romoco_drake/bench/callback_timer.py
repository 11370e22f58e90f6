"""Per-system wall time of a diagram's Python callbacks, for the timing benches.

Within :func:`timed_callbacks`, every callback a ``LeafSystem`` declares (output-port calcs and
periodic, initialization and forced events) is wrapped so that its wall time is added to its
system's account. Times are exclusive: a callback that evaluates another system's port (the
usual way a tick pulls its inputs) is charged its own time only, the other system the rest.
What is in no Python callback (Drake's framework, its C++ systems) is the tick's time minus the
accounts' sum. The wrapping costs about a microsecond a call (30-50 µs a G1 hardware tick of
some 30 callbacks).
"""

from __future__ import annotations

import contextlib
import time
from collections import defaultdict

from pydrake.systems.framework import LeafSystem

# Each declaration's callback argument: (position after ``self``, keyword).
_DECLARATIONS = {
    "DeclareVectorOutputPort": (2, "calc"),
    "DeclareAbstractOutputPort": (2, "calc"),
    "DeclarePeriodicDiscreteUpdateEvent": (2, "update"),
    "DeclarePeriodicUnrestrictedUpdateEvent": (2, "update"),
    "DeclarePeriodicPublishEvent": (2, "publish"),
    "DeclareInitializationDiscreteUpdateEvent": (0, "update"),
    "DeclareInitializationUnrestrictedUpdateEvent": (0, "update"),
    "DeclareForcedPublishEvent": (0, "publish"),
    "DeclareForcedDiscreteUpdateEvent": (0, "update"),
    "DeclareForcedUnrestrictedUpdateEvent": (0, "update"),
}


class CallbackTimer:
    """Exclusive callback time (ns) per system name since the last :meth:`lap`."""

    def __init__(self, clock=time.perf_counter_ns):
        self._clock = clock
        self._spent: dict[str, int] = defaultdict(int)
        self._children: list[int] = []  # per open callback: time spent in the callbacks it called
        self._names: dict[int, str] = {}

    def lap(self) -> dict[str, int]:
        """Each system's time since the last lap, and a new lap."""
        spent = dict(self._spent)
        self._spent.clear()
        return spent

    def wrap(self, system: LeafSystem, callback):
        """``callback`` charging its exclusive time to ``system``."""
        key = id(system)
        children, spent, names, clock = self._children, self._spent, self._names, self._clock

        def timed(*args):
            children.append(0)
            start = clock()
            try:
                return callback(*args)
            finally:
                elapsed = clock() - start
                nested = children.pop()
                name = names.get(key)
                if name is None:
                    name = names[key] = system.get_name() or type(system).__name__
                spent[name] += elapsed - nested
                if children:
                    children[-1] += elapsed

        return timed


@contextlib.contextmanager
def timed_callbacks(clock=time.perf_counter_ns):
    """Within: systems constructed have their callbacks timed by the yielded :class:`CallbackTimer`
    on ``clock`` (ns; the wall clock by default) for as long as the systems live (only their
    construction needs to be inside)."""
    timer = CallbackTimer(clock)
    originals = {name: getattr(LeafSystem, name) for name in _DECLARATIONS if hasattr(LeafSystem, name)}

    def patched(name: str, declare):
        position, keyword = _DECLARATIONS[name]

        def declare_timed(self, *args, **kwargs):
            if keyword in kwargs:
                kwargs[keyword] = timer.wrap(self, kwargs[keyword])
            elif len(args) > position and callable(args[position]):
                args = (*args[:position], timer.wrap(self, args[position]), *args[position + 1:])
            return declare(self, *args, **kwargs)

        return declare_timed

    for name, declare in originals.items():
        setattr(LeafSystem, name, patched(name, declare))
    try:
        yield timer
    finally:
        for name, declare in originals.items():
            setattr(LeafSystem, name, declare)
