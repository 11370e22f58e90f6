"""Link dropouts: windows in which LCM messages between robot and controller are lost.

A test-rig fault like a push (:mod:`~romoco_drake.interfaces.disturbance`): it needs both ends
of the link in this process (``--via-lcm``). During a :class:`Dropout` the chosen stream's
publisher sends nothing, as a radio or network outage would; the receivers see no new message
and react as they would on the robot (:mod:`~romoco_drake.interfaces.hardware`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pydrake.common.value import AbstractValue
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.framework import LeafSystem

from romoco_drake.interfaces.lcm_codec import (
    BASE_STATE_CHANNEL,
    MOTOR_COMMAND_CHANNEL,
    PROPRIOCEPTION_CHANNEL,
)

# What each stream loses: the robot's sensor messages, the controller's motor commands, or both
# directions (motion capture included: the whole link is down).
STREAM_CHANNELS = {
    "proprioception": (PROPRIOCEPTION_CHANNEL,),
    "commands": (MOTOR_COMMAND_CHANNEL,),
    "all": (PROPRIOCEPTION_CHANNEL, BASE_STATE_CHANNEL, MOTOR_COMMAND_CHANNEL),
}


@dataclass
class Dropout:
    """From ``t`` (s) for ``duration`` (s), no message of ``stream`` gets through."""

    t: float
    duration: float = 0.1
    stream: Literal["proprioception", "commands", "all"] = "proprioception"

    def drops(self, channel: str, time: float) -> bool:
        return channel in STREAM_CHANNELS[self.stream] and self.t <= time < self.t + self.duration


class DroppingPublisher(LeafSystem):
    """Publishes the bytes on its input to ``channel`` every ``period`` s, except in dropouts.

    | port    | dir | size     | meaning                    |
    |---------|-----|----------|----------------------------|
    | message | in  | abstract | encoded message to publish |

    The stand-in for ``LcmPublisherSystem`` on a link with dropouts: the same periodic publish,
    with nothing sent while a :class:`Dropout` covers the channel.
    """

    def __init__(self, channel: str, lcm: DrakeLcmInterface, period: float, offset: float,
                 dropouts: list[Dropout]):
        super().__init__()
        self.channel, self.lcm = channel, lcm
        self.dropouts = [d for d in dropouts if channel in STREAM_CHANNELS[d.stream]]
        self.message_port = self.DeclareAbstractInputPort("message", AbstractValue.Make(b""))
        self.DeclarePeriodicPublishEvent(period, offset, self._publish)

    def _publish(self, context) -> None:
        t = context.get_time()
        if any(d.drops(self.channel, t) for d in self.dropouts):
            return
        self.lcm.Publish(self.channel, self.message_port.Eval(context), t)
