"""Typed contracts between systems: control mode, contact domain, link stage and event counters.

``Mode`` and ``Domain`` are ``str`` enums: they compare equal to their names
(``Mode.WALKING == "walking"``) and serialise to them in JSON, while a port or a field declared
with them only ever holds one of the listed values. Numeric encodings (LCM status messages,
logs) go through :meth:`Mode.index` and the validated :meth:`Mode.decode`, never through raw
list indexing: an index of −1 used to read as damping and NaN raised deep inside a controller.
``LinkStage`` crosses vector ports as a number, read back with :meth:`LinkStage.decode`. Counts
a system keeps (failures, link events) are :class:`Counters` dataclasses on abstract ports, read
by name, never by position.
"""

from __future__ import annotations

import functools
import math
from dataclasses import asdict, dataclass, fields, replace
from enum import Enum, IntEnum

import numpy as np

from romoco_drake.values import SharedValue


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


class LinkStage(IntEnum):
    """How a side of the LCM link acts on the age of the newest message it needs.

    The controller side (:mod:`~romoco_drake.interfaces.receiver`) goes FRESH → RIDE_THROUGH →
    STAND → DAMPING as its measurements age; the robot side
    (:mod:`~romoco_drake.interfaces.robot_sim`) FRESH → HOLD → DAMPING as its commands do. The
    values grow with the loss, so a later stage compares greater. A vector port carries the
    value as a float (the simulated station: FRESH); read it with :meth:`decode`.
    """

    FRESH = 0  # messages arrive: act on them
    RIDE_THROUGH = 1  # controller side: walk on predicted measurements, the command plus a PD sent
    STAND = 2  # controller side: the same, slowing down to a stop
    HOLD = 3  # robot side: the last posture held by joint PD
    DAMPING = 4  # lost for longer (or never received): joint damping

    @classmethod
    def decode(cls, value: float) -> LinkStage:
        """The stage numbered ``value``; ValueError names a value that is no stage."""
        try:  # a stage's own number (int or float) needs no checks
            return _STAGES[value]
        except (KeyError, TypeError):  # another value, or an unhashable one (an array)
            pass
        v = float(value)
        if not math.isfinite(v) or v != round(v) or int(v) not in cls._value2member_map_:
            known = ", ".join(f"{s.value} {s.name}" for s in cls)
            raise ValueError(f"{value!r} is not a link stage ({known})")
        return cls(int(v))


_STAGES = {float(stage): stage for stage in LinkStage}


@dataclass(frozen=True)
class Counters(SharedValue):
    """Event counts a system keeps in discrete state (:meth:`vector`) and shows on an abstract
    port (:meth:`from_vector`); fields are named as the run summary's keys where it reports them."""

    @classmethod
    def size(cls) -> int:
        return len(fields(cls))

    @classmethod
    def from_vector(cls, values) -> Counters:
        return cls(*map(int, np.asarray(values).tolist()))  # Python floats: int() of each is cheap

    def values(self) -> tuple[int, ...]:
        """The counts in field order (``dataclasses.astuple`` deep-copies: ten times slower)."""
        return tuple(self.__dict__[name] for name in _field_names(type(self)))

    def vector(self) -> np.ndarray:
        return np.array(self.values(), dtype=float)

    def summary(self) -> dict[str, int]:
        return asdict(self)

    def __add__(self, other: Counters) -> Counters:
        return type(self)(*(a + b for a, b in zip(self.values(), other.values(), strict=True)))


@functools.cache
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in fields(cls))


@dataclass(frozen=True)
class ControllerStats(Counters):
    """A whole-body controller's solver failures, safe (damping) ticks, current run of failures
    and ticks answered by a relaxed problem."""

    failures: int = 0
    safe_ticks: int = 0
    failure_streak: int = 0
    relaxed_ticks: int = 0


@dataclass(frozen=True)
class StateStats(Counters):
    """The shared kinematics' unusable state estimates (non-finite or diverged): entries into
    one and the current run of ticks in one."""

    nonfinite_state_events: int = 0
    nonfinite_streak: int = 0


@dataclass(frozen=True)
class DeadlineStats(Counters):
    """The control loop's ticks over their period: all of them, the longest and the current run
    of them, and the runs that reached ``link.max_consecutive_misses`` (late events)."""

    deadline_misses: int = 0
    longest_miss_streak: int = 0
    miss_streak: int = 0
    late_events: int = 0


@dataclass(frozen=True)
class LinkCounters(Counters):
    """The controller side's link safety counts: the measurement receiver counts stages entered
    and rejected messages, the command sender rejected (non-finite) and clamped commands and
    E-stops; the station's counts are their sum."""

    stale_events: int = 0
    ride_through_events: int = 0
    stand_events: int = 0
    damping_events: int = 0
    rejected_messages: int = 0
    clamped_commands: int = 0
    estop: int = 0

    def entered(self, stage: LinkStage) -> LinkCounters:
        """One more entry to ``stage`` (RIDE_THROUGH, STAND or DAMPING)."""
        key = f"{stage.name.lower()}_events"
        return replace(self, **{key: getattr(self, key) + 1})


@dataclass(frozen=True)
class RobotLinkCounters(Counters):
    """The robot side's link safety counts (the simulated robot's command receiver)."""

    stale_events: int = 0
    hold_events: int = 0
    damping_events: int = 0
    rejected_messages: int = 0
    estop: int = 0


@dataclass(frozen=True)
class MpcStats(Counters):
    """A VI-MPC planner's solves, failed solves and updates without a usable reference, in the
    order of its ``mpc_stats`` vector port."""

    mpc_solves: int = 0
    mpc_failures: int = 0
    mpc_fallback_updates: int = 0
