"""The settings every controller shares; each controller's own dataclass extends them.

A scenario's ``controller:`` section is parsed by the dataclass its registry entry declares
(``CONTROLLERS.add(..., config=...)``), so a key the chosen controller does not read is a load
error naming the controller and its keys, and each controller's ranges sit beside its fields.
"""

from __future__ import annotations

from dataclasses import dataclass

from romoco_drake.config import RATE_HZ, declare_ranges


@dataclass
class ControllerSettings:
    """``name``: the registry entry (``romoco list``); ``rate_hz``: its tick rate."""

    name: str = "standing"
    rate_hz: float = 1000.0


declare_ranges(ControllerSettings, rate_hz=RATE_HZ)
