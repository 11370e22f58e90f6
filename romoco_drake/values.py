"""Base for the immutable values carried on abstract ports and in abstract state."""

from __future__ import annotations


class SharedValue:
    """Copies return the object itself.

    Drake clones abstract values (port caches, state updates, ``FixValue``) with
    ``copy.deepcopy``; for values that are never mutated after construction that copy only
    costs time, so subclasses share one instance instead. Subclasses must stay immutable:
    frozen dataclasses whose arrays nobody writes to.
    """

    __slots__ = ()

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self
