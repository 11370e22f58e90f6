"""Walking commands: piecewise constant over time, and limited to what the robot can walk."""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import LeafSystem

from romoco_drake.errors import RomocoError
from romoco_drake.robots.config import CommandLimits
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


def segments_from_log(times: np.ndarray, data: np.ndarray) -> list[CommandSegment]:
    """The piecewise-constant profile of logged command vectors (``data``: 6 × N): a segment at
    the first sample and at each change, so a live run is scored as a scripted one."""
    if len(times) == 0:
        return [CommandSegment(0.0, WalkCommand())]
    changed = np.flatnonzero(np.any(np.diff(data, axis=1) != 0.0, axis=0)) + 1
    return [CommandSegment(0.0 if i == 0 else float(times[i]), WalkCommand.from_vector(data[:, i]))
            for i in [0, *changed]]


def limited_velocity(held: np.ndarray, target: np.ndarray, limits: CommandLimits, dt: float) -> np.ndarray:
    """The limited (vx, vy, wz) ``dt`` after ``held``: toward ``target`` clipped to the velocity
    limits, at most at the acceleration limits (``held`` is inside the velocity limits)."""
    v_max = np.array([limits.vx, limits.vy, limits.wz])
    a_max = np.array([limits.ax, limits.ay, limits.wz_rate])
    return held + np.clip(np.clip(target, -v_max, v_max) - held, -a_max * dt, a_max * dt)


def reach_times(segments: list[CommandSegment], limits: CommandLimits) -> np.ndarray:
    """When the limited command reaches each segment's (clipped) command: the segment's start
    plus the ramp its accelerations need from where the previous segment's ramp had got to."""
    a_max = np.array([limits.ax, limits.ay, limits.wz_rate])
    held, previous, out = np.zeros(3), np.zeros(3), []
    for i, segment in enumerate(segments):
        if i:
            held = limited_velocity(held, previous, limits, segment.start - segments[i - 1].start)
        target = limited_velocity(held, segment.command.to_vector()[:3], limits, np.inf)
        out.append(segment.start + float(np.max(np.abs(target - held) / a_max)))
        previous = target
    return np.array(out)


class CommandLimiter(LeafSystem):
    """Keeps the walking command inside the robot's envelope: clipped, then rate limited.

    Each ``period`` the held (vx, vy, wz) moves toward the input's, clipped to ±the limits'
    velocities, by at most the limits' accelerations times ``period``. The other entries (step
    width, CoM height, step time) pass through. A non-finite velocity entry is taken as a stop
    (target 0), so a bad command slows the robot down instead of reaching the planner; so is
    any command while the optional ``stop`` input is set (the state machine's, on a blind link).

    | port | kind | size | meaning |
    |---|---|---|---|
    | ``command_in`` | in | 6 | :class:`WalkCommand` vector as asked |
    | ``stop`` | in | 1 | optional: > 0.5 ramps to a stop whatever is asked (read in the update only) |
    | ``command`` | out | 6 | the same with the limited (vx, vy, wz) |

    Discrete state: the limited (vx, vy, wz), from zero (the robot starts standing).
    """

    def __init__(self, limits: CommandLimits, period: float, offset: float = 0.0):
        super().__init__()
        self.period, self.limits = period, limits
        self._max = np.array([limits.vx, limits.vy, limits.wz])
        self._max_step = [limits.ax * period, limits.ay * period, limits.wz_rate * period]
        self.command_in_port = self.DeclareVectorInputPort("command_in", COMMAND_SIZE)
        self.stop_port = self.DeclareVectorInputPort("stop", 1)
        self._velocity = self.DeclareDiscreteState(3)
        self.command_port = self.DeclareVectorOutputPort(
            "command", COMMAND_SIZE, self._calc,
            prerequisites_of_calc={self.input_port_ticket(self.command_in_port.get_index()),
                                   self.discrete_state_ticket(self._velocity)})
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset, self._update)

    def clipped(self, command: WalkCommand) -> bool:
        """Whether ``command`` asks for more than the velocity limits."""
        return bool(np.any(np.abs([command.vx, command.vy, command.wz]) > self._max))

    def summary(self, segments: list[CommandSegment]) -> dict:
        """The run summary's count of the command segments the limits clipped."""
        return {"command_clipped_segments": sum(self.clipped(seg.command) for seg in segments)}

    def _update(self, context, discrete_state) -> None:
        held = context.get_discrete_state(self._velocity).value().tolist()
        target = [v if math.isfinite(v) else 0.0 for v in self.command_in_port.Eval(context)[:3].tolist()]
        if self.stop_port.HasValue(context) and self.stop_port.Eval(context)[0] > 0.5:
            target = [0.0, 0.0, 0.0]
        # limited_velocity, on three floats (numpy's overhead was most of this update).
        step = [min(max(min(max(v, -v_max), v_max) - h, -a), a)
                for v, h, v_max, a in zip(target, held, self._max.tolist(), self._max_step, strict=True)]
        velocity = [h + d for h, d in zip(held, step, strict=True)]
        discrete_state.get_mutable_vector(self._velocity).SetFromVector(velocity)

    def _calc(self, context, out) -> None:
        cmd = np.array(self.command_in_port.Eval(context))
        cmd[:3] = context.get_discrete_state(self._velocity).value()
        out.SetFromVector(cmd)
