"""The settings every estimator shares (the scenario's ``estimator:`` section)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from romoco_drake.config import RATE_HZ, Range, declare_ranges


@dataclass
class EstimatorSettings:
    """``name``: the registry entry: ``ground_truth`` (encoders plus the base pose/velocity ports:
    exact in simulation, motion capture on hardware), ``kalman`` (linear, takes the IMU's on-board
    orientation as given, flat ground) or ``invariant_ekf`` (estimates the orientation too, no
    flat-ground assumption); the filters read encoders, IMU and contact switches only and their
    yaw drifts (commands are in the estimated heading frame, see ``HeadingHold``).
    ``rate_hz``: the filter's update rate; None: the controller's."""

    name: str = "ground_truth"
    rate_hz: float | None = None


declare_ranges(EstimatorSettings, rate_hz=RATE_HZ)


@dataclass
class InvariantEkfSettings(EstimatorSettings):
    """The ``invariant_ekf`` entry's settings. ``start_offset_xyz`` (m, world axes) and
    ``start_offset_rpy`` (rad: roll, pitch, yaw about the world axes): how far the pose the filter
    starts from is off the pose the robot starts at, as for a robot set down by hand (zero: the
    filter starts at that pose: in simulation the scenario's start, raised onto its terrain or by
    ``initial_height_offset``; on hardware the nominal pose). Tilt converges from gravity and the stance
    feet; yaw and horizontal position are unobservable, so their offset stays as the estimate's
    frame, and what matters is their drift from it (the run summary's ``yaw_drift_rad_per_min``,
    ``position_drift_per_m``). ``terrain_anchor_s`` (s): on terrain (not on the flat floor, where
    the filter stays map-free) the time constant with which the estimate's height follows the
    scenario's ``terrain:`` map under its settled stance feet (the filter cannot observe it)."""

    start_offset_xyz: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    start_offset_rpy: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    terrain_anchor_s: float = 0.2


# A start more than 1 m or half a turn off is no pose estimate to converge from; a height anchor
# faster than a 1 kHz tick or slower than a minute is no filter.
declare_ranges(InvariantEkfSettings, start_offset_xyz=Range(-1.0, 1.0, "m", size=3),
               start_offset_rpy=Range(-0.5 * math.pi, 0.5 * math.pi, "rad", size=3),
               terrain_anchor_s=Range(1e-3, 60.0, "s"))
