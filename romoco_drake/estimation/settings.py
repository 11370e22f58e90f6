"""The settings every estimator shares (the scenario's ``estimator:`` section)."""

from __future__ import annotations

from dataclasses import dataclass

from romoco_drake.config import RATE_HZ, declare_ranges


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
