"""The LCM link's pieces both sides share: its config, stages, E-stop latch, inbox, publishers.

The controller side (:mod:`~romoco_drake.interfaces.hardware`) and the robot side
(:mod:`~romoco_drake.interfaces.robot_sim`) build their receivers and senders from these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import DiagramBuilder, LeafSystem, OutputPort, ValueProducer
from pydrake.systems.lcm import LcmPublisherSystem, LcmSubscriberSystem

from romoco_drake.config import Range, declare_ranges, positive
from romoco_drake.interfaces.dropout import STREAM_CHANNELS, Dropout, DroppingPublisher
from romoco_drake.interfaces.lcm_codec import MessageRejected, RawBytesSerializer, decode_estop
from romoco_drake.modes import Counters, LinkStage
from romoco_drake.robots.model import RobotModel

# Messages leave this long after the step or tick they report: a publish event at the step's
# own instant sees the state from before that step's updates (the previous step's values).
PUBLISH_DELAY = 2e-5  # s, less than any plant step


@dataclass
class LinkConfig:
    """Timing and limits of the LCM link (both the controller's and the robot's side)."""

    timeout_s: float = 0.02  # no new message for this long: the stream is stale
    # Robot side: how often received commands are checked and taken over (the controller side
    # takes its measurements once a controller tick).
    receive_rate_hz: float = 1000.0
    max_joint_speed: float = 30.0  # rad/s, |v_d| limit of a sent command
    max_gain_factor: float = 3.0  # K_p, K_d at most this times the robot YAML's gains
    # Controller side, measurements lost: predicted, walking on, up to this age of the last message ...
    ride_through_s: float = 0.1
    # ... then predicted while slowing down to a stop (and standing) this much longer, then damping.
    stand_s: float = 2.0
    # Robot side, commands lost: the last posture is held by joint PD this long, then damping.
    hold_s: float = 0.5
    # Controller side at real time (--hardware): this many ticks in a row over the controller's
    # period take the stages above, as a stale stream does (DeadlineMonitor); 0: never.
    max_consecutive_misses: int = 5


# A stream stale for a second has long lost the robot; the receive rate is a clock like the
# controller's; 100 rad/s is beyond any joint motor; a gain factor of 10 lets a sender ask for
# 10× the YAML gains, more is no longer the same robot. Walking on a prediction for more than a
# second (a whole gait cycle) outruns any model; standing on one beyond a minute is a robot left
# alone, which damping should take over. Waiting for more than 1000 late ticks in a row (a
# second at 1 kHz) before acting is not keeping a deadline.
declare_ranges(LinkConfig, timeout_s=positive(1.0, "s"), receive_rate_hz=Range(1.0, 10000.0, "Hz"),
               max_joint_speed=positive(100.0, "rad/s"), max_gain_factor=positive(10.0),
               ride_through_s=Range(0.0, 1.0, "s"), stand_s=Range(0.0, 60.0, "s"),
               hold_s=Range(0.0, 60.0, "s"), max_consecutive_misses=Range(0, 1000, "ticks"))


def link_stage(age: float, config: LinkConfig) -> LinkStage:
    """The controller side's stage for measurements last received ``age`` s ago (inf: never)."""
    if age <= config.timeout_s:
        return LinkStage.FRESH
    if age <= config.timeout_s + config.ride_through_s:
        return LinkStage.RIDE_THROUGH
    stand_until = config.timeout_s + config.ride_through_s + config.stand_s
    return LinkStage.STAND if age <= stand_until else LinkStage.DAMPING


def damping_command(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """[q_d; v_d; τ_ff; K_p; K_d] holding nothing: joint damping −K_d v about the measured q."""
    nu = robot.nu
    return np.concatenate([q, np.zeros(2 * nu), np.zeros(nu), robot.kd])


def counters_port(system: LeafSystem, name: str, cls: type[Counters], index) -> OutputPort:
    """An abstract output port showing the ``cls`` counts kept in discrete state ``index``."""
    return system.DeclareAbstractOutputPort(
        name, lambda: AbstractValue.Make(cls()),
        lambda context, value: value.set_value(cls.from_vector(context.get_discrete_state(index).value())),
        prerequisites_of_calc={system.discrete_state_ticket(index)})


class EstopLatch:
    """A system's E-stop input: engaged messages latch it for the rest of the run.

    A message that does not decode also engages it (fail safe: the E-stop channel is not one to
    guess about), and is counted as rejected. The last bytes seen are abstract state, so a
    message counts once however long it stays on the port; the latch is discrete state.
    ``engaged`` also reads the current message, so the E-stop acts on the tick it arrives.
    """

    def __init__(self, system: LeafSystem):
        self.port = system.DeclareAbstractInputPort("estop", AbstractValue.Make(b""))
        self.latched = system.DeclareDiscreteState(1)
        self.seen = system.DeclareAbstractState(AbstractValue.Make(b""))

    @staticmethod
    def _engages(data: bytes) -> tuple[bool, bool]:
        """(engages, rejected) for one non-empty message."""
        try:
            return decode_estop(data).engaged, False
        except MessageRejected:
            return True, True

    def engaged(self, context) -> bool:
        data = self.port.Eval(context)
        return bool(context.get_discrete_state(self.latched).GetAtIndex(0)) or (
            bool(data) and self._engages(data)[0])

    def take(self, context, state) -> tuple[bool, bool]:
        """(newly engaged, rejected) after this update's message; call in an unrestricted update."""
        data = self.port.Eval(context)
        if not data or data == context.get_abstract_state(int(self.seen)).get_value():
            return False, False
        state.get_mutable_abstract_state(int(self.seen)).set_value(data)
        engages, rejected = self._engages(data)
        newly = engages and not context.get_discrete_state(self.latched).GetAtIndex(0)
        if newly:
            state.get_mutable_discrete_state().get_mutable_vector(int(self.latched)).SetFromVector([1.0])
        return newly, rejected


class Inbox:
    """Reads a raw-bytes subscriber port: the newest good message's values, and bookkeeping.

    ``latest`` (a cache entry) is the port's current message decoded, if it decodes and is not
    older than the last one taken, else the last good values: the newest measurement reaches
    the controller without waiting for a periodic update. ``take``, run inside the owner's
    periodic update, keeps in discrete state the last good values, the last good message's
    utime, the time it arrived and whether any arrived, and in abstract state the last bytes
    seen, so one bad message is counted once however long it stays on the port.
    """

    def __init__(self, system: LeafSystem, channel: str, decode, default: np.ndarray):
        self.decode = decode
        self._memo: tuple[bytes | None, tuple[int, np.ndarray] | None] = (None, None)
        self.port = system.DeclareAbstractInputPort(channel, AbstractValue.Make(b""))
        self.values = system.DeclareDiscreteState(default)
        self.meta = system.DeclareDiscreteState([-1.0, -np.inf, 0.0])  # utime, arrival time, received
        self.seen = system.DeclareAbstractState(AbstractValue.Make(b""))
        self.latest = system.DeclareCacheEntry(
            f"newest good {channel}", ValueProducer(allocate=lambda: AbstractValue.Make(default.copy()),
                                                    calc=self._latest),
            {system.input_port_ticket(self.port.get_index()), system.discrete_state_ticket(self.values),
             system.discrete_state_ticket(self.meta)})

    def _decoded(self, data: bytes) -> tuple[int, np.ndarray]:
        """``decode(data)``, memoised for the last message: the cache entry and the update both
        read each message, and the entry again after the update (MessageRejected is not kept;
        the values are read-only)."""
        if data is not self._memo[0] and data != self._memo[0]:
            utime, values = self.decode(data)
            values.flags.writeable = False  # shared by every reader of the memo
            self._memo = (data, (utime, values))
        return self._memo[1]

    def _latest(self, context, value) -> None:
        data = self.port.Eval(context)
        if data:
            try:
                utime, values = self._decoded(data)
                if utime > context.get_discrete_state(self.meta).GetAtIndex(0):  # else: taken or stale
                    value.set_value(values)
                    return
            except MessageRejected:
                pass
        value.set_value(context.get_discrete_state(self.values).value().copy())

    def take(self, context, state) -> bool:
        """Takes the port's message if it is new; False if it was rejected (and new)."""
        data = self.port.Eval(context)
        if not data or data == context.get_abstract_state(int(self.seen)).get_value():
            return True
        state.get_mutable_abstract_state(int(self.seen)).set_value(data)
        utime = context.get_discrete_state(self.meta).GetAtIndex(0)
        try:
            msg_utime, values = self._decoded(data)
        except MessageRejected:
            return False
        if msg_utime <= utime:  # a repeat or out of order
            return False
        discrete = state.get_mutable_discrete_state()
        discrete.get_mutable_vector(int(self.meta)).SetFromVector([msg_utime, context.get_time(), 1.0])
        discrete.get_mutable_vector(int(self.values)).SetFromVector(values)
        return True

    def fresh(self, context, state, timeout: float) -> bool:
        """Whether, after this update's ``take``, a message arrived within ``timeout``."""
        _, arrival, received = state.get_discrete_state().get_vector(int(self.meta)).value().tolist()
        return bool(received) and context.get_time() - arrival <= timeout

    def age(self, context, state=None) -> float:
        """Time since the last good message arrived (inf before the first); ``state``: after
        this update's ``take``."""
        source = context if state is None else state
        _, arrival, received = source.get_discrete_state().get_vector(int(self.meta)).value().tolist()
        return context.get_time() - arrival if received else np.inf


def subscribe(builder: DiagramBuilder, lcm: DrakeLcmInterface, channel: str, port,
              wait_s: float = 0.0) -> None:
    """Feeds ``port`` the raw bytes of the newest message on ``channel``; with ``wait_s`` > 0 the
    simulation's initialization waits up to that long (wall time) for the first message."""
    sub = builder.AddNamedSystem(f"{channel.lower()}_subscriber", LcmSubscriberSystem(
        channel, RawBytesSerializer(), lcm, wait_for_message_on_initialization_timeout=wait_s))
    builder.Connect(sub.get_output_port(), port)


def publish(builder: DiagramBuilder, lcm: DrakeLcmInterface, channel: str, port, period: float,
            offset: float = 0.0, dropouts: list[Dropout] | None = None) -> None:
    """Publishes the bytes on ``port`` to ``channel`` every ``period`` s (from ``offset``), except
    while one of ``dropouts`` covers the channel."""
    if any(channel in STREAM_CHANNELS[d.stream] for d in dropouts or ()):
        system = DroppingPublisher(channel, lcm, period, offset, dropouts)
    else:
        system = LcmPublisherSystem(channel, RawBytesSerializer(), lcm, period, offset)
    pub = builder.AddNamedSystem(f"{channel.lower()}_publisher", system)
    builder.Connect(port, pub.get_input_port())
