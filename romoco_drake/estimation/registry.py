"""The estimator registry: every estimator a scenario can name, how to build it, what it reads.

A factory takes ``(robot, config, initial_base_position, terrain)``: the scenario's ``estimator:``
section (:class:`~romoco_drake.estimation.settings.EstimatorSettings`, its rate resolved), the
base position to start from when it is known (simulation) or None, and the scenario's
:class:`~romoco_drake.rom.terrain.Terrain` map (None on the flat floor).
``inputs`` are the station output ports it is wired to (same names on its own input ports).
"""

from __future__ import annotations

from romoco_drake.config import LINK_TICK_OFFSET
from romoco_drake.estimation.ground_truth import GroundTruthEstimator
from romoco_drake.estimation.invariant_estimator import InvariantEkfEstimator
from romoco_drake.estimation.kalman_estimator import KalmanEstimator
from romoco_drake.estimation.settings import EstimatorSettings, InvariantEkfSettings
from romoco_drake.registry import Registry

ESTIMATORS = Registry("estimator")
ESTIMATORS.add("ground_truth", lambda robot, config, start, terrain: GroundTruthEstimator(robot),
               "encoders plus the base pose/velocity ports (exact in simulation, motion capture on hardware)",
               config=EstimatorSettings, inputs=("joint_state", "base_pose", "base_velocity"))
ESTIMATORS.add("kalman", lambda robot, config, start, terrain: KalmanEstimator(
    robot, 1.0 / config.rate_hz, initial_base_position=start, offset=LINK_TICK_OFFSET, terrain=terrain),
    "contact-aided linear Kalman filter on encoders, IMU (its on-board orientation as given) and contact "
    "switches; stance feet on the flat floor or the scenario's terrain map",
    config=EstimatorSettings, inputs=("joint_state", "imu", "foot_contact"))
ESTIMATORS.add("invariant_ekf", lambda robot, config, start, terrain: InvariantEkfEstimator(
    robot, 1.0 / config.rate_hz, initial_base_position=start, offset=LINK_TICK_OFFSET,
    start_offset=(config.start_offset_xyz, config.start_offset_rpy),
    terrain=terrain, terrain_anchor_s=config.terrain_anchor_s),
    "contact-aided right-invariant EKF on encoders, IMU rates and contact switches; starts at the nominal "
    "orientation and the simulation's start position (the nominal one on hardware), or "
    "start_offset_xyz/rpy off them, yaw and position in its own start frame; on terrain, its height "
    "anchored to the scenario's map",
    config=InvariantEkfSettings, inputs=("joint_state", "imu", "foot_contact", "link_stage"))
