"""Piecewise-constant walking commands over time."""

from __future__ import annotations

import bisect
from dataclasses import dataclass

from pydrake.systems.framework import LeafSystem

from romoco_drake.errors import RomocoError
from romoco_drake.rom.types import COMMAND_SIZE, WalkCommand


@dataclass(frozen=True)
class CommandSegment:
    """From ``start`` (s) on, walk with ``command``."""

    start: float
    command: WalkCommand


class CommandSource(LeafSystem):
    """Outputs the command of the latest segment that has started.

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command`` | out | 6 | :class:`WalkCommand` vector |
    """

    def __init__(self, segments: list[CommandSegment]):
        super().__init__()
        if not segments or segments[0].start > 0.0:
            raise RomocoError("a command profile needs a segment starting at t = 0")
        starts = [s.start for s in segments]
        if starts != sorted(starts):
            raise RomocoError("command segments must be in time order")
        self.segments = list(segments)
        self._starts = starts
        self.command_port = self.DeclareVectorOutputPort(
            "command", COMMAND_SIZE, self._calc, prerequisites_of_calc={self.time_ticket()})

    def command_at(self, t: float) -> WalkCommand:
        return self.segments[bisect.bisect_right(self._starts, t) - 1].command

    def _calc(self, context, out) -> None:
        out.SetFromVector(self.command_at(context.get_time()).to_vector())
