"""Typed control mode and contact domain, as carried on abstract ports and in references.

Both are ``str`` enums: they compare equal to their names (``Mode.WALKING == "walking"``) and
serialise to them in JSON, while a port or a field declared with them only ever holds one of
the listed values. Numeric encodings (LCM status messages, logs) go through :meth:`Mode.index`
and the validated :meth:`Mode.decode`, never through raw list indexing: an index of −1 used to
read as damping and NaN raised deep inside a controller.
"""

from __future__ import annotations

import math
from enum import Enum


class Mode(str, Enum):
    """What the gait state machine asks of the whole-body controller."""

    IN_AIR = "in_air"  # no contact: hold the nominal joint angles
    STANDING = "standing"
    WALKING = "walking"
    DAMPING = "damping"  # safe mode: joint damping only (after a fall or a bad state)

    def __str__(self) -> str:
        return self.value

    @property
    def index(self) -> int:
        """The mode's number in LCM messages and logs (declaration order)."""
        return _MODE_LIST.index(self)

    @classmethod
    def decode(cls, value: float) -> Mode:
        """The mode numbered ``value``; ValueError names the bad value (non-integer, NaN, out of range)."""
        v = float(value)
        if not math.isfinite(v) or v != round(v) or not 0 <= v < len(_MODE_LIST):
            raise ValueError(f"{value!r} is not a mode number "
                             f"({', '.join(f'{m.index} {m.value}' for m in _MODE_LIST)})")
        return _MODE_LIST[int(v)]


_MODE_LIST = tuple(Mode)


class Domain(str, Enum):
    """Which feet are held by contact constraints."""

    LEFT = "left"
    RIGHT = "right"
    DOUBLE = "double"
    NONE = "none"

    def __str__(self) -> str:
        return self.value

    @property
    def feet(self) -> tuple[str, ...]:
        """The feet in contact, left first."""
        return {"left": ("left",), "right": ("right",), "double": ("left", "right"), "none": ()}[self.value]

    @property
    def single_support(self) -> bool:
        return self is Domain.LEFT or self is Domain.RIGHT
