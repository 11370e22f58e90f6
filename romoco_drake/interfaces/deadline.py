"""The control loop's deadline: each tick's wall time against its period, the misses counted, and
on a real-time link a run of misses taking the link's safe stages, as a stale stream does."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

from pydrake.systems.framework import EventStatus, LeafSystem

from romoco_drake.interfaces.link import PUBLISH_DELAY, LinkConfig, counters_port, link_stage
from romoco_drake.modes import DeadlineStats, LinkStage

_STREAK = [f.name for f in dataclasses.fields(DeadlineStats)].index("miss_streak")


class DeadlineMonitor(LeafSystem):
    """Times every tick of the control loop (every ``period`` s from ``offset``) on a wall clock.

    | port       | dir | size     | meaning                                                    |
    |------------|-----|----------|------------------------------------------------------------|
    | stats      | out | abstract | :class:`~romoco_drake.modes.DeadlineStats`                 |
    | link_stage | out | 1        | the :class:`~romoco_drake.modes.LinkStage` the loop's lateness asks for |

    Two updates a tick: at the tick an unrestricted one reads the clock; ``PUBLISH_DELAY`` later,
    after every system's update of the tick and the command's publish, a discrete one takes the
    clock's advance since as the tick's time, a miss if more than ``period``. Drake runs one
    time's unrestricted updates in the order the systems were added, and its discrete updates
    after them, so this system is added first (:func:`~romoco_drake.wiring.build_diagram`). At
    real time a tick that ends early waits for the publish, so one within ``PUBLISH_DELAY`` of
    its period may count as missed.

    ``config.max_consecutive_misses`` misses in a row (0: never) are one ``late_events``, and from
    then on ``link_stage`` is that of a stream gone stale at that tick (RIDE_THROUGH, after
    ``ride_through_s`` STAND, after ``stand_s`` more DAMPING; :func:`~.link.link_stage` on the
    ticks since, not on wall time), which the station acts on (its ``loop_stage`` input); the next
    tick on time ends it, as a message resuming does.
    ``clock`` (s, monotonic; None: ``time.perf_counter``) is the wall clock, a fake one in tests.
    """

    def __init__(self, period: float, offset: float = 0.0, config: LinkConfig | None = None,
                 clock: Callable[[], float] | None = None):
        super().__init__()
        self.period, self.config = period, config or LinkConfig()
        self._clock = clock if clock is not None else time.perf_counter
        self._started = self.DeclareDiscreteState(1)  # the clock at the tick
        self._stats = self.DeclareDiscreteState(DeadlineStats.size())
        self.stats_port = counters_port(self, "stats", DeadlineStats, self._stats)
        self.link_stage_port = self.DeclareVectorOutputPort(
            "link_stage", 1, lambda c, out: out.SetFromVector([float(self.stage(self._read(c)))]),
            prerequisites_of_calc={self.discrete_state_ticket(self._stats)})
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._start)
        self.DeclarePeriodicDiscreteUpdateEvent(period, offset + PUBLISH_DELAY, self._finish)

    def _read(self, context) -> DeadlineStats:
        return DeadlineStats.from_vector(context.get_discrete_state(self._stats).value())

    def stage(self, stats: DeadlineStats) -> LinkStage:
        """The stage a run of ``stats.miss_streak`` misses asks for (class docstring)."""
        limit = self.config.max_consecutive_misses
        if limit == 0 or stats.miss_streak < limit:
            return LinkStage.FRESH
        return link_stage(self.config.timeout_s + (stats.miss_streak - limit + 1) * self.period, self.config)

    def _start(self, context, state) -> None:
        state.get_mutable_discrete_state().get_mutable_vector(self._started).SetFromVector([self._clock()])

    def _finish(self, context, discrete_state) -> EventStatus | None:
        took = self._clock() - context.get_discrete_state(self._started).GetAtIndex(0)
        if took <= self.period and not context.get_discrete_state(self._stats).GetAtIndex(_STREAK):
            # On time after a tick on time: the counts stand, and Drake leaves the state (and what
            # depends on it) as it is.
            return EventStatus.DidNothing()
        s = self._read(context)
        if took > self.period:
            streak = s.miss_streak + 1
            late = s.late_events + (streak == self.config.max_consecutive_misses)
            s = DeadlineStats(s.deadline_misses + 1, max(s.longest_miss_streak, streak), streak, late)
        elif s.miss_streak:
            s = DeadlineStats(s.deadline_misses, s.longest_miss_streak, 0, s.late_events)
        discrete_state.get_mutable_vector(self._stats).SetFromVector(s.vector())

    def summary(self, context) -> dict:
        """The run summary's deadline keys: ``deadline_misses``, ``longest_miss_streak``, ``late_events``."""
        s = self._read(context)
        return {"deadline_misses": s.deadline_misses, "longest_miss_streak": s.longest_miss_streak,
                "late_events": s.late_events}
